//! The step responses of the loop that will actually run, checked against time-domain specs.
//!
//! The handout's translation (eqs. 31-41) assumes a second-order closed loop. The loop that runs
//! has the PID's zeros, the derivative filter (eq. 53), the zero-order hold at T_s and a voltage
//! limit, so its overshoot and settling time differ, and with the limit they also depend on the
//! step size. This module simulates that loop: the discrete PID of [`crate::control::pid`]
//! (derivative on the error or on the measurement, back-calculation anti-windup, output limit)
//! driving the exactly ZOH-discretised plant, for reference steps from `step_min_rad` to
//! `step_max_rad`, and measures each response against the spec.
//!
//! # Step convention
//! Two starts, as `servo run` gives them ([`StepStart`]):
//! * later (`servo run --ref step:A@t0`, t0 > 0): the loop starts at rest with r = 0 (the
//!   controller's first sample primes its derivative history), and the reference steps to A at
//!   the next sample, t = 0 of the metrics; with the derivative on the error this sample kicks;
//! * at start (`--ref step:A`, any first move after power-up): the step is the controller's first
//!   sample, whose derivative history is primed with it (no kick).
//!
//! [`check_steps`] simulates both (one when the derivative acts on the measurement: they are then
//! the same) and keeps the worse at each size, so a design cannot rely on the kick. Metrics are
//! relative to A: overshoot (max y - A)/A, settling time = last time |y - A| > band A, 10-90 %
//! rise time.

// Small dense loops read best with explicit indices.
#![allow(clippy::needless_range_loop)]

use super::controller::Discretization;
use super::ss::DiscreteStateSpace;
use super::DesignError;
use crate::control::pid::{AntiWindup, DerivativeOn, Pid, PidConfig, PidGains};
use crate::math;
use alloc::vec::Vec;

/// Largest plant order the simulation handles (the full model has 4 states).
pub const MAX_ORDER: usize = 8;

/// The controller structure around the gains: what `servo run` builds from the gains file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopStructure {
    /// What the derivative acts on.
    pub derivative_on: DerivativeOn,
    /// Back-calculation anti-windup gain K_w [1/s]; `None`: no anti-windup.
    pub kw_per_s: Option<f64>,
    /// Symmetric output (driver input) limit [V]; infinite: none.
    pub u_limit_v: f64,
    /// Discretisation of the integral and the derivative.
    pub discretization: Discretization,
}

impl LoopStructure {
    /// The PID configuration of `gains` at period `ts_s` [s] with this structure.
    pub fn pid_config(&self, gains: &PidGains, ts_s: f64) -> PidConfig {
        let mut c = PidConfig::new(*gains, ts_s);
        if self.u_limit_v.is_finite() {
            c = c.with_symmetric_limit(self.u_limit_v);
        }
        c.derivative_on = self.derivative_on;
        c.discretization = self.discretization;
        c.anti_windup = match self.kw_per_s {
            Some(kw) => AntiWindup::BackCalculation { kw },
            None => AntiWindup::None,
        };
        c
    }

    /// Checks the limit (> 0) and K_w (finite, >= 0).
    pub fn validate(&self) -> Result<(), DesignError> {
        if self.u_limit_v.is_nan() || self.u_limit_v <= 0.0 {
            return Err(DesignError::OutOfRange {
                name: "voltage limit [V]",
                value: self.u_limit_v,
                why: "the output limit must be > 0 V (e.g. --u-limit 10)",
            });
        }
        if let Some(kw) = self.kw_per_s {
            if !(kw.is_finite() && kw >= 0.0) {
                return Err(DesignError::OutOfRange {
                    name: "K_w [1/s]",
                    value: kw,
                    why: "the anti-windup gain must be a finite number >= 0",
                });
            }
        }
        Ok(())
    }
}

/// The speed requirement of a time-domain spec.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SpeedTarget {
    /// Settle within +-`band` (0.05 or 0.01 of the step) by `time_s` [s].
    Settling { band: f64, time_s: f64 },
    /// 10-90 % rise time at most `time_s` [s].
    Rise { time_s: f64 },
}

/// Time-domain specs on the steps of a range of sizes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimeSpecs {
    /// Largest overshoot [fraction of the step]; `None`: not specified.
    pub overshoot_max: Option<f64>,
    /// Speed requirement; `None`: not specified.
    pub speed: Option<SpeedTarget>,
    /// Smallest step size [rad] (> 0).
    pub step_min_rad: f64,
    /// Largest step size [rad] (>= step_min_rad).
    pub step_max_rad: f64,
}

impl TimeSpecs {
    /// Checks the numbers.
    pub fn validate(&self) -> Result<(), DesignError> {
        if let Some(m) = self.overshoot_max {
            if !(m.is_finite() && m > 0.0 && m < 1.0) {
                return Err(DesignError::OutOfRange {
                    name: "overshoot [fraction]",
                    value: m,
                    why: "it must lie in (0, 1): 0.1 means 10 %",
                });
            }
        }
        let t = match self.speed {
            Some(SpeedTarget::Settling { band, time_s }) => {
                if !(band > 0.0 && band < 1.0) {
                    return Err(DesignError::OutOfRange {
                        name: "settling band [fraction]",
                        value: band,
                        why: "it must lie in (0, 1)",
                    });
                }
                time_s
            }
            Some(SpeedTarget::Rise { time_s }) => time_s,
            None => 1.0,
        };
        if !(t.is_finite() && t > 0.0) {
            return Err(DesignError::OutOfRange {
                name: "time spec [s]",
                value: t,
                why: "a settling or rise time must be a finite number of seconds > 0",
            });
        }
        let (a, b) = (self.step_min_rad, self.step_max_rad);
        if !(a.is_finite() && a > 0.0) {
            return Err(DesignError::OutOfRange {
                name: "--step-min [rad]",
                value: a,
                why: "the smallest step must be a finite number of radians > 0",
            });
        }
        if !(b.is_finite() && b >= a) {
            return Err(DesignError::OutOfRange {
                name: "--step-max [rad]",
                value: b,
                why: "the largest step must be finite and >= --step-min",
            });
        }
        Ok(())
    }

    /// Band of the settling time to report: the spec's, else 5 %.
    pub fn band(&self) -> f64 {
        match self.speed {
            Some(SpeedTarget::Settling { band, .. }) => band,
            _ => 0.05,
        }
    }

    /// `n` step sizes spread evenly over the range (one when the range is a single size).
    pub fn grid(&self, n: usize) -> Vec<f64> {
        let (a, b) = (self.step_min_rad, self.step_max_rad);
        if b <= a || n < 2 {
            return alloc::vec![a];
        }
        (0..n)
            .map(|k| a + (b - a) * k as f64 / (n - 1) as f64)
            .collect()
    }

    /// The simulated time needed to judge the specs [s], at least `floor_s`.
    pub fn horizon_s(&self, omega_gc: f64, factor: f64, floor_s: f64) -> f64 {
        let t = match self.speed {
            Some(SpeedTarget::Settling { time_s, .. }) => time_s,
            Some(SpeedTarget::Rise { time_s }) => 3.0 * time_s,
            None => 10.0 / omega_gc,
        };
        (factor * t).max(floor_s)
    }
}

/// Metrics of one simulated step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOutcome {
    /// Step size A [rad].
    pub step_rad: f64,
    /// Overshoot (max y - A)/A [%], 0 when y never exceeds A.
    pub overshoot_pct: f64,
    /// Settling time in the spec's band [s]; `None`: not settled within the simulated horizon.
    pub settling_time_s: Option<f64>,
    /// 10-90 % rise time [s]; `None`: 90 % never reached.
    pub rise_time_s: Option<f64>,
    /// Largest |u| [V].
    pub peak_u_v: f64,
    /// Fraction of samples at the voltage limit [-].
    pub saturated_fraction: f64,
    /// Simulated horizon [s].
    pub horizon_s: f64,
}

/// Samples of one simulated step, normalised by the step size.
#[derive(Debug, Clone, PartialEq)]
pub struct StepTrace {
    pub step_rad: f64,
    /// Time since the step [s].
    pub time_s: Vec<f64>,
    /// y / A [-].
    pub y_norm: Vec<f64>,
    /// Controller output u [V].
    pub u_v: Vec<f64>,
}

/// The ZOH plant copied into fixed arrays for a fast inner loop.
#[derive(Debug, Clone, Copy)]
pub struct FastPlant {
    n: usize,
    phi: [f64; MAX_ORDER * MAX_ORDER],
    gamma: [f64; MAX_ORDER],
    c: [f64; MAX_ORDER],
    ts_s: f64,
}

impl FastPlant {
    /// Copies a discrete plant (order at most [`MAX_ORDER`], D = 0).
    pub fn new(p: &DiscreteStateSpace) -> Result<FastPlant, DesignError> {
        let n = p.phi.nrows();
        if n == 0 || n > MAX_ORDER || p.d != 0.0 {
            return Err(DesignError::Invalid(
                "the step simulation handles strictly proper plants of order 1..8",
            ));
        }
        let mut f = FastPlant {
            n,
            phi: [0.0; MAX_ORDER * MAX_ORDER],
            gamma: [0.0; MAX_ORDER],
            c: [0.0; MAX_ORDER],
            ts_s: p.ts_s,
        };
        for i in 0..n {
            for j in 0..n {
                f.phi[i * MAX_ORDER + j] = p.phi[(i, j)];
            }
            f.gamma[i] = p.gamma[i];
            f.c[i] = p.c[i];
        }
        Ok(f)
    }

    /// Sample period T_s [s].
    pub fn ts_s(&self) -> f64 {
        self.ts_s
    }
}

/// When the reference step comes (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StepStart {
    /// After one sample at rest with r = 0 (`servo run --ref step:A@t0`).
    Later,
    /// On the controller's first sample (`servo run --ref step:A`).
    AtStart,
}

/// Simulates one step of size `step_rad` coming later in the run (see [`simulate_step_from`]).
pub fn simulate_step(
    plant: &FastPlant,
    cfg: &PidConfig,
    step_rad: f64,
    band: f64,
    horizon_s: f64,
    trace: bool,
) -> Result<(StepOutcome, Option<StepTrace>), DesignError> {
    simulate_step_from(
        plant,
        cfg,
        step_rad,
        band,
        horizon_s,
        trace,
        StepStart::Later,
    )
}

/// Simulates one step of size `step_rad` starting as `start` says, for `horizon_s`, and measures
/// it against `band`; with `trace`, also returns the samples.
pub fn simulate_step_from(
    plant: &FastPlant,
    cfg: &PidConfig,
    step_rad: f64,
    band: f64,
    horizon_s: f64,
    trace: bool,
    start: StepStart,
) -> Result<(StepOutcome, Option<StepTrace>), DesignError> {
    let mut pid = Pid::new(*cfg).map_err(|_| {
        DesignError::Invalid("the controller configuration is not valid (gains, T_s or limits)")
    })?;
    let n = plant.n;
    let ts = plant.ts_s;
    let steps = math::round(horizon_s / ts).max(1.0) as usize;
    let mut x = [0.0f64; MAX_ORDER];
    let mut xn = [0.0f64; MAX_ORDER];
    if start == StepStart::Later {
        // k = 0 of the loop: at rest, r = 0 (primes the controller).
        let u0 = pid.update(0.0, 0.0, 0.0).u_v;
        advance(plant, &mut x, &mut xn, u0);
    }
    let mut tr = trace.then(|| StepTrace {
        step_rad,
        time_s: Vec::with_capacity(steps + 1),
        y_norm: Vec::with_capacity(steps + 1),
        u_v: Vec::with_capacity(steps + 1),
    });
    let inv = 1.0 / step_rad;
    let (mut y_max, mut peak_u, mut sat) = (f64::NEG_INFINITY, 0.0f64, 0usize);
    let (mut t10, mut t90) = (None, None);
    let mut last_out: Option<usize> = None;
    let (mut y_out, mut y_after) = (0.0, f64::NAN);
    let mut y_prev = 0.0;
    for k in 0..=steps {
        let mut y = 0.0;
        for i in 0..n {
            y += plant.c[i] * x[i];
        }
        let yn = y * inv;
        let o = pid.update(step_rad, y, 0.0);
        if !(yn.is_finite() && o.u_v.is_finite()) {
            return Err(DesignError::Invalid(
                "the step simulation diverged (non-finite output)",
            ));
        }
        if let Some(t) = tr.as_mut() {
            t.time_s.push(k as f64 * ts);
            t.y_norm.push(yn);
            t.u_v.push(o.u_v);
        }
        y_max = y_max.max(yn);
        peak_u = peak_u.max(o.u_v.abs());
        if o.saturated {
            sat += 1;
        }
        if k > 0 {
            let cross = |level: f64| (k as f64 - 1.0 + (level - y_prev) / (yn - y_prev)) * ts;
            if t10.is_none() && yn >= 0.1 && y_prev < 0.1 {
                t10 = Some(cross(0.1));
            }
            if t90.is_none() && yn >= 0.9 && y_prev < 0.9 {
                t90 = Some(cross(0.9));
            }
        }
        if (yn - 1.0).abs() > band {
            last_out = Some(k);
            y_out = yn;
            y_after = f64::NAN;
        } else if last_out == Some(k.wrapping_sub(1)) {
            y_after = yn;
        }
        y_prev = yn;
        advance(plant, &mut x, &mut xn, o.u_v);
    }
    let settling_time_s = match last_out {
        None => Some(0.0),
        // out of the band at the end of the horizon, or too late to be sure it stays in
        Some(k) if k >= steps || (k as f64) > 0.9 * steps as f64 => None,
        Some(k) => {
            let target = if y_out > 1.0 { 1.0 + band } else { 1.0 - band };
            let f = if y_after != y_out {
                ((target - y_out) / (y_after - y_out)).clamp(0.0, 1.0)
            } else {
                0.0
            };
            Some((k as f64 + f) * ts)
        }
    };
    let outcome = StepOutcome {
        step_rad,
        overshoot_pct: (100.0 * (y_max - 1.0)).max(0.0),
        settling_time_s,
        rise_time_s: match (t10, t90) {
            (Some(a), Some(b)) => Some(b - a),
            _ => None,
        },
        peak_u_v: peak_u,
        saturated_fraction: sat as f64 / (steps + 1) as f64,
        horizon_s: steps as f64 * ts,
    };
    Ok((outcome, tr))
}

#[inline]
fn advance(p: &FastPlant, x: &mut [f64; MAX_ORDER], xn: &mut [f64; MAX_ORDER], u: f64) {
    let n = p.n;
    for i in 0..n {
        let row = &p.phi[i * MAX_ORDER..i * MAX_ORDER + n];
        let mut acc = p.gamma[i] * u;
        for j in 0..n {
            acc += row[j] * x[j];
        }
        xn[i] = acc;
    }
    x[..n].copy_from_slice(&xn[..n]);
}

/// How one step outcome measures against the specs: (overshoot / spec, speed figure / spec), each
/// 0 when not specified; an unsettled response counts as twice the horizon.
pub fn spec_ratios(o: &StepOutcome, specs: &TimeSpecs) -> (f64, f64) {
    let os = match specs.overshoot_max {
        Some(m) => o.overshoot_pct / (100.0 * m),
        None => 0.0,
    };
    let sp = match specs.speed {
        Some(SpeedTarget::Settling { time_s, .. }) => {
            o.settling_time_s.unwrap_or(2.0 * o.horizon_s) / time_s
        }
        Some(SpeedTarget::Rise { time_s }) => o.rise_time_s.unwrap_or(2.0 * o.horizon_s) / time_s,
        None => 0.0,
    };
    (os, sp)
}

/// The check of a whole step range.
#[derive(Debug, Clone, PartialEq)]
pub struct RangeCheck {
    pub specs: TimeSpecs,
    pub structure: LoopStructure,
    /// One outcome per checked step size, ascending.
    pub outcomes: Vec<StepOutcome>,
    /// Worst overshoot over the range [%].
    pub worst_overshoot_pct: f64,
    /// Worst speed figure over the range: settling time in the spec's band, or rise time with a
    /// rise-time spec [s]; `None`: some step did not settle (or rise) within the horizon.
    pub worst_speed_s: Option<f64>,
    /// max over the range of (overshoot / spec, speed / spec): <= 1 means met.
    pub worst_ratio: f64,
}

impl RangeCheck {
    /// Whether every specified figure is met at every checked step size.
    pub fn met(&self) -> bool {
        self.worst_ratio <= 1.0
    }

    /// The overshoot shortfall [percentage points] when missed.
    pub fn overshoot_excess_pct(&self) -> Option<f64> {
        let m = 100.0 * self.specs.overshoot_max?;
        (self.worst_overshoot_pct > m).then_some(self.worst_overshoot_pct - m)
    }

    /// The speed shortfall [s] when missed (infinite when not settled within the horizon).
    pub fn speed_excess_s(&self) -> Option<f64> {
        let t = match self.specs.speed? {
            SpeedTarget::Settling { time_s, .. } | SpeedTarget::Rise { time_s } => time_s,
        };
        match self.worst_speed_s {
            None => Some(f64::INFINITY),
            Some(w) => (w > t).then_some(w - t),
        }
    }
}

/// Simulates `n_steps` step sizes over the specs' range for `horizon_s` and collects the worst
/// figures.
pub fn check_range(
    plant: &FastPlant,
    gains: &PidGains,
    structure: &LoopStructure,
    specs: &TimeSpecs,
    n_steps: usize,
    horizon_s: f64,
) -> Result<RangeCheck, DesignError> {
    check_steps(
        plant,
        gains,
        structure,
        specs,
        &specs.grid(n_steps),
        horizon_s,
    )
}

/// As [`check_range`] for the given step sizes [rad].
pub fn check_steps(
    plant: &FastPlant,
    gains: &PidGains,
    structure: &LoopStructure,
    specs: &TimeSpecs,
    steps_rad: &[f64],
    horizon_s: f64,
) -> Result<RangeCheck, DesignError> {
    let cfg = structure.pid_config(gains, plant.ts_s);
    let band = specs.band();
    let mut outcomes = Vec::with_capacity(steps_rad.len());
    let (mut wo, mut ws, mut wr) = (0.0f64, Some(0.0f64), 0.0f64);
    let starts: &[StepStart] = match structure.derivative_on {
        DerivativeOn::Error => &[StepStart::Later, StepStart::AtStart],
        DerivativeOn::Measurement => &[StepStart::Later],
    };
    for &a in steps_rad {
        // The worse of the starts at this size.
        let mut worst: Option<(StepOutcome, f64)> = None;
        for &st in starts {
            let (o, _) = simulate_step_from(plant, &cfg, a, band, horizon_s, false, st)?;
            let (r1, r2) = spec_ratios(&o, specs);
            let r = r1.max(r2);
            if worst.as_ref().is_none_or(|(_, w)| r > *w) {
                worst = Some((o, r));
            }
        }
        let Some((o, _)) = worst else { continue };
        wo = wo.max(o.overshoot_pct);
        let speed = match specs.speed {
            Some(SpeedTarget::Rise { .. }) => o.rise_time_s,
            _ => o.settling_time_s,
        };
        ws = match (ws, speed) {
            (Some(w), Some(s)) => Some(w.max(s)),
            _ => None,
        };
        let (r1, r2) = spec_ratios(&o, specs);
        wr = wr.max(r1).max(r2);
        outcomes.push(o);
    }
    Ok(RangeCheck {
        specs: *specs,
        structure: *structure,
        outcomes,
        worst_overshoot_pct: wo,
        worst_speed_s: ws,
        worst_ratio: wr,
    })
}

/// Step sizes of a design's check over its range.
pub const CHECK_STEPS: usize = 17;

/// The check of a verified design: its gains with `structure` on its discrete plant (the full
/// model when known, ZOH at T_s), [`CHECK_STEPS`] step sizes over the specs' range, a horizon of
/// 10 times the speed spec (at least 1 s).
pub fn check_report(
    report: &super::verify::DesignReport,
    structure: &LoopStructure,
    specs: &TimeSpecs,
) -> Result<RangeCheck, DesignError> {
    specs.validate()?;
    structure.validate()?;
    let plant = FastPlant::new(&report.discrete_plant)?;
    check_range(
        &plant,
        &report.gains,
        structure,
        specs,
        CHECK_STEPS,
        specs.horizon_s(report.request.spec.omega_gc, 10.0, 1.0),
    )
}

/// The normalised responses at the given step sizes (for plots).
pub fn traces(
    plant: &FastPlant,
    gains: &PidGains,
    structure: &LoopStructure,
    band: f64,
    steps_rad: &[f64],
    horizon_s: f64,
) -> Result<Vec<StepTrace>, DesignError> {
    let cfg = structure.pid_config(gains, plant.ts_s);
    let mut out = Vec::with_capacity(steps_rad.len());
    for &a in steps_rad {
        if let (_, Some(t)) = simulate_step(plant, &cfg, a, band, horizon_s, true)? {
            out.push(t);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::closed_loop::ClosedLoop;
    use crate::design::step::{metrics, step_response};
    use crate::design::PlantModel;
    use crate::params::PlantParams;

    const G: PidGains = PidGains {
        kp: 7.0476,
        ki: 86.121,
        kd: 0.14418,
        tl_s: 1.0 / 150.0,
    };

    fn linear() -> LoopStructure {
        LoopStructure {
            derivative_on: DerivativeOn::Error,
            kw_per_s: None,
            u_limit_v: f64::INFINITY,
            discretization: Discretization::BackwardEuler,
        }
    }

    /// Without a limit the loop is linear: every step size gives the unit-step metrics of the
    /// closed-loop state-space model (`step`), which is built independently of `control::pid`.
    #[test]
    fn unlimited_loop_matches_the_linear_closed_loop() {
        let d = PlantModel::full(&PlantParams::TABLE2)
            .state_space()
            .discretize_zoh(1e-3);
        let cl = ClosedLoop::discrete(&d, &G, Discretization::BackwardEuler);
        let m = metrics(&step_response(&cl, 1.0, 0));
        let plant = FastPlant::new(&d).unwrap();
        let specs = TimeSpecs {
            overshoot_max: Some(0.1),
            speed: Some(SpeedTarget::Settling {
                band: 0.05,
                time_s: 0.15,
            }),
            step_min_rad: 0.2,
            step_max_rad: 2.0,
        };
        let c = check_range(&plant, &G, &linear(), &specs, 4, 1.0).unwrap();
        // A step later in the run is the linear model's step (the derivative kicks on its first
        // sample); the check keeps the worse of that and the step at start (no kick), so its
        // outcomes are at least as bad.
        let cfg = linear().pid_config(&G, 1e-3);
        for o in &c.outcomes {
            assert!(o.overshoot_pct >= m.overshoot_pct - 1e-9, "{o:?} {m:?}");
            let (o, _) = simulate_step(&plant, &cfg, o.step_rad, 0.05, 1.0, false).unwrap();
            assert!(
                (o.overshoot_pct - m.overshoot_pct).abs() < 1e-9,
                "{o:?} {m:?}"
            );
            let (a, b) = (o.settling_time_s.unwrap(), m.settling_time_5pct_s.unwrap());
            assert!((a - b).abs() < 1e-9, "{a} {b}");
            assert!((o.rise_time_s.unwrap() - m.rise_time_s.unwrap()).abs() < 1e-9);
        }
        // 20 % overshoot misses a 10 % spec by ~2x
        assert!(!c.met() && c.worst_ratio > 1.5, "{c:?}");
        assert!(c.overshoot_excess_pct().unwrap() > 5.0);
    }

    /// With a 10 V limit, small steps stay linear and large ones saturate and change.
    #[test]
    fn limit_makes_large_steps_differ() {
        let d = PlantModel::full(&PlantParams::TABLE2)
            .state_space()
            .discretize_zoh(1e-3);
        let plant = FastPlant::new(&d).unwrap();
        let s = LoopStructure {
            u_limit_v: 10.0,
            ..linear()
        };
        let cfg = s.pid_config(&G, 1e-3);
        let (small, _) = simulate_step(&plant, &cfg, 0.05, 0.05, 1.0, false).unwrap();
        let (lin, _) = simulate_step(
            &plant,
            &linear().pid_config(&G, 1e-3),
            0.05,
            0.05,
            1.0,
            false,
        )
        .unwrap();
        assert_eq!(small.saturated_fraction, 0.0);
        assert!((small.overshoot_pct - lin.overshoot_pct).abs() < 1e-12);
        let (big, t) = simulate_step(&plant, &cfg, 3.0, 0.05, 1.0, true).unwrap();
        assert!(big.saturated_fraction > 0.0 && big.peak_u_v <= 10.0 + 1e-12);
        assert!(
            (big.overshoot_pct - lin.overshoot_pct).abs() > 1.0,
            "{big:?} {lin:?}"
        );
        let t = t.unwrap();
        assert_eq!(t.time_s.len(), t.y_norm.len());
        assert!(t.u_v.iter().all(|u| u.abs() <= 10.0 + 1e-12));
    }
}
