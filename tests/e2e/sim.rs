//! End-to-end tests of the simulated gearmotor: accuracy against an exact ZOH solution and a fine
//! reference integration, and the visible signature of every catalogue effect.

use servo_core::effects::Effect;
use servo_core::sim::{PlantSim, PlantState, SensorConfig, Sensors};
use servo_core::{Plant, PlantParams};

const DT: f64 = 1e-3;
const B_EQ: f64 = 1.5e-6;

fn plant(specs: &[&str]) -> Plant {
    let mut p = Plant::nominal();
    p.effects
        .insert(Effect::parse(&format!("viscous:b_eq={B_EQ}")).unwrap());
    for s in specs {
        p.effects.insert(Effect::parse(s).unwrap());
    }
    p
}

fn run(sim: &mut PlantSim, u: impl Fn(usize) -> f64, steps: usize) -> Vec<PlantState> {
    let mut out = vec![*sim.state()];
    for k in 0..steps {
        out.push(*sim.step(u(k)));
    }
    out
}

/// Voltage that holds a motor torque `tau_l` [N m, load side] at standstill (steady current).
fn u_for_load_torque(p: &PlantParams, tau_l: f64) -> f64 {
    tau_l / p.n / p.k_t * p.r_eq() / p.k_drv
}

// ---------------------------------------------------------------------------------------------
// Independent reference: RK4 at 1 us with its own stick-slip logic, written from eqs. 18-21.
// ---------------------------------------------------------------------------------------------

struct Reference {
    p: PlantParams,
    b_eq: f64,
    tau_c: (f64, f64),
    stribeck: Option<(f64, f64)>,
    cog: Option<(f64, f64, f64)>,
    imb: Option<(f64, f64)>,
    /// (gap, stiffness, damping, load fraction)
    backlash: Option<(f64, f64, f64, f64)>,
    delay_s: f64,
}

impl Reference {
    fn new(plant: &Plant) -> Reference {
        let e = &plant.effects;
        use servo_core::EffectKind as K;
        let c = e.value(K::Coulomb, "tau_sf").unwrap_or(0.0);
        let tau_c = match e.get(K::Asymmetry) {
            Some(a) => (a.get("tau_sf_pos").unwrap(), a.get("tau_sf_neg").unwrap()),
            None => (c, c),
        };
        Reference {
            p: plant.params,
            b_eq: plant.b_eq(),
            tau_c,
            stribeck: e
                .get(K::Stribeck)
                .map(|s| (s.get("tau_s").unwrap(), s.get("omega_s").unwrap())),
            cog: e.get(K::Cogging).map(|c| {
                (
                    c.get("amplitude").unwrap(),
                    c.get("harmonic").unwrap(),
                    c.get("phase").unwrap(),
                )
            }),
            imb: e
                .get(K::Imbalance)
                .map(|c| (c.get("amplitude").unwrap(), c.get("phase").unwrap())),
            backlash: e.get(K::Backlash).map(|b| {
                (
                    b.get("gap").unwrap(),
                    b.get("stiffness").unwrap(),
                    b.get("damping").unwrap(),
                    b.get("load_inertia_fraction").unwrap(),
                )
            }),
            delay_s: e.value(K::Delay, "delay").unwrap_or(0.0),
        }
    }

    fn dry(&self) -> bool {
        self.tau_c.0 > 0.0 || self.tau_c.1 > 0.0 || self.stribeck.is_some()
    }

    fn breakaway(&self, dir: f64) -> f64 {
        match self.stribeck {
            Some((s, _)) => s,
            None => {
                if dir > 0.0 {
                    self.tau_c.0
                } else {
                    self.tau_c.1
                }
            }
        }
    }

    /// Kinetic friction (load side, signed) for direction `dir` at load speed `w_l`.
    fn friction(&self, dir: f64, w_l: f64) -> f64 {
        let c = if dir > 0.0 {
            self.tau_c.0
        } else {
            self.tau_c.1
        };
        let level = match self.stribeck {
            Some((s, ws)) => c + (s - c) * (-(w_l / ws) * (w_l / ws)).exp(),
            None => c,
        };
        dir * level
    }

    fn contact(&self, x: &[f64; 6]) -> f64 {
        let (g, k, c, _) = self.backlash.unwrap();
        let d = x[3] / self.p.n - x[5];
        let dd = x[2] / self.p.n - x[4];
        if d > g / 2.0 {
            (k * (d - g / 2.0) + c * dd).max(0.0)
        } else if d < -g / 2.0 {
            (k * (d + g / 2.0) + c * dd).min(0.0)
        } else {
            0.0
        }
    }

    /// Net torque on the motor-side body without friction [N m], motor side.
    fn motor_drive(&self, x: &[f64; 6]) -> f64 {
        let p = &self.p;
        let mut t = p.k_t * x[1];
        if let Some((a, h, ph)) = self.cog {
            t -= a * (h * x[3] + ph).sin();
        }
        if self.backlash.is_some() {
            t -= self.contact(x) / p.n;
        } else if let Some((a, ph)) = self.imb {
            t -= a * (x[3] / p.n + ph).sin() / p.n;
        }
        t
    }

    /// Net torque without friction on the body carrying the dry friction (the drivetrain, or the
    /// load with backlash) [N m], load side.
    fn drive(&self, x: &[f64; 6]) -> f64 {
        if self.backlash.is_some() {
            self.contact(x) - self.imb.map_or(0.0, |(a, ph)| a * (x[5] + ph).sin())
        } else {
            self.motor_drive(x) * self.p.n
        }
    }

    fn deriv(&self, x: &[f64; 6], u: f64, stuck: bool, dir: f64) -> [f64; 6] {
        let p = &self.p;
        let j = p.j_eq();
        let mut d = [0.0; 6];
        d[0] = (p.k_drv * u - x[0]) / p.t_drv();
        d[1] = (x[0] - p.r_eq() * x[1] - p.k_e * x[2]) / p.l_a;
        match self.backlash {
            None => {
                let fric = if self.dry() && !stuck {
                    self.friction(dir, x[2] / p.n) / p.n
                } else {
                    0.0
                };
                if !stuck {
                    d[2] = (self.motor_drive(x) - self.b_eq * x[2] - fric) / j;
                }
                d[3] = x[2];
            }
            Some((_, _, _, f)) => {
                // Dry friction on the load body.
                let fric = if self.dry() && !stuck {
                    self.friction(dir, x[4])
                } else {
                    0.0
                };
                let (j1, j2) = (j * (1.0 - f), p.n * p.n * j * f);
                d[2] = (self.motor_drive(x) - self.b_eq * (1.0 - f) * x[2]) / j1;
                d[3] = x[2];
                if !stuck {
                    let imb = self.imb.map_or(0.0, |(a, ph)| a * (x[5] + ph).sin());
                    d[4] = (self.contact(x) - p.n * p.n * self.b_eq * f * x[4] - imb - fric) / j2;
                }
                d[5] = x[4];
            }
        }
        d
    }

    /// Simulates `steps` control periods of the ZOH input `u(k)` with RK4 at `h` [s].
    fn run(&self, u: impl Fn(usize) -> f64, steps: usize, h: f64) -> Vec<[f64; 6]> {
        let m = (DT / h).round() as usize;
        let mut x = [0.0; 6];
        let mut stuck = self.dry();
        let mut dir = 0.0;
        let mut out = vec![x];
        let delay_sub = (self.delay_s / h).round() as usize;
        let input = |i: usize| -> f64 {
            // sub-step i of the whole run; input after the delay.
            if i < delay_sub {
                0.0
            } else {
                u((i - delay_sub) / m)
            }
        };
        for k in 0..steps {
            for s in 0..m {
                let uu = input(k * m + s);
                if stuck && self.dry() {
                    let drive = self.drive(&x);
                    let d = drive.signum();
                    if drive.abs() * self.p.n > self.breakaway(d) {
                        stuck = false;
                        dir = d;
                    }
                }
                let f = |y: &[f64; 6]| self.deriv(y, uu, stuck, dir);
                let add = |a: &[f64; 6], b: &[f64; 6], c: f64| {
                    let mut r = *a;
                    for i in 0..6 {
                        r[i] += c * b[i];
                    }
                    r
                };
                let k1 = f(&x);
                let k2 = f(&add(&x, &k1, h / 2.0));
                let k3 = f(&add(&x, &k2, h / 2.0));
                let k4 = f(&add(&x, &k3, h));
                for i in 0..6 {
                    x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
                }
                let w = if self.backlash.is_some() { 4 } else { 2 };
                if self.dry() && !stuck && x[w] * dir <= 0.0 {
                    x[w] = 0.0;
                    stuck = true;
                }
            }
            out.push(x);
        }
        out
    }
}

fn load_angle(r: &Reference, x: &[f64; 6]) -> f64 {
    if r.backlash.is_some() {
        x[5]
    } else {
        x[3] / r.p.n
    }
}

/// Input used by the accuracy tests: a slow sine with steps (reversals, stops and fast parts).
fn test_input(k: usize) -> f64 {
    let t = k as f64 * DT;
    3.0 * (2.0 * std::f64::consts::PI * 1.5 * t).sin() + if (k / 150) & 1 == 0 { 0.8 } else { -0.8 }
}

/// The largest load-angle error [rad] of servo's simulator of `specs` against the RK4 reference
/// over `steps` periods, and the load's range [rad]; `whole`: with whole periods stepped at once
/// between events ([`PlantSim::with_coarse_periods`], the diagnosis's simulations).
fn compare_with_reference(specs: &[&str], steps: usize, whole: bool) -> (f64, f64) {
    let p = plant(specs);
    let mut sim = PlantSim::new(&p, DT).unwrap();
    if whole {
        sim = sim.with_coarse_periods();
    }
    let got = run(&mut sim, test_input, steps);
    let reference = Reference::new(&p);
    let want = reference.run(test_input, steps, 1e-6);
    let mut max_err: f64 = 0.0;
    let mut range: f64 = 0.0;
    for (g, w) in got.iter().zip(&want) {
        let wl = load_angle(&reference, w);
        max_err = max_err.max((g.theta_l_rad - wl).abs());
        range = range.max(wl.abs());
    }
    println!(
        "{specs:?}{}: max |theta_l error| = {max_err:.3e} rad over a range of {range:.3} rad",
        if whole { " (whole periods)" } else { "" }
    );
    (max_err, range)
}

#[test]
fn linear_plant_equals_exact_zoh_solution() {
    let _machine = servo_e2e::shared();
    // Independent exact solution: nalgebra's matrix exponential of the augmented 5x5 system
    // [[A, B], [0, 0]] dt, states (u_drv, i_a, omega_m, theta_m).
    let p = plant(&[]);
    let k = &p.params;
    let j = k.j_eq();
    let a = nalgebra::SMatrix::<f64, 5, 5>::from_row_slice(&[
        -1.0 / k.t_drv(),
        0.0,
        0.0,
        0.0,
        k.k_drv / k.t_drv(),
        1.0 / k.l_a,
        -k.r_eq() / k.l_a,
        -k.k_e / k.l_a,
        0.0,
        0.0,
        0.0,
        k.k_t / j,
        -B_EQ / j,
        0.0,
        0.0,
        0.0,
        0.0,
        1.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
    ]);
    let e = (a * DT).exp();
    let mut sim = PlantSim::new(&p, DT).unwrap();
    let mut x = nalgebra::SVector::<f64, 5>::zeros();
    for step in 0..3000 {
        let u = test_input(step);
        x[4] = u;
        x = e * x;
        let s = sim.step(u);
        let tol = 1e-9 * (1.0 + x[3].abs());
        assert!(
            (s.theta_m_rad - x[3]).abs() < tol,
            "step {step}: {} vs {}",
            s.theta_m_rad,
            x[3]
        );
        assert!((s.omega_m_rad_s - x[2]).abs() < 1e-9 * (1.0 + x[2].abs()));
        assert!((s.i_a_a - x[1]).abs() < 1e-9);
        assert!((s.u_drv_v - x[0]).abs() < 1e-9);
        assert!((s.theta_l_rad - x[3] / k.n).abs() < tol);
    }
}

#[test]
fn nonlinear_mechanics_match_fine_reference_integration() {
    let _machine = servo_e2e::shared();
    for specs in [
        &["coulomb:tau_sf=0.006"][..],
        &["coulomb:tau_sf=0.004", "stribeck:tau_s=0.008,omega_s=0.5"][..],
        &["asymmetry:tau_sf_pos=0.003,tau_sf_neg=0.006"][..],
        &["cogging:amplitude=3e-4,harmonic=12,phase=0.4"][..],
        &["imbalance:amplitude=0.03,phase=0.5"][..],
        &["backlash:gap=0.05"][..],
        &["delay:delay=0.0027", "coulomb:tau_sf=0.003"][..],
        &[
            "coulomb:tau_sf=0.004",
            "stribeck:tau_s=0.007,omega_s=0.5",
            "cogging:amplitude=2e-4,harmonic=6",
            "imbalance:amplitude=0.02",
            "backlash:gap=0.04",
        ][..],
    ] {
        // The simulations of a diagnosis step whole periods between events: as accurate.
        for whole in [false, true] {
            let (err, range) = compare_with_reference(specs, 1500, whole);
            assert!(
                range > 1.0,
                "{specs:?}: the test input should move the load ({range} rad)"
            );
            assert!(
                err < 2e-3 * range.max(1.0),
                "{specs:?} (whole periods {whole}): error {err:.3e} rad"
            );
        }
    }
}

#[test]
fn below_breakaway_the_shaft_does_not_creep() {
    let _machine = servo_e2e::shared();
    for (specs, tau_break, tau_kin) in [
        (&["coulomb:tau_sf=0.006"][..], 0.006, 0.006),
        (
            &["coulomb:tau_sf=0.004", "stribeck:tau_s=0.009,omega_s=0.3"][..],
            0.009,
            0.004,
        ),
    ] {
        let p = plant(specs);
        // Just below breakaway: held for 3 s, not a single nanoradian of creep.
        let mut sim = PlantSim::new(&p, DT).unwrap();
        let u = u_for_load_torque(&p.params, 0.97 * tau_break);
        let states = run(&mut sim, |_| u, 3000);
        assert!(
            states
                .iter()
                .all(|s| s.theta_l_rad == 0.0 && s.omega_m_rad_s == 0.0 && s.stuck),
            "{specs:?} crept"
        );
        // The holding friction equals the driving torque.
        let t = sim.torques();
        assert!(
            (t.friction_l_nm - 0.97 * tau_break).abs() < 1e-6 * tau_break,
            "{t:?}"
        );
        // Just above breakaway: it moves.
        let mut sim = PlantSim::new(&p, DT).unwrap();
        let u = u_for_load_torque(&p.params, 1.03 * tau_break);
        let states = run(&mut sim, |_| u, 500);
        let end = states.last().unwrap();
        assert!(
            end.theta_l_rad > 1e-3 && !end.stuck,
            "{specs:?}: no breakaway at 1.03 tau_s"
        );
        // Stribeck: between tau_sf and tau_s a moving shaft keeps moving, a resting one stays.
        if tau_kin < tau_break {
            let mut sim = PlantSim::new(&p, DT).unwrap();
            let u_mid = u_for_load_torque(&p.params, 0.5 * (tau_kin + tau_break));
            let states = run(&mut sim, |k| if k < 100 { 2.0 * u } else { u_mid }, 2000);
            let end = states.last().unwrap();
            assert!(
                !end.stuck && end.omega_l_rad_s > 0.0,
                "a sliding shaft between tau_sf and tau_s kept sliding"
            );
            let mut sim = PlantSim::new(&p, DT).unwrap();
            let states = run(&mut sim, |_| u_mid, 2000);
            assert!(
                states.iter().all(|s| s.theta_l_rad == 0.0),
                "a resting shaft below tau_s stayed"
            );
        }
    }
}

#[test]
fn stick_slip_does_not_chatter() {
    let _machine = servo_e2e::shared();
    // A slow sine just above breakaway: the shaft alternates stuck and slipping phases, with one
    // breakaway per half period and no chattering at the stops.
    let p = plant(&["coulomb:tau_sf=0.004", "stribeck:tau_s=0.008,omega_s=0.3"]);
    let mut sim = PlantSim::new(&p, DT).unwrap();
    let amp = u_for_load_torque(&p.params, 0.012);
    let states = run(
        &mut sim,
        |k| amp * (2.0 * std::f64::consts::PI * k as f64 * DT).sin(),
        4000,
    );
    let breakaways = states
        .windows(2)
        .filter(|w| w[0].stuck && !w[1].stuck)
        .count();
    let stops = states
        .windows(2)
        .filter(|w| !w[0].stuck && w[1].stuck)
        .count();
    println!("4 periods: {breakaways} breakaways, {stops} stops");
    assert!(
        (7..=9).contains(&breakaways),
        "{breakaways} breakaways in 4 periods"
    );
    assert!((7..=9).contains(&stops), "{stops} stops in 4 periods");
    // While stuck, the angle is exactly constant.
    for w in states.windows(2) {
        if w[0].stuck && w[1].stuck {
            assert_eq!(w[0].theta_m_rad, w[1].theta_m_rad);
        }
    }
}

#[test]
fn asymmetry_moves_one_way_only() {
    let _machine = servo_e2e::shared();
    let p = plant(&["asymmetry:tau_sf_pos=0.003,tau_sf_neg=0.008"]);
    let u = u_for_load_torque(&p.params, 0.005);
    let mut sim = PlantSim::new(&p, DT).unwrap();
    let fwd = run(&mut sim, |_| u, 1000);
    assert!(fwd.last().unwrap().theta_l_rad > 0.05);
    let mut sim = PlantSim::new(&p, DT).unwrap();
    let back = run(&mut sim, |_| -u, 1000);
    assert!(back.iter().all(|s| s.theta_l_rad == 0.0));
}

#[test]
fn backlash_load_waits_for_the_gap_after_a_reversal() {
    let _machine = servo_e2e::shared();
    let gap = 0.08;
    let p = plant(&[&format!("backlash:gap={gap}"), "coulomb:tau_sf=0.003"]);
    let mut sim = PlantSim::new(&p, DT).unwrap();
    // Slow triangle-like drive so the load is nearly at rest at the reversal.
    let states = run(
        &mut sim,
        |k| 2.0 * (2.0 * std::f64::consts::PI * 0.5 * k as f64 * DT).sin(),
        3000,
    );
    // First reversal of the motor (forward -> backward).
    let rev = states
        .windows(2)
        .position(|w| w[0].omega_m_rad_s > 0.0 && w[1].omega_m_rad_s <= 0.0)
        .unwrap()
        + 1;
    let (tl0, tm0) = (states[rev].theta_l_rad, states[rev].theta_m_rad);
    // The load stays (within 5% of the gap) until the motor has travelled the gap backwards.
    let n = p.params.n;
    let mut moved_at = None;
    for s in &states[rev..] {
        if (s.theta_l_rad - tl0).abs() > 0.05 * gap {
            moved_at = Some((tm0 - s.theta_m_rad) / n);
            break;
        }
    }
    let travel = moved_at.expect("the load moved back eventually");
    println!(
        "motor travel (load side) before the load followed: {travel:.4} rad for a gap of {gap} rad"
    );
    assert!(travel > 0.8 * gap && travel < 1.3 * gap, "travel {travel}");
    // Without backlash the load follows at once.
    let p = plant(&["coulomb:tau_sf=0.003"]);
    let mut sim = PlantSim::new(&p, DT).unwrap();
    let states = run(
        &mut sim,
        |k| 2.0 * (2.0 * std::f64::consts::PI * 0.5 * k as f64 * DT).sin(),
        3000,
    );
    for s in &states {
        assert!((s.theta_l_rad - s.theta_m_rad / n).abs() < 1e-12);
    }
}

#[test]
fn saturation_limits_the_applied_input() {
    let _machine = servo_e2e::shared();
    let p = plant(&["saturation:limit=4"]);
    let mut sim = PlantSim::new(&p, DT).unwrap();
    let states = run(&mut sim, |k| 12.0 * (k as f64 * 0.01).sin(), 2000);
    assert!(states.iter().all(|s| s.u_in_v.abs() <= 4.0));
    assert!(states.iter().any(|s| s.u_in_v == 4.0) && states.iter().any(|s| s.u_in_v == -4.0));
    // Equal to the linear plant driven by the clipped input.
    let mut lin = PlantSim::new(&plant(&[]), DT).unwrap();
    let clipped = run(
        &mut lin,
        |k| (12.0 * (k as f64 * 0.01).sin()).clamp(-4.0, 4.0),
        2000,
    );
    for (a, b) in states.iter().zip(&clipped) {
        assert!((a.theta_l_rad - b.theta_l_rad).abs() < 1e-12 * (1.0 + b.theta_l_rad.abs()));
    }
}

#[test]
fn deadzone_ignores_small_inputs() {
    let _machine = servo_e2e::shared();
    let p = plant(&["deadzone:width=0.7"]);
    let mut sim = PlantSim::new(&p, DT).unwrap();
    let states = run(&mut sim, |k| 0.69 * (k as f64 * 0.01).sin(), 2000);
    assert!(states
        .iter()
        .all(|s| s.theta_l_rad == 0.0 && s.i_a_a == 0.0));
    // Above the band the plant sees u - width.
    let mut sim = PlantSim::new(&p, DT).unwrap();
    let got = run(&mut sim, |_| 2.0, 500);
    let mut lin = PlantSim::new(&plant(&[]), DT).unwrap();
    let want = run(&mut lin, |_| 1.3, 500);
    assert!((got[500].theta_l_rad - want[500].theta_l_rad).abs() < 1e-12);
}

#[test]
fn delay_shifts_the_response() {
    let _machine = servo_e2e::shared();
    // Whole and fractional delays against the undelayed plant simulated at a period that makes
    // the delay a whole number of samples (both linear, so both exact).
    let u = |k: usize| test_input(k);
    let mut plain = PlantSim::new(&plant(&[]), DT / 10.0).unwrap();
    let reference = run(&mut plain, |k| u(k / 10), 20_000);
    for delay in [0.003, 0.0025, 0.0007] {
        let mut sim = PlantSim::new(&plant(&[&format!("delay:delay={delay}")]), DT).unwrap();
        let got = run(&mut sim, u, 1500);
        let shift = (delay / (DT / 10.0)).round() as usize;
        let mut max_err: f64 = 0.0;
        for (k, s) in got.iter().enumerate().skip(5) {
            let r = &reference[k * 10 - shift];
            max_err = max_err.max((s.theta_l_rad - r.theta_l_rad).abs());
        }
        println!("delay {delay} s: max deviation from the shifted response {max_err:.2e} rad");
        assert!(max_err < 1e-9, "delay {delay}: {max_err}");
        // And the response really is shifted: it differs from the undelayed one.
        let mut undelayed = PlantSim::new(&plant(&[]), DT).unwrap();
        let und = run(&mut undelayed, u, 1500);
        let diff = got
            .iter()
            .zip(&und)
            .map(|(a, b)| (a.theta_l_rad - b.theta_l_rad).abs())
            .fold(0.0, f64::max);
        assert!(diff > 1e-3);
    }
}

/// Amplitude of the component of `y` at angle frequency `cycles` per radian of `angle`.
fn harmonic_amplitude(y: &[f64], angle: &[f64], cycles: f64) -> f64 {
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let (mut s, mut c) = (0.0, 0.0);
    for (v, a) in y.iter().zip(angle) {
        s += (v - mean) * (cycles * a).sin();
        c += (v - mean) * (cycles * a).cos();
    }
    2.0 * (s * s + c * c).sqrt() / y.len() as f64
}

#[test]
fn cogging_ripple_has_the_motor_side_period() {
    let _machine = servo_e2e::shared();
    let p = plant(&["cogging:amplitude=4e-4,harmonic=8"]);
    let mut sim = PlantSim::with_max_substep(&p, DT, 20e-6).unwrap();
    let states = run(&mut sim, |_| 0.6, 6000);
    let tail = &states[2000..];
    let w: Vec<f64> = tail.iter().map(|s| s.omega_m_rad_s).collect();
    let th: Vec<f64> = tail.iter().map(|s| s.theta_m_rad).collect();
    let at = harmonic_amplitude(&w, &th, 8.0);
    let off = harmonic_amplitude(&w, &th, 5.0).max(harmonic_amplitude(&w, &th, 11.0));
    println!("speed ripple at 8/rev {at:.3e} rad/s, off-harmonic {off:.3e}");
    assert!(at > 10.0 * off && at > 1e-3);
    // No ripple without cogging.
    let mut sim = PlantSim::new(&plant(&[]), DT).unwrap();
    let states = run(&mut sim, |_| 0.6, 6000);
    let w: Vec<f64> = states[2000..].iter().map(|s| s.omega_m_rad_s).collect();
    let th: Vec<f64> = states[2000..].iter().map(|s| s.theta_m_rad).collect();
    assert!(harmonic_amplitude(&w, &th, 8.0) < 0.05 * at);
}

#[test]
fn imbalance_ripple_has_the_load_period_and_holds_against_friction() {
    let _machine = servo_e2e::shared();
    let p = plant(&["imbalance:amplitude=0.02,phase=0"]);
    let mut sim = PlantSim::new(&p, DT).unwrap();
    let states = run(&mut sim, |_| 3.0, 6000);
    let tail = &states[2000..];
    let w: Vec<f64> = tail.iter().map(|s| s.omega_l_rad_s).collect();
    let th: Vec<f64> = tail.iter().map(|s| s.theta_l_rad).collect();
    let at = harmonic_amplitude(&w, &th, 1.0);
    let off = harmonic_amplitude(&w, &th, 2.0).max(harmonic_amplitude(&w, &th, 3.0));
    println!("load speed ripple at 1/rev {at:.3e} rad/s, at 2-3/rev {off:.3e}");
    assert!(at > 5.0 * off && at > 1e-2);
    // With no input the eccentric mass swings down to its stable rest theta_l = -phase (mod 2 pi).
    let mut p = plant(&["imbalance:amplitude=0.02,phase=0"]);
    p.effects
        .insert(Effect::parse("viscous:b_eq=2e-5").unwrap());
    let mut sim = PlantSim::new(&p, DT).unwrap();
    sim.reset(PlantState {
        theta_m_rad: 0.5 * p.params.n,
        ..PlantState::default()
    });
    let states = run(&mut sim, |_| 0.0, 20000);
    let end = states.last().unwrap().theta_l_rad;
    let rest =
        (end + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    assert!(rest.abs() < 1e-2, "{end}");
    assert!(servo_core::effects::imbalance::torque_l(0.02, 0.0, end).abs() < 1e-3);
}

#[test]
fn any_combination_is_finite_and_deterministic() {
    let _machine = servo_e2e::shared();
    let all = [
        "coulomb:tau_sf=0.005",
        "stribeck:tau_s=0.009,omega_s=0.2",
        "asymmetry:tau_sf_pos=0.004,tau_sf_neg=0.007",
        "backlash:gap=0.03,stiffness=1e7,damping=1",
        "cogging:amplitude=3e-4,harmonic=12,phase=0.3",
        "imbalance:amplitude=0.03,phase=1",
        "saturation:limit=6",
        "deadzone:width=0.4",
        "delay:delay=0.0033",
    ];
    for mask in (0u32..512).step_by(7) {
        let specs: Vec<&str> = all
            .iter()
            .enumerate()
            .filter(|(i, _)| mask & (1 << i) != 0)
            .map(|(_, s)| *s)
            .collect();
        let p = plant(&specs);
        let go = || {
            let mut sim = PlantSim::new(&p, DT).unwrap();
            run(
                &mut sim,
                |k| if (k / 97) & 1 == 0 { 10.0 } else { -10.0 } * ((k % 13) as f64 / 13.0),
                800,
            )
        };
        let a = go();
        assert!(
            a.iter().all(|s| s.theta_l_rad.is_finite()
                && s.i_a_a.is_finite()
                && s.omega_l_rad_s.abs() < 1e3),
            "{specs:?}"
        );
        assert_eq!(a, go(), "{specs:?} not deterministic");
    }
}

#[test]
fn sensors_quantise_add_seeded_noise() {
    let _machine = servo_e2e::shared();
    let cfg = SensorConfig {
        counts_per_rev: 4096,
        current_noise_a: 0.01,
        current_offset_a: 0.002,
        seed: 42,
    };
    let mut s = Sensors::new(cfg);
    let q = std::f64::consts::TAU / 4096.0;
    let mut values = Vec::new();
    for k in 0..20000 {
        let theta = -3.0 + k as f64 * 3.1e-4;
        let st = PlantState {
            theta_l_rad: theta,
            i_a_a: 0.5,
            ..PlantState::default()
        };
        let m = s.measure(&st);
        // On the grid, at most one count below the true angle.
        let c = m.theta_l_rad / q;
        assert!(
            (c - c.round()).abs() < 1e-9
                && m.theta_l_rad <= theta + 1e-12
                && theta - m.theta_l_rad < q
        );
        assert_eq!(m.encoder_count as f64, c.round());
        values.push(m.i_a_a - 0.5);
    }
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let std = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / values.len() as f64).sqrt();
    assert!((mean - 0.002).abs() < 3e-4, "offset {mean}");
    assert!((std - 0.01).abs() < 5e-4, "std {std}");
    // Same seed, same noise; another seed, other noise.
    let st = PlantState {
        i_a_a: 0.1,
        ..PlantState::default()
    };
    let a: Vec<f64> = {
        let mut s = Sensors::new(cfg);
        (0..10).map(|_| s.measure(&st).i_a_a).collect()
    };
    let b: Vec<f64> = {
        let mut s = Sensors::new(cfg);
        (0..10).map(|_| s.measure(&st).i_a_a).collect()
    };
    let c: Vec<f64> = {
        let mut s = Sensors::new(SensorConfig { seed: 43, ..cfg });
        (0..10).map(|_| s.measure(&st).i_a_a).collect()
    };
    assert_eq!(a, b);
    assert_ne!(a, c);
}

#[test]
fn cogging_and_imbalance_torques_have_their_stated_amplitude() {
    let _machine = servo_e2e::shared();
    // Quasi-static breakaway from rest: with the resisting cogging torque at its peak
    // (phase pi/2 at theta_m = 0), the motor torque at breakaway is tau_sf / N + amplitude; with
    // the imbalance at its peak it is (tau_sf + amplitude) / N.
    let tau_sf = 0.01;
    for (spec, extra_m) in [
        (
            "cogging:amplitude=3e-4,harmonic=12,phase=1.5707963267948966",
            3e-4,
        ),
        (
            "imbalance:amplitude=0.005,phase=1.5707963267948966",
            0.005 / 14.0,
        ),
    ] {
        let p = plant(&[&format!("coulomb:tau_sf={tau_sf}"), spec]);
        let mut sim = PlantSim::new(&p, DT).unwrap();
        let k = &p.params;
        let mut at_break = None;
        for step in 0..20000 {
            let u = 1e-4 * step as f64; // 0.1 V/s: quasi-static
            let i_before = sim.state().i_a_a;
            if !sim.step(u).stuck {
                at_break = Some(k.k_t * i_before);
                break;
            }
        }
        let tau_m = at_break.expect("broke away");
        let want = tau_sf / k.n + extra_m;
        println!("{spec}: breakaway motor torque {tau_m:.4e} N m, expected {want:.4e}");
        assert!(
            (tau_m / want - 1.0).abs() < 0.01,
            "{spec}: {tau_m} vs {want}"
        );
    }
}

/// Moved from the simulator's unit tests (they name catalogue effects, which live in the
/// registry only).
mod sim_effects {
    use servo_core::effects::Effect;
    use servo_core::sim::{PlantSim, SimError};
    use servo_core::Plant;

    fn plant_with(specs: &[&str]) -> Plant {
        let mut p = Plant::nominal();
        p.effects
            .insert(Effect::parse("viscous:b_eq=1e-6").unwrap());
        for s in specs {
            p.effects.insert(Effect::parse(s).unwrap());
        }
        p
    }

    #[test]
    fn every_effect_together_stays_finite_and_deterministic() {
        let _machine = servo_e2e::shared();
        let p = plant_with(&[
            "coulomb:tau_sf=0.005",
            "stribeck:tau_s=0.008,omega_s=0.3",
            "asymmetry:tau_sf_pos=0.004,tau_sf_neg=0.006",
            "backlash:gap=0.03,stiffness=1e6,damping=0.5",
            "cogging:amplitude=2e-4,harmonic=12,phase=0.3",
            "imbalance:amplitude=0.01,phase=1",
            "saturation:limit=8",
            "deadzone:width=0.3",
            "delay:delay=0.0025",
        ]);
        let run = || {
            let mut sim = PlantSim::new(&p, 1e-3).unwrap();
            let mut out = [0.0; 3000];
            for (k, o) in out.iter_mut().enumerate() {
                let u = 10.0 * (k as f64 * 0.01).sin() + if k % 7 == 0 { 3.0 } else { -1.0 };
                let s = sim.step(u);
                assert!(
                    s.theta_l_rad.is_finite() && s.i_a_a.is_finite() && s.omega_l_rad_s.is_finite()
                );
                assert!(s.theta_l_rad.abs() < 1e4);
                *o = s.theta_l_rad;
            }
            out
        };
        assert_eq!(run(), run());
    }

    #[test]
    fn extreme_contact_stiffness_stays_bounded() {
        let _machine = servo_e2e::shared();
        for spec in [
            "backlash:gap=0.02,stiffness=1e12,damping=0",
            "backlash:gap=0,stiffness=1e9,damping=10",
        ] {
            let p = plant_with(&[spec, "coulomb:tau_sf=0.003"]);
            let mut sim = PlantSim::new(&p, 1e-3).unwrap();
            for k in 0..3000 {
                let u = if (k / 200) & 1 == 0 { 10.0 } else { -10.0 };
                let s = sim.step(u);
                assert!(
                    s.theta_l_rad.is_finite() && s.omega_l_rad_s.abs() < 200.0,
                    "{spec}: {s:?}"
                );
                assert!(
                    (s.theta_m_rad / 14.0 - s.theta_l_rad).abs() < 0.011 + 1e-3,
                    "{spec}: {s:?}"
                );
            }
        }
    }

    #[test]
    fn rejects_unusable_effects() {
        let _machine = servo_e2e::shared();
        let p = plant_with(&["delay:delay=2"]);
        assert!(matches!(
            PlantSim::new(&p, 1e-3),
            Err(SimError::DelayTooLong { .. })
        ));
        let p = plant_with(&["backlash:gap=0.01,load_inertia_fraction=0"]);
        assert!(matches!(
            PlantSim::new(&p, 1e-3),
            Err(SimError::InertiaFraction(_))
        ));
        assert!(matches!(
            PlantSim::new(&Plant::nominal(), 0.0),
            Err(SimError::BadPeriod(_))
        ));
        let mut p = Plant::nominal();
        p.effects
            .insert(Effect::parse("cogging:amplitude=1e-3").unwrap());
        assert!(matches!(PlantSim::new(&p, 1e-3), Err(SimError::Effect(_))));
    }
}
