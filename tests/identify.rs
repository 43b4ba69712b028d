//! End-to-end tests of identification (handout section 4).
//!
//! * Simulated records with known truth: every parameter inside its reported 95 % interval.
//! * The real Padova lab data (../shared/realdata, or SERVO_REALDATA): the published estimates of
//!   each SOURCE.txt reproduced within 3 %, and the electrical check of padova2021-jacopisky.

use servo_core::ident::combined::{identify_combined, CombinedConfig};
use servo_core::ident::electrical::identify_electrical;
use servo_core::ident::friction::{identify_friction, FrictionConfig};
use servo_core::ident::inertia::identify_inertia;
use servo_core::ident::phases::PhaseConfig;
use servo_core::ident::Experiment;
use servo_cli::cmd::identify_ramp::{run_speed_loop, FrictionRecipe, InertiaRecipe};
use servo_core::record::Record;
use servo_core::sim::SensorConfig;
use servo_core::{Plant, PlantParams};
use servo_hw::sim::SimBackend;
use std::path::Path;

/// The constants the published Padova estimates used (course parameter file).
fn course_params() -> PlantParams {
    PlantParams { k_t: 7.68128e-3, k_e: 7.6776e-3, n: 14.0, ..PlantParams::TABLE2 }
}

/// Minimal numeric CSV reader for the test fixtures: `map` = [(record signal, column, scale)].
fn read_csv(path: &Path, map: &[(&str, &str, f64)]) -> Record {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let idx: Vec<usize> = map
        .iter()
        .map(|(_, c, _)| header.iter().position(|h| h == c).unwrap_or_else(|| panic!("no column {c}")))
        .collect();
    let mut cols: Vec<Vec<f64>> = vec![Vec::new(); map.len()];
    for l in lines {
        let f: Vec<&str> = l.split(',').collect();
        for (k, &i) in idx.iter().enumerate() {
            cols[k].push(f[i].trim().parse::<f64>().unwrap() * map[k].2);
        }
    }
    let mut r = Record { source: path.display().to_string(), ..Default::default() };
    for ((sig, _, _), c) in map.iter().zip(cols) {
        match *sig {
            "time" => r.time_s = c,
            "u" => r.u_v = Some(c),
            "i_a" => r.i_a_a = Some(c),
            "omega_m" => r.omega_m_rad_s = Some(c),
            "omega_l" => r.omega_l_rad_s = Some(c),
            "theta_l" => r.theta_l_rad = Some(c),
            other => panic!("signal {other}"),
        }
    }
    r
}

fn within(name: &str, got: f64, want: f64, rel: f64) {
    let e = (got - want) / want;
    eprintln!("{name}: {got:.5e} vs published {want:.5e} ({:+.2} %)", e * 100.0);
    assert!(e.abs() <= rel, "{name}: {got:e} vs {want:e} ({:+.2} %)", e * 100.0);
}

struct Group {
    dir: &'static str,
    friction: Vec<(&'static str, &'static str, f64)>,
    inertia: Vec<(&'static str, &'static str, f64)>,
    b_eq: f64,
    tau_sf: f64,
    j_eq: f64,
}

fn groups() -> Vec<Group> {
    let deg = std::f64::consts::PI / 180.0;
    let rpm = std::f64::consts::PI / 30.0;
    vec![
        Group {
            dir: "padova2021-jacopisky",
            friction: vec![("time", "t_s", 1.0), ("omega_m", "wm_deg_per_s", deg), ("i_a", "ia_A", 1.0), ("u", "u_V", 1.0)],
            inertia: vec![("time", "t_s", 1.0), ("omega_l", "wl_deg_per_s", deg), ("i_a", "ia_A", 1.0), ("u", "u_V", 1.0)],
            // Parameters_Estimation_Lab0.mlx: Beq = 7.040304e-07, tau_sf = 9.787708e-03 (filtered), Jeq = 7.411006e-07.
            b_eq: 7.040304e-7,
            tau_sf: 9.787708e-3,
            j_eq: 7.411006e-7,
        },
        Group {
            dir: "padova2022-mustacchi",
            friction: vec![("time", "t_s", 1.0), ("omega_m", "wm_rpm", rpm), ("i_a", "ia_A", 1.0)],
            inertia: vec![("time", "t_s", 1.0), ("omega_m", "wm_rpm", rpm), ("i_a", "ia_A", 1.0)],
            b_eq: 1.2744866709519896e-6,
            tau_sf: 0.01063783718605647,
            j_eq: 5.556686421833261e-7,
        },
        Group {
            dir: "padova2021-savian",
            friction: vec![("time", "t_s", 1.0), ("omega_l", "wl_rad_per_s", 1.0), ("i_a", "ia_A", 1.0)],
            inertia: vec![("time", "t_s", 1.0), ("omega_l", "wl_rad_per_s", 1.0), ("i_a", "ia_A", 1.0)],
            b_eq: 1.071e-6,
            tau_sf: 0.0071,
            j_eq: 8.035e-7,
        },
    ]
}

#[test]
fn real_data_library_reproduces_published_estimates() {
    let Some(root) = servo_e2e::realdata_dir() else { return };
    let p = course_params();
    for g in groups() {
        eprintln!("== {}", g.dir);
        let csv = root.join(g.dir).join("csv");
        let exps: Vec<Experiment> = ["friction_pos.csv", "friction_neg.csv"]
            .iter()
            .map(|f| Experiment::from_record(&read_csv(&csv.join(f), &g.friction), &p).unwrap())
            .collect();
        let inertia_file = if g.dir.contains("jacopisky") { "accel_decel.csv" } else { "inertia.csv" };
        let inertia = Experiment::from_record(&read_csv(&csv.join(inertia_file), &g.inertia), &p).unwrap();
        let f = identify_friction(&exps, p.n, &FrictionConfig::default()).unwrap();
        eprintln!("plateaus: {}", f.points.len());
        within("B_eq", f.b_eq.value, g.b_eq, 0.03);
        within("tau_sf", f.tau_sf.value, g.tau_sf, 0.03);
        let j = identify_inertia(std::slice::from_ref(&inertia), Some(&f), &PhaseConfig::default()).unwrap();
        eprintln!("inertia pairs: {} {:?}", j.pairs.len(), j.pairs.iter().map(|p| p.2).collect::<Vec<_>>());
        within("J_eq", j.j_eq.value, g.j_eq, 0.03);
        let mut all = exps.clone();
        all.push(inertia.clone());
        match identify_combined(&all, p.n, &CombinedConfig::default()) {
            Ok(c) => eprintln!(
                "combined: J {:.4e} +- {:.1e}, B {:.4e} +- {:.1e}, tau {:.4e} +- {:.1e}",
                c.j_eq.value, c.j_eq.std_err, c.b_eq.value, c.b_eq.std_err, c.tau_sf.value, c.tau_sf.std_err
            ),
            Err(e) => eprintln!("combined: {e}"),
        }
        if g.dir.contains("jacopisky") {
            let e = identify_electrical(&exps, &p, &FrictionConfig::default()).unwrap();
            within("k_drv", e.k_drv.value, 0.5989, 0.01);
            within("R_eq", e.r_eq.value, 3.057, 0.02);
            assert!(e.warnings.is_empty(), "{:?}", e.warnings);
        }
    }
}

/// Truth of the simulated tests: Padova-like friction and inertia.
fn truth() -> PlantParams {
    PlantParams { b_eq: Some(1.1e-6), tau_sf: Some(8.0e-3), j_eq: Some(7.0e-7), ..PlantParams::TABLE2 }
}

/// Closed-loop staircase (both directions) and ramps on the simulator with sensor noise.
fn simulate(seed: u64) -> (Record, Record) {
    let p = truth();
    let plant = Plant::from_params(p).unwrap();
    let sensors = SensorConfig { seed, current_noise_a: 3e-3, counts_per_rev: 4096, ..SensorConfig::default() };
    let fr = FrictionRecipe {
        speeds_rad_s: vec![80.0, 200.0, 320.0, 440.0, 560.0],
        step_duration_s: 2.0,
        both_directions: true,
        rest_s: 0.5,
    };
    let ir = InertiaRecipe { accel_rad_s2: 660.0, peak_speed_rad_s: 600.0, base_speed_rad_s: 30.0, cycles: 4, rest_s: 0.3 };
    let mut b = SimBackend::new(&plant, sensors, 1e-3).unwrap();
    let f = run_speed_loop(&mut b, &p, "sim friction", |t| fr.reference(t).map(|w| (w, 0.0))).unwrap();
    let mut b = SimBackend::new(&plant, SensorConfig { seed: seed + 1000, ..sensors }, 1e-3).unwrap();
    let i = run_speed_loop(&mut b, &p, "sim inertia", |t| ir.reference(t)).unwrap();
    (f, i)
}

#[test]
fn simulated_truth_is_inside_the_reported_intervals() {
    let p = truth();
    for seed in 1..=4 {
        let (f, i) = simulate(seed);
        let ef = Experiment::from_record(&f, &p).unwrap();
        let ei = Experiment::from_record(&i, &p).unwrap();
        let fr = identify_friction(std::slice::from_ref(&ef), p.n, &FrictionConfig::default()).unwrap();
        let ji = identify_inertia(std::slice::from_ref(&ei), Some(&fr), &PhaseConfig::default()).unwrap();
        eprintln!(
            "seed {seed}: B_eq {:.4e} [{:.4e}, {:.4e}]  tau_sf {:.4e} [{:.4e}, {:.4e}]  J_eq {:.4e} [{:.4e}, {:.4e}]",
            fr.b_eq.value, fr.b_eq.ci95.0, fr.b_eq.ci95.1, fr.tau_sf.value, fr.tau_sf.ci95.0, fr.tau_sf.ci95.1,
            ji.j_eq.value, ji.j_eq.ci95.0, ji.j_eq.ci95.1
        );
        assert!(fr.b_eq.contains(1.1e-6), "seed {seed}: B_eq {:?}", fr.b_eq);
        assert!(fr.tau_sf.contains(8.0e-3), "seed {seed}: tau_sf {:?}", fr.tau_sf);
        assert!(ji.j_eq.contains(7.0e-7), "seed {seed}: J_eq {:?}", ji.j_eq);
        // The intervals are informative, not just wide.
        assert!(fr.b_eq.rel_err() < 0.05 && fr.tau_sf.rel_err() < 0.05 && ji.j_eq.rel_err() < 0.05);
        let c = identify_combined(&[ef, ei], p.n, &CombinedConfig::default()).unwrap();
        eprintln!(
            "  combined: J {:.4e} [{:.4e}, {:.4e}] B {:.4e} [{:.4e}, {:.4e}] tau {:.4e} [{:.4e}, {:.4e}]",
            c.j_eq.value, c.j_eq.ci95.0, c.j_eq.ci95.1, c.b_eq.value, c.b_eq.ci95.0, c.b_eq.ci95.1,
            c.tau_sf.value, c.tau_sf.ci95.0, c.tau_sf.ci95.1
        );
        assert!(c.j_eq.contains(7.0e-7), "seed {seed}: combined J_eq {:?}", c.j_eq);
        assert!(c.b_eq.contains(1.1e-6), "seed {seed}: combined B_eq {:?}", c.b_eq);
        assert!(c.tau_sf.contains(8.0e-3), "seed {seed}: combined tau_sf {:?}", c.tau_sf);
    }
}

#[test]
fn combined_works_on_an_open_loop_voltage_sweep() {
    let p = truth();
    let plant = Plant::from_params(p).unwrap();
    for seed in [3, 9] {
        let mut sim = servo_core::sim::PlantSim::new(&plant, 1e-3).unwrap();
        let mut sensors = servo_core::sim::Sensors::new(SensorConfig { seed, ..SensorConfig::default() });
        let mut rec = Record { source: "open-loop sweep".into(), ..Record::default() };
        let (mut u_log, mut th, mut ia) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..20_000 {
            let t = k as f64 * 1e-3;
            // Square-ish multi-level voltage sweep with reversals.
            let u = 8.0 * (std::f64::consts::TAU * 0.25 * t).sin().signum() * (0.4 + 0.6 * ((t * 0.7).sin()).abs());
            let m = sensors.measure(sim.state());
            rec.time_s.push(t);
            th.push(m.theta_l_rad);
            ia.push(m.i_a_a);
            u_log.push(u);
            sim.step(u);
        }
        rec.theta_l_rad = Some(th);
        rec.i_a_a = Some(ia);
        rec.u_v = Some(u_log);
        let e = Experiment::from_record(&rec, &p).unwrap();
        let c = identify_combined(&[e], p.n, &CombinedConfig::default()).unwrap();
        eprintln!(
            "sweep seed {seed}: J {:.4e} [{:.4e}, {:.4e}] B {:.4e} [{:.4e}, {:.4e}] tau {:.4e} [{:.4e}, {:.4e}]",
            c.j_eq.value, c.j_eq.ci95.0, c.j_eq.ci95.1, c.b_eq.value, c.b_eq.ci95.0, c.b_eq.ci95.1,
            c.tau_sf.value, c.tau_sf.ci95.0, c.tau_sf.ci95.1
        );
        assert!(c.j_eq.contains(7.0e-7), "{:?}", c.j_eq);
        assert!(c.b_eq.contains(1.1e-6), "{:?}", c.b_eq);
        assert!(c.tau_sf.contains(8.0e-3), "{:?}", c.tau_sf);
    }
}

#[test]
fn unidentifiable_data_is_refused_with_an_explanation() {
    let p = truth();
    // One speed level only (both directions): B_eq and tau_sf cannot be separated.
    let n = 6000;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
    let w: Vec<f64> = t.iter().map(|t| if *t < 3.0 { 300.0 } else { -300.0 }).collect();
    let i: Vec<f64> = w.iter().map(|w| (1.1e-6 * w + 8e-3 / 14.0 * w.signum()) / p.k_t).collect();
    let rec = Record { source: "one-level".into(), time_s: t.clone(), omega_m_rad_s: Some(w.clone()), i_a_a: Some(i), ..Record::default() };
    let e = Experiment::from_record(&rec, &p).unwrap();
    let err = identify_friction(std::slice::from_ref(&e), p.n, &FrictionConfig::default()).unwrap_err().to_string();
    assert!(err.contains("same speed magnitude") && err.contains("other speed levels"), "{err}");
    // No acceleration phase: J_eq cannot be seen.
    let err = identify_inertia(std::slice::from_ref(&e), None, &PhaseConfig::default()).unwrap_err().to_string();
    assert!(err.contains("no constant acceleration"), "{err}");
    // No current: no torque.
    let rec = Record { source: "no-current".into(), time_s: t, omega_m_rad_s: Some(w), ..Record::default() };
    let e = Experiment::from_record(&rec, &p).unwrap();
    let err = identify_friction(std::slice::from_ref(&e), p.n, &FrictionConfig::default()).unwrap_err().to_string();
    assert!(err.contains("armature current"), "{err}");
}

#[test]
#[ignore]
fn probe_sim_inertia() {
    let p = truth();
    let plant = Plant::from_params(p).unwrap();
    let mut sim = servo_core::sim::PlantSim::new(&plant, 1e-3).unwrap();
    let mut w = vec![];
    let mut ia = vec![];
    for k in 0..3000 {
        let u = if k < 1500 { 3.0 } else { 8.0 };
        sim.step(u);
        w.push(sim.state().omega_m_rad_s);
        ia.push(sim.state().i_a_a);
    }
    // J from the torque balance at a few instants: (k_t i - B w - tau/N) / a
    for k in [1505, 1510, 1520, 1540] {
        let a = (w[k + 1] - w[k - 1]) / 2e-3;
        let tq = p.k_t * ia[k] - 1.1e-6 * w[k] - 8e-3 / 14.0;
        eprintln!("k {k}: a {a:.1} J {:.5e}", tq / a);
    }
}

#[test]
#[ignore]
fn probe_sweep_variants() {
    let p = truth();
    let plant = Plant::from_params(p).unwrap();
    for variant in 0..3 {
        let mut sim = servo_core::sim::PlantSim::new(&plant, 1e-3).unwrap();
        let mut sensors = servo_core::sim::Sensors::new(SensorConfig { seed: 3, ..SensorConfig::default() });
        let mut rec = Record { source: "probe".into(), ..Record::default() };
        let (mut th, mut ia, mut w) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..20_000 {
            let t = k as f64 * 1e-3;
            let u = 8.0 * (std::f64::consts::TAU * 0.25 * t).sin().signum() * (0.4 + 0.6 * ((t * 0.7).sin()).abs());
            let m = sensors.measure(sim.state());
            rec.time_s.push(t);
            th.push(if variant == 2 { m.theta_l_rad } else { sim.state().theta_l_rad });
            w.push(sim.state().omega_m_rad_s);
            ia.push(sim.state().i_a_a);
            sim.step(u);
        }
        if variant == 0 {
            rec.omega_m_rad_s = Some(w);
        } else {
            rec.theta_l_rad = Some(th);
        }
        rec.i_a_a = Some(ia);
        let e = Experiment::from_record(&rec, &p).unwrap();
        for fc in [5.0, 10.0, 20.0] {
            let c = identify_combined(std::slice::from_ref(&e), p.n, &CombinedConfig { cutoff_hz: fc, ..CombinedConfig::default() }).unwrap();
            eprintln!("variant {variant} fc {fc}: J {:.5e} B {:.5e} tau {:.5e}", c.j_eq.value, c.b_eq.value, c.tau_sf.value);
        }
    }
}

#[test]
#[ignore]
fn probe_synthetic() {
    let p = truth();
    let (j, b, tsf, n, kt) = (7e-7, 1.1e-6, 8e-3, 14.0, p.k_t);
    let mut t = vec![];
    let mut w = vec![];
    let mut ia = vec![];
    for k in 0..20000 {
        let tk = k as f64 * 1e-3;
        let q = tk % 2.0;
        let (wk, ak) = if q < 1.0 { (50.0 + 600.0 * q, 600.0) } else { (650.0 - 600.0 * (q - 1.0), -600.0) };
        t.push(tk);
        w.push(wk);
        ia.push((j * ak + b * wk + tsf / n * f64::signum(wk)) / kt);
    }
    let rec = Record { source: "syn".into(), time_s: t, omega_m_rad_s: Some(w), i_a_a: Some(ia), ..Record::default() };
    let e = Experiment::from_record(&rec, &p).unwrap();
    let ji = identify_inertia(std::slice::from_ref(&e), None, &PhaseConfig::default()).unwrap();
    eprintln!("phases J {:.5e} pairs {}", ji.j_eq.value, ji.pairs.len());
}

#[test]
#[ignore]
fn probe_sweep_instant() {
    let p = truth();
    let plant = Plant::from_params(p).unwrap();
    let mut sim = servo_core::sim::PlantSim::new(&plant, 1e-3).unwrap();
    let (mut w, mut ia) = (vec![], vec![]);
    for k in 0..8000 {
        let t = k as f64 * 1e-3;
        let u = 8.0 * (std::f64::consts::TAU * 0.25 * t).sin().signum() * (0.4 + 0.6 * ((t * 0.7).sin()).abs());
        w.push(sim.state().omega_m_rad_s);
        ia.push(sim.state().i_a_a);
        sim.step(u);
    }
    for k in (100..8000).step_by(250) {
        let a = (w[k + 1] - w[k - 1]) / 2e-3;
        let tq = p.k_t * ia[k] - 1.1e-6 * w[k] - 8e-3 / 14.0 * w[k].signum();
        eprintln!("k {k}: w {:.1} a {a:.1} resid/a {:.5e}", w[k], tq / a);
    }
}
