//! Calibration of identification's 95 % intervals: does a printed interval hold the truth 95 %
//! of the time?
//!
//! The harness draws a plant (J_eq, B_eq, tau_sf around the lab plant), an input (the speed-loop
//! staircase and ramps of `identify --ramp`, with or without an extra sine log; an open-loop
//! voltage sine; an open-loop PRBS of voltage levels; a position PID on random steps) and seeds,
//! simulates it on
//! * servo's simulator ([`servo_core::sim::PlantSim`] behind [`SimBackend`]), and
//! * [`OtherSim`], written here independently of servo's: classic RK4 at 50 us, Coulomb friction
//!   smoothed as tau_sf tanh(omega_l / omega_s) (creeping, not sticking), a current sensor with
//!   an anti-alias lag, noise and ADC steps, a floor-quantised encoder, and (open loop) a logged
//!   tachometer speed with a first-order lag and quantisation,
//!
//! runs [`servo_core::ident::auto::identify`] exactly as `servo identify` calls it (default
//! options, the true electrical constants as `--params`), and counts how often the 95 % intervals
//! of J_eq, B_eq and tau_sf contain the truth.
//!
//! * `calibration::intervals_cover_the_truth_on_a_fast_subset`: a subset (both simulators,
//!   every input), fails below 85 % for any parameter.
//! * `calibration::calibration_benchmark` (ignored; the benchmark): 240 identifications, prints
//!   coverage and the median relative half-width per parameter, simulator and input:
//!   `cargo test --release --test e2e calibration::calibration_benchmark -- --ignored --nocapture`.

// Per-parameter loops index the parallel arrays of a tally.
#![allow(clippy::needless_range_loop)]

use servo_core::control::{Pid, PidConfig, PidGains, SpeedLoopConfig, SpeedProfile};
use servo_core::ident::auto::{identify, IdentifyOptions};
use servo_core::ident::{Estimate, Experiment};
use servo_core::record::Record;
use servo_core::sim::sensors::SplitMix64;
use servo_core::sim::SensorConfig;
use servo_core::{Plant, PlantParams};
use servo_hw::run::{run_loop, RunConfig};
use servo_hw::sim::SimBackend;
use servo_hw::{Backend, BoardInfo, HwError, Sample};
use std::f64::consts::TAU;

const DT: f64 = 1e-3;

/// Which simulator made the logs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimKind {
    Servo,
    Other,
}

/// The experiment of one identification.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputKind {
    /// The speed-loop staircase and up/down ramps of `identify --ramp`.
    Ramps,
    /// Those and a 20 s open-loop voltage sine log.
    RampsSine,
    /// An open-loop voltage sine only (combined least squares).
    Sine,
    /// An open-loop PRBS of voltage levels only.
    Prbs,
    /// A position PID on random steps (closed loop) only.
    ClosedLoop,
}

pub const INPUTS: [InputKind; 5] = [
    InputKind::Ramps,
    InputKind::RampsSine,
    InputKind::Sine,
    InputKind::Prbs,
    InputKind::ClosedLoop,
];

/// One identification's outcome: per parameter (J_eq, B_eq, tau_sf) the estimate and the truth.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub sim: SimKind,
    pub input: InputKind,
    pub seed: u64,
    /// `None`: identification refused or gave no value (with the reason).
    pub est: [Option<(Estimate, &'static str)>; 3],
    pub truth: [f64; 3],
    pub refused: Option<String>,
}

pub const NAMES: [&str; 3] = ["J_eq", "B_eq", "tau_sf"];

/// A random plant around the lab plant: J_eq x [0.7, 1.4], B_eq x [0.5, 2], tau_sf x [0.6, 1.4].
pub fn draw_plant(rng: &mut SplitMix64) -> PlantParams {
    let lab = PlantParams::LAB;
    let u = |rng: &mut SplitMix64, lo: f64, hi: f64| lo + (hi - lo) * rng.uniform();
    PlantParams {
        j_eq: Some(lab.j_eq() * u(rng, 0.7, 1.4)),
        b_eq: Some(lab.b_eq() * u(rng, 0.5, 2.0)),
        tau_sf: Some(lab.tau_sf() * u(rng, 0.6, 1.4)),
        ..lab
    }
}

/// What a case simulates: the plant and, for the effect cases, an imbalance at the load
/// (amplitude [N m], phase [rad]: amplitude sin(theta_l + phase) opposing the motion's drive).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rig {
    pub p: PlantParams,
    pub imbalance: Option<(f64, f64)>,
}

/// The independent simulator: state [u_drv, i_a, omega_m, theta_m], RK4 at 50 us.
pub struct OtherSim {
    p: PlantParams,
    x: [f64; 4],
    t: f64,
    /// Speed scale of the smooth Coulomb friction [rad/s at the load].
    omega_s: f64,
    /// Current sensor: first-order lag [s], noise [A], ADC step [A], its filtered state.
    i_tau_s: f64,
    i_noise: f64,
    i_lsb: f64,
    i_filt: f64,
    /// Tachometer (load speed): first-order lag [s], quantisation [rad/s], its state.
    tach_tau_s: f64,
    tach_lsb: f64,
    tach: f64,
    last_u: f64,
    rng: SplitMix64,
    /// An eccentric load: amplitude [N m] and phase [rad] of its torque at the load.
    imbalance: Option<(f64, f64)>,
}

impl OtherSim {
    /// The rig `rig` (its plant and its imbalance, if any).
    pub fn rig(rig: &Rig, rng: &mut SplitMix64) -> OtherSim {
        OtherSim {
            imbalance: rig.imbalance,
            ..OtherSim::new(rig.p, rng)
        }
    }

    pub fn new(p: PlantParams, rng: &mut SplitMix64) -> OtherSim {
        let u = |rng: &mut SplitMix64, lo: f64, hi: f64| lo + (hi - lo) * rng.uniform();
        OtherSim {
            p,
            x: [0.0; 4],
            t: 0.0,
            omega_s: u(rng, 0.01, 0.05),
            i_tau_s: u(rng, 0.0, 1e-4),
            i_noise: u(rng, 1e-3, 4e-3),
            i_lsb: 2.0 / 2048.0,
            i_filt: 0.0,
            tach_tau_s: u(rng, 0.0, 1.5e-3),
            tach_lsb: 0.01,
            tach: 0.0,
            last_u: 0.0,
            rng: SplitMix64(rng.next_u64()),
            imbalance: None,
        }
    }

    fn deriv(&self, x: [f64; 4], u: f64) -> [f64; 4] {
        let p = &self.p;
        let (n, j, b) = (p.n, p.j_eq(), p.b_eq());
        let w_l = x[2] / n;
        let coulomb = p.tau_sf() * (w_l / self.omega_s).tanh() / n;
        let eccentric = self
            .imbalance
            .map_or(0.0, |(a, ph)| a * (x[3] / n + ph).sin() / n);
        [
            (p.k_drv * u - x[0]) / p.t_drv(),
            (x[0] - p.r_eq() * x[1] - p.k_e * x[2]) / p.l_a,
            (p.k_t * x[1] - b * x[2] - coulomb - eccentric) / j,
            x[2],
        ]
    }

    /// One control period [`DT`] at the driver input `u` [V].
    pub fn step(&mut self, u: f64) {
        let h = 50e-6;
        let m = (DT / h).round() as usize;
        for _ in 0..m {
            let x = self.x;
            let add =
                |k: &[f64; 4], s: f64| -> [f64; 4] { std::array::from_fn(|i| x[i] + s * k[i]) };
            let k1 = self.deriv(x, u);
            let k2 = self.deriv(add(&k1, h / 2.0), u);
            let k3 = self.deriv(add(&k2, h / 2.0), u);
            let k4 = self.deriv(add(&k3, h), u);
            for i in 0..4 {
                self.x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
            // Sensor lags, integrated exactly over the sub-step.
            let a = (-h / self.i_tau_s.max(1e-9)).exp();
            self.i_filt = a * self.i_filt + (1.0 - a) * self.x[1];
            let a = (-h / self.tach_tau_s.max(1e-9)).exp();
            self.tach = a * self.tach + (1.0 - a) * self.x[2] / self.p.n;
        }
        self.t += DT;
        self.last_u = u;
    }

    /// Encoder (4096 counts per load revolution, floor), current (lag, noise, ADC), tachometer.
    pub fn measure(&mut self) -> (f64, i64, f64, f64) {
        let cpr = 4096.0;
        let count = (self.x[3] / self.p.n / TAU * cpr).floor();
        let i = self.i_filt + self.i_noise * self.rng.normal();
        let i = (i / self.i_lsb).round() * self.i_lsb;
        let w = (self.tach / self.tach_lsb).round() * self.tach_lsb;
        (count * TAU / cpr, count as i64, i, w)
    }
}

impl Backend for OtherSim {
    fn info(&self) -> BoardInfo {
        BoardInfo {
            firmware: "calibration other-sim",
            counts_per_rev: 4096,
            voltage_limit_v: 10.0,
            sample_period_s: DT,
        }
    }
    fn sample(&mut self) -> Result<Sample, HwError> {
        let (th, count, i, _) = self.measure();
        Ok(Sample {
            time_s: self.t,
            theta_l_rad: th,
            encoder_count: count,
            i_a_a: i,
            u_applied_v: self.last_u,
        })
    }
    fn apply(&mut self, u_v: f64) -> Result<(), HwError> {
        self.step(u_v.clamp(-10.0, 10.0));
        Ok(())
    }
    fn stop(&mut self) -> Result<(), HwError> {
        self.last_u = 0.0;
        Ok(())
    }
}

/// The backend of one log: servo's simulator or the other one.
fn backend(sim: SimKind, rig: &Rig, rng: &mut SplitMix64) -> Box<dyn Backend> {
    match sim {
        SimKind::Servo => {
            let mut plant = Plant::from_params(rig.p).unwrap();
            if let Some((a, ph)) = rig.imbalance {
                plant.effects.insert(
                    servo_core::effects::Effect::parse(&format!(
                        "imbalance:amplitude={a},phase={ph}"
                    ))
                    .unwrap(),
                );
            }
            let sensors = SensorConfig {
                seed: rng.next_u64(),
                current_noise_a: 1e-3 + 3e-3 * rng.uniform(),
                ..SensorConfig::default()
            };
            Box::new(SimBackend::new(&plant, sensors, DT).unwrap())
        }
        SimKind::Other => Box::new(OtherSim::rig(rig, rng)),
    }
}

/// The speed-loop experiments of `identify --ramp` (staircase both ways, up/down ramps), with a
/// random number of speeds, hold time, cycles and acceleration.
fn ramp_logs(sim: SimKind, rig: &Rig, rng: &mut SplitMix64) -> Vec<Record> {
    let p = &rig.p;
    let n = p.n;
    let levels = 4 + (rng.next_u64() % 4) as usize;
    let top = 450.0 + 250.0 * rng.uniform();
    let hold = 1.5 + 1.5 * rng.uniform();
    let mut stair = SpeedProfile::new();
    for sign in [1.0, -1.0] {
        stair.hold(0.5, 0.0).unwrap();
        for k in 1..=levels {
            stair
                .hold(hold, sign * top * k as f64 / levels as f64 / n)
                .unwrap();
        }
    }
    let accel = 400.0 + 600.0 * rng.uniform();
    let peak = 500.0 + 200.0 * rng.uniform();
    let cycles = 3 + (rng.next_u64() % 4) as usize;
    let mut ramps = SpeedProfile::new();
    ramps.hold(0.3, 0.0).unwrap();
    for _ in 0..cycles {
        ramps.ramp(peak / accel, 0.0, peak / n).unwrap();
        ramps.ramp(peak / accel, peak / n, 0.0).unwrap();
    }
    // The controller is designed for the nominal (lab) plant, as `identify --ramp` does.
    let speed_loop = SpeedLoopConfig::from_params(
        &PlantParams::LAB,
        servo_core::control::speed::SPEED_LOOP_CROSSOVER_RAD_S,
    )
    .unwrap();
    let mut out = Vec::new();
    for (profile, name) in [(stair, "friction"), (ramps, "inertia")] {
        let mut b = backend(sim, rig, rng);
        let cfg = RunConfig::speed(profile, speed_loop);
        let mut rec = run_loop(&mut *b, &cfg, None).unwrap().record;
        rec.source = format!("{sim:?} {name}");
        out.push(rec);
    }
    out
}

/// An open-loop voltage log of `secs` seconds: `u(t, rng)` is the voltage.
fn open_loop_log(
    sim: SimKind,
    rig: &Rig,
    rng: &mut SplitMix64,
    secs: f64,
    name: &str,
    mut u: impl FnMut(f64, &mut SplitMix64) -> f64,
) -> Record {
    let steps = (secs / DT) as usize;
    let (mut t, mut th, mut ia, mut uv, mut wl) = (vec![], vec![], vec![], vec![], vec![]);
    let mut urng = SplitMix64(rng.next_u64());
    match sim {
        SimKind::Servo => {
            let mut b = backend(sim, rig, rng);
            for k in 0..steps {
                let s = b.sample().unwrap();
                let uk = u(k as f64 * DT, &mut urng);
                t.push(s.time_s);
                th.push(s.theta_l_rad);
                ia.push(s.i_a_a);
                uv.push(uk);
                b.apply(uk).unwrap();
            }
        }
        SimKind::Other => {
            let mut s = OtherSim::rig(rig, rng);
            for k in 0..steps {
                let (thk, _, ik, wk) = s.measure();
                let uk = u(k as f64 * DT, &mut urng);
                t.push(s.t);
                th.push(thk);
                ia.push(ik);
                wl.push(wk);
                uv.push(uk);
                s.step(uk);
            }
        }
    }
    Record {
        source: format!("{sim:?} {name}"),
        time_s: t,
        theta_l_rad: Some(th),
        omega_l_rad_s: (!wl.is_empty()).then_some(wl),
        i_a_a: Some(ia),
        u_v: Some(uv),
        ..Record::default()
    }
}

/// A voltage sine: amplitude 3-8 V, 0.3-1.5 Hz, 20 s.
fn sine_log(sim: SimKind, p: &Rig, rng: &mut SplitMix64) -> Record {
    let amp = 3.0 + 5.0 * rng.uniform();
    let f = 0.3 + 1.2 * rng.uniform();
    open_loop_log(sim, p, rng, 20.0, "sine", move |t, _| {
        amp * (TAU * f * t).sin()
    })
}

/// Random voltage levels (+-1 to +-8 V) held 0.3-0.8 s, 20 s.
fn prbs_log(sim: SimKind, p: &Rig, rng: &mut SplitMix64) -> Record {
    let (mut level, mut until) = (0.0, 0.0);
    open_loop_log(sim, p, rng, 20.0, "prbs", move |t, r| {
        if t >= until {
            let mag = 1.0 + 7.0 * r.uniform();
            level = if r.uniform() < 0.5 { -mag } else { mag };
            until = t + 0.3 + 0.5 * r.uniform();
        }
        level
    })
}

/// A position PID tracking a reference whose speed swings around a random level without
/// reversing (load 10-30 rad/s, +-60 % at 0.2-1 Hz, either direction), 20 s.
fn closed_loop_log(sim: SimKind, p: &Rig, rng: &mut SplitMix64) -> Record {
    let gains = PidGains {
        kp: 7.5244,
        ki: 94.0379,
        kd: 0.1505,
        tl_s: 0.004,
    };
    let mut pid = Pid::new(PidConfig::new(gains, DT).with_symmetric_limit(10.0)).unwrap();
    let mut b = backend(sim, p, rng);
    let sign = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
    let w0 = sign * (10.0 + 20.0 * rng.uniform());
    let f = 0.2 + 0.8 * rng.uniform();
    let mut r = 0.0;
    let (mut t, mut th, mut ia, mut uv) = (vec![], vec![], vec![], vec![]);
    for k in 0..20_000 {
        let tk = k as f64 * DT;
        r += w0 * (1.0 + 0.6 * (TAU * f * tk).sin()) * DT;
        let s = b.sample().unwrap();
        let u = servo_core::compare::Controller::update(&mut pid, r, s.theta_l_rad);
        let u = u.clamp(-10.0, 10.0);
        t.push(s.time_s);
        th.push(s.theta_l_rad);
        ia.push(s.i_a_a);
        uv.push(u);
        b.apply(u).unwrap();
    }
    Record {
        source: format!("{sim:?} closed loop"),
        time_s: t,
        theta_l_rad: Some(th),
        i_a_a: Some(ia),
        u_v: Some(uv),
        ..Record::default()
    }
}

/// The logs of one case.
pub fn logs(sim: SimKind, input: InputKind, p: &PlantParams, rng: &mut SplitMix64) -> Vec<Record> {
    let rig = Rig {
        p: *p,
        imbalance: None,
    };
    rig_logs(sim, input, &rig, rng)
}

/// The logs of one case on `rig`.
pub fn rig_logs(sim: SimKind, input: InputKind, p: &Rig, rng: &mut SplitMix64) -> Vec<Record> {
    match input {
        InputKind::Ramps => ramp_logs(sim, p, rng),
        InputKind::RampsSine => {
            let mut l = ramp_logs(sim, p, rng);
            l.push(sine_log(sim, p, rng));
            l
        }
        InputKind::Sine => vec![sine_log(sim, p, rng)],
        InputKind::Prbs => vec![prbs_log(sim, p, rng)],
        InputKind::ClosedLoop => vec![closed_loop_log(sim, p, rng)],
    }
}

/// One identification: a random plant, the logs of `input` on `sim`, `identify` as the CLI
/// calls it with the true electrical constants.
pub fn run_case(sim: SimKind, input: InputKind, seed: u64) -> Outcome {
    let mut rng = SplitMix64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xCA11_B8A7E);
    let truth = draw_plant(&mut rng);
    let recs = logs(sim, input, &truth, &mut rng);
    // The `--params` of the user: the true electrical constants, no mechanical overrides.
    let params = PlantParams {
        j_eq: None,
        b_eq: None,
        tau_sf: None,
        ..truth
    };
    let t = [truth.j_eq(), truth.b_eq(), truth.tau_sf()];
    let exps: Result<Vec<Experiment>, _> = recs
        .iter()
        .map(|r| Experiment::from_record(r, &params))
        .collect();
    let (est, refused) = match exps
        .map_err(|e| e.to_string())
        .and_then(|e| identify(&e, &params, &IdentifyOptions::default()).map_err(|e| e.to_string()))
    {
        Ok(r) => ([r.j_eq(), r.b_eq(), r.tau_sf()], None),
        Err(e) => ([None, None, None], Some(e)),
    };
    Outcome {
        sim,
        input,
        seed,
        est,
        truth: t,
        refused,
    }
}

/// Coverage table: per parameter, (covered, identified, refused/missing) and the median relative
/// half-width of the interval.
pub struct Tally {
    pub covered: [usize; 3],
    pub total: [usize; 3],
    pub missing: [usize; 3],
    pub half_widths: [Vec<f64>; 3],
    pub z: [Vec<f64>; 3],
}

impl Tally {
    pub fn new(outcomes: &[&Outcome]) -> Tally {
        let mut t = Tally {
            covered: [0; 3],
            total: [0; 3],
            missing: [0; 3],
            half_widths: Default::default(),
            z: Default::default(),
        };
        for o in outcomes {
            for k in 0..3 {
                match &o.est[k] {
                    Some((e, _)) => {
                        t.total[k] += 1;
                        if e.contains(o.truth[k]) {
                            t.covered[k] += 1;
                        }
                        let hw = 0.5 * (e.ci95.1 - e.ci95.0);
                        t.half_widths[k].push(hw / o.truth[k]);
                        t.z[k].push((e.value - o.truth[k]) / hw.max(1e-300));
                    }
                    None => t.missing[k] += 1,
                }
            }
        }
        t
    }
    pub fn coverage(&self, k: usize) -> f64 {
        self.covered[k] as f64 / self.total[k].max(1) as f64
    }
    pub fn line(&self, label: &str) -> String {
        let med = |v: &[f64]| {
            let mut v = v.to_vec();
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
        };
        let mut s = format!("{label:<24}");
        for k in 0..3 {
            s.push_str(&format!(
                " | {:>6} {:>3}/{:<3} {:5.1} % hw {:7.3} % |z|med {:5.2}",
                NAMES[k],
                self.covered[k],
                self.total[k],
                100.0 * self.coverage(k),
                100.0 * med(&self.half_widths[k]),
                med(&self.z[k].iter().map(|z| z.abs()).collect::<Vec<_>>()),
            ));
            if self.missing[k] > 0 {
                s.push_str(&format!(" ({} none)", self.missing[k]));
            }
        }
        s
    }
}

/// Runs `per` seeds of every (simulator, input) pair from `seed0` on two threads and prints the
/// tables; returns the outcomes.
pub fn run_grid(per: u64, seed0: u64) -> Vec<Outcome> {
    let mut cases = Vec::new();
    for sim in [SimKind::Servo, SimKind::Other] {
        for input in INPUTS {
            for s in 0..per {
                cases.push((sim, input, seed0 + s));
            }
        }
    }
    let outcomes: Vec<Outcome> = cases
        .iter()
        .map(|&(sim, input, seed)| run_case(sim, input, seed))
        .collect();
    for o in &outcomes {
        if let Some(r) = &o.refused {
            eprintln!("{:?} {:?} seed {}: refused: {r}", o.sim, o.input, o.seed);
        }
        for k in 0..3 {
            if let Some((e, m)) = &o.est[k] {
                if !e.contains(o.truth[k]) {
                    eprintln!(
                        "  miss {:?} {:?} seed {} {} ({m}): {:.4e} [{:.4e}, {:.4e}] truth {:.4e} ({:+.2} %)",
                        o.sim,
                        o.input,
                        o.seed,
                        NAMES[k],
                        e.value,
                        e.ci95.0,
                        e.ci95.1,
                        o.truth[k],
                        100.0 * (e.value / o.truth[k] - 1.0)
                    );
                }
            }
        }
    }
    for sim in [SimKind::Servo, SimKind::Other] {
        for input in INPUTS {
            let sel: Vec<&Outcome> = outcomes
                .iter()
                .filter(|o| o.sim == sim && o.input == input)
                .collect();
            eprintln!("{}", Tally::new(&sel).line(&format!("{sim:?} {input:?}")));
        }
    }
    let all: Vec<&Outcome> = outcomes.iter().collect();
    eprintln!("{}", Tally::new(&all).line("ALL"));
    outcomes
}

/// The benchmark: 2 simulators x 5 inputs x 24 seeds = 240 identifications.
#[test]
#[ignore]
fn calibration_benchmark() {
    let _machine = servo_e2e::shared();
    let per = std::env::var("SERVO_CALIBRATION_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(24);
    let start = std::time::Instant::now();
    let out = run_grid(per, 1000);
    let all: Vec<&Outcome> = out.iter().collect();
    let t = Tally::new(&all);
    eprintln!(
        "{} identifications in {:.1} s",
        out.len(),
        start.elapsed().as_secs_f64()
    );
    for k in 0..3 {
        assert!(
            (0.90..=0.98).contains(&t.coverage(k)),
            "{}: coverage {:.1} %",
            NAMES[k],
            100.0 * t.coverage(k)
        );
    }
}

/// A fast subset of the benchmark (both simulators, every input, other seeds): below 85 %
/// coverage for any parameter fails.
#[test]
fn intervals_cover_the_truth_on_a_fast_subset() {
    let _machine = servo_e2e::shared();
    let start = std::time::Instant::now();
    let out = run_grid(3, 1);
    eprintln!(
        "{} identifications in {:.1} s",
        out.len(),
        start.elapsed().as_secs_f64()
    );
    let all: Vec<&Outcome> = out.iter().collect();
    let t = Tally::new(&all);
    for k in 0..3 {
        assert!(
            t.coverage(k) >= 0.85,
            "{}: coverage {:.1} % ({}/{})",
            NAMES[k],
            100.0 * t.coverage(k),
            t.covered[k],
            t.total[k]
        );
    }
}

// ---- A catalogue effect: the base and an imbalance fitted as `servo compare --add` does ----

/// The parameters of an effect case: the base, then the imbalance's main parameter.
pub const EFFECT_NAMES: [&str; 4] = ["J_eq", "B_eq", "tau_sf", "imbalance.amplitude"];

/// One fit of the base with an added imbalance, as `servo compare --add imbalance` makes it
/// ([`servo_core::fit::fit_model`], default options, the model's base as the start): per
/// parameter of [`EFFECT_NAMES`] the estimate and its printed 95 % half-width (1.96 se), and the
/// truth. This is also the fit `servo trend` makes of each log (with the model's effects).
#[derive(Debug, Clone)]
pub struct EffectOutcome {
    pub sim: SimKind,
    pub input: InputKind,
    pub seed: u64,
    /// (value, 95 % half-width); `None`: no value or no interval.
    pub est: [Option<(f64, f64)>; 4],
    pub truth: [f64; 4],
    pub refused: Option<String>,
}

/// A random plant with an imbalance of 0.5-2.5 x its Coulomb level at a random phase, the
/// logs of `input` on `sim`, and the fit of the base with `--add imbalance`.
pub fn run_effect_case(sim: SimKind, input: InputKind, seed: u64) -> EffectOutcome {
    use servo_core::fit::{fit_model, EffectToFit, FitOptions};
    let mut rng = SplitMix64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x00EF_FEC7);
    let p = draw_plant(&mut rng);
    let amp = p.tau_sf() * (0.5 + 2.0 * rng.uniform());
    let phase = TAU * rng.uniform() - std::f64::consts::PI;
    let rig = Rig {
        p,
        imbalance: Some((amp, phase)),
    };
    let recs = rig_logs(sim, input, &rig, &mut rng);
    // The model the user compares against: the true electrical constants, the lab's mechanics.
    let lab = PlantParams::LAB;
    let start = Plant::from_params(PlantParams {
        j_eq: lab.j_eq,
        b_eq: lab.b_eq,
        tau_sf: lab.tau_sf,
        ..p
    })
    .unwrap();
    let truth = [p.j_eq(), p.b_eq(), p.tau_sf(), amp];
    let add = [EffectToFit::parse("imbalance").unwrap()];
    let (est, refused) = match fit_model(&recs, &start, &add, &FitOptions::default()) {
        Ok(f) => {
            let get = |effect: Option<&str>, key: &str| {
                f.params
                    .iter()
                    .find(|e| {
                        e.key == key && effect.is_none_or(|n| e.effect.map(|k| k.name()) == Some(n))
                    })
                    .and_then(|e| Some((e.value, 1.96 * e.std_err?)))
            };
            (
                [
                    get(None, "j_eq"),
                    get(None, "b_eq"),
                    get(None, "tau_sf"),
                    get(Some("imbalance"), "amplitude"),
                ],
                None,
            )
        }
        Err(e) => ([None; 4], Some(e.to_string())),
    };
    EffectOutcome {
        sim,
        input,
        seed,
        est,
        truth,
        refused,
    }
}

/// Per parameter of [`EFFECT_NAMES`]: (covered, with an interval), over `outcomes`.
pub fn effect_coverage(outcomes: &[&EffectOutcome]) -> [(usize, usize); 4] {
    let mut c = [(0, 0); 4];
    for o in outcomes {
        for k in 0..4 {
            if let Some((v, hw)) = o.est[k] {
                c[k].1 += 1;
                if (v - o.truth[k]).abs() <= hw {
                    c[k].0 += 1;
                }
            }
        }
    }
    c
}

fn effect_line(label: &str, outcomes: &[&EffectOutcome]) -> String {
    let mut s = format!("{label:<24}");
    for (k, (a, n)) in effect_coverage(outcomes).iter().enumerate() {
        s.push_str(&format!(
            " | {} {a}/{n} {:5.1} %",
            EFFECT_NAMES[k],
            100.0 * *a as f64 / (*n).max(1) as f64
        ));
    }
    s
}

/// `per` seeds of every (simulator, input) pair from `seed0`; prints the misses and tables.
pub fn run_effect_grid(per: u64, seed0: u64) -> Vec<EffectOutcome> {
    let mut out = Vec::new();
    for sim in [SimKind::Servo, SimKind::Other] {
        for input in INPUTS {
            for s in 0..per {
                out.push(run_effect_case(sim, input, seed0 + s));
            }
        }
    }
    for o in &out {
        if let Some(r) = &o.refused {
            eprintln!("{:?} {:?} seed {}: refused: {r}", o.sim, o.input, o.seed);
        }
        for k in 0..4 {
            if let Some((v, hw)) = o.est[k] {
                if (v - o.truth[k]).abs() > hw {
                    eprintln!(
                        "  miss {:?} {:?} seed {} {}: {v:.4e} +/- {hw:.2e} truth {:.4e} ({:+.2} %)",
                        o.sim,
                        o.input,
                        o.seed,
                        EFFECT_NAMES[k],
                        o.truth[k],
                        100.0 * (v / o.truth[k] - 1.0)
                    );
                }
            }
        }
    }
    for sim in [SimKind::Servo, SimKind::Other] {
        for input in INPUTS {
            let sel: Vec<&EffectOutcome> = out
                .iter()
                .filter(|o| o.sim == sim && o.input == input)
                .collect();
            eprintln!("{}", effect_line(&format!("{sim:?} {input:?}"), &sel));
        }
    }
    let all: Vec<&EffectOutcome> = out.iter().collect();
    eprintln!("{}", effect_line("ALL", &all));
    out
}

/// The effect benchmark: 2 simulators x 5 inputs x 24 seeds = 240 fits with an imbalance
/// (`SERVO_CALIBRATION_SEEDS` seeds per pair).
#[test]
#[ignore]
fn effect_calibration_benchmark() {
    let _machine = servo_e2e::shared();
    let per = std::env::var("SERVO_CALIBRATION_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(24);
    let start = std::time::Instant::now();
    let out = run_effect_grid(per, 1000);
    eprintln!(
        "{} fits in {:.1} s",
        out.len(),
        start.elapsed().as_secs_f64()
    );
    let all: Vec<&EffectOutcome> = out.iter().collect();
    for (k, (a, n)) in effect_coverage(&all).iter().enumerate() {
        let c = *a as f64 / (*n).max(1) as f64;
        assert!(
            (0.90..=0.98).contains(&c),
            "{}: coverage {:.1} %",
            EFFECT_NAMES[k],
            100.0 * c
        );
    }
}

/// A fast subset of the effect benchmark (both simulators, every input, other seeds): below
/// 85 % coverage of any parameter, the imbalance's amplitude included, fails.
#[test]
fn effect_intervals_cover_the_truth_on_a_fast_subset() {
    let _machine = servo_e2e::shared();
    let start = std::time::Instant::now();
    let out = run_effect_grid(2, 1);
    eprintln!(
        "{} fits in {:.1} s",
        out.len(),
        start.elapsed().as_secs_f64()
    );
    let all: Vec<&EffectOutcome> = out.iter().collect();
    for (k, (a, n)) in effect_coverage(&all).iter().enumerate() {
        assert!(
            *n >= out.len() * 3 / 4 && *a as f64 >= 0.85 * *n as f64,
            "{}: {a} of {n} intervals hold the truth ({} fits)",
            EFFECT_NAMES[k],
            out.len()
        );
    }
}
