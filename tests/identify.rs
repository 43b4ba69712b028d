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
use servo_core::record::Record;
use servo_core::PlantParams;
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
