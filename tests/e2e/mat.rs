//! MATLAB MAT-files as logs (issue 13, section 1): a synthetic Level-5 file written here (Scope
//! structures with their own time, a cell, an opaque object, compressed and not) read through
//! MATLAB paths and a guessed map; every real lab .mat file imports; identify on the .mat files
//! gives the CSV estimates and the published ones; compare replays the tester PID runs and
//! mustacchi's step without u from its gains and reference; a foreign MCAP with nullable fields
//! left out is read; the reader never panics on mutated real and synthetic files.

use servo_cli::io::mat_log;
use servo_cli::io::mat_read::{parse_mat, MatValue};
use servo_cli::io::read_log_with_meta;
use servo_core::sim::sensors::SplitMix64;
use std::path::{Path, PathBuf};

use servo_e2e::mat_writer::{doubles, element, mat_file, matrix, scope, text};

/// The synthetic lab file: a position/reference/u Scope at 1 ms, a labelled encoder Scope, a
/// current Scope at 2 ms on its own time (shifted by 0.5 ms), an opaque object, a cell, a scalar.
fn synthetic(compressed: bool) -> Vec<u8> {
    let t: Vec<f64> = (0..400).map(|k| k as f64 * 1e-3).collect();
    let th_deg: Vec<f64> = t.iter().map(|t| 90.0 * t).collect();
    let ref_deg = vec![30.0; t.len()];
    let u: Vec<f64> = t.iter().map(|t| 5.0 - t).collect();
    let ti: Vec<f64> = (0..200).map(|k| k as f64 * 2e-3 - 0.0005).collect();
    let ia: Vec<f64> = ti.iter().map(|t| 0.1 + 2.0 * t).collect();
    let opaque = matrix(
        17,
        &[],
        "obj",
        &[
            element(1, b"MCOS"),
            element(1, b"FileWrapper__"),
            doubles("", 1, 2, &[1.0, 2.0]),
        ],
    );
    let cell = matrix(
        1,
        &[1, 2],
        "c",
        &[doubles("", 1, 3, &[1.0, 2.0, 3.0]), text("", "x")],
    );
    mat_file(
        &[
            // As in the lab files: the two-column signal has no label.
            scope(
                "thl_u",
                &t,
                &[(vec![th_deg.clone(), ref_deg], ""), (vec![u], "u[V]")],
            ),
            scope("enc", &t, &[(vec![th_deg], "thl[deg]")]),
            scope("ia_scope", &ti, &[(vec![ia], "ia[A]")]),
            opaque,
            cell,
            doubles("gain", 1, 1, &[8.91]),
        ],
        compressed,
    )
}

/// The column map of the synthetic file.
const SYNTHETIC_MAP: &str = "time=thl_u.time,theta_l=thl_u.signals(1).values(:,1):deg,ref=thl_u.signals(1).values(:,end):deg,u=thl_u.signals(2).values,i_a=ia_scope.signals.values";

fn write_tmp(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn synthetic_mat_paths_resampling_and_guess() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    for compressed in [true, false] {
        let bytes = synthetic(compressed);
        let f = parse_mat(&bytes).unwrap();
        let names: Vec<&str> = f.variables.iter().map(|v| v.name.as_str()).collect();
        assert_eq!(names, ["thl_u", "enc", "ia_scope", "obj", "c", "gain"]);
        assert!(
            matches!(f.get("obj"), Some(MatValue::Skipped { class, .. }) if class.contains("FileWrapper__")),
            "{:?}",
            f.get("obj")
        );
        let path = write_tmp(tmp.path(), &format!("syn{compressed}.mat"), &bytes);
        let (rec, meta) = read_log_with_meta(&path, Some(SYNTHETIC_MAP)).unwrap();
        assert_eq!(rec.len(), 400);
        let th = rec.theta_l_rad.as_ref().unwrap();
        assert!((th[100] - (90.0 * 0.1f64).to_radians()).abs() < 1e-12);
        assert!((rec.ref_rad.as_ref().unwrap()[5] - 30f64.to_radians()).abs() < 1e-12);
        assert!((rec.u_v.as_ref().unwrap()[200] - 4.8).abs() < 1e-12);
        // The current's own time (2 ms, shifted) is resampled linearly onto thl_u.time: exact
        // for a linear signal, NaN before its first sample.
        let ia = rec.i_a_a.as_ref().unwrap();
        assert!(ia[0].is_finite() && (ia[0] - 0.1 - 2.0 * 0.0).abs() < 1e-12);
        assert!((ia[123] - (0.1 + 2.0 * 0.123)).abs() < 1e-12, "{}", ia[123]);
        assert!(
            ia[399].is_nan(),
            "after the last current sample: {}",
            ia[399]
        );
        assert!(
            meta.notes
                .iter()
                .any(|n| n.contains("own time `ia_scope.time`") && n.contains("resampled")),
            "{:?}",
            meta.notes
        );
        // Guessed from the labels with units; the unlabelled two-column signal is left out.
        let (g, meta) = read_log_with_meta(&path, None).unwrap();
        assert!(
            meta.notes.iter().any(|n| n.contains(
                "--columns time=thl_u.time,u=thl_u.signals(2).values,theta_l=enc.signals.values:deg,i_a=ia_scope.signals.values"
            )),
            "{:?}",
            meta.notes
        );
        assert_eq!(g.theta_l_rad, rec.theta_l_rad);
        assert_eq!(g.i_a_a.as_ref().unwrap()[123], ia[123]);
        // Errors name the path and what is there.
        for (bad, needle) in [
            ("time=thl_u.time,u=thl_u.signals.values", "1x2 struct array"),
            ("time=thl_u.time,u=thl_u.signals(3).values", "exceeds"),
            (
                "time=thl_u.time,u=thl_u.signals(1).values",
                "select one column",
            ),
            ("time=thl_u.time,u=nothere", "no variable `nothere`"),
            (
                "time=thl_u.time,u=thl_u.sig",
                "its fields are time, signals, blockName",
            ),
            ("time=thl_u.time,u=gain", "has 1 samples"),
        ] {
            let e = format!("{:#}", read_log_with_meta(&path, Some(bad)).unwrap_err());
            assert!(e.contains(needle), "{bad}: {e}");
        }
    }
}

#[test]
fn ambiguous_labels_are_not_guessed() {
    let _machine = servo_e2e::shared();
    let t: Vec<f64> = (0..50).map(|k| k as f64 * 1e-3).collect();
    let i = vec![0.1; 50];
    let bytes = mat_file(
        &[
            scope("a", &t, &[(vec![i.clone()], "ia[A]")]),
            scope("b", &t, &[(vec![i], "ia_filt[A]")]),
        ],
        true,
    );
    let tmp = tempfile::tempdir().unwrap();
    let p = write_tmp(tmp.path(), "two.mat", &bytes);
    let e = format!("{:#}", read_log_with_meta(&p, None).unwrap_err());
    assert!(
        e.contains(
            "`i_a` could be `a.signals.values` ('ia[A]') or `b.signals.values` ('ia_filt[A]')"
        ) && e.contains("--columns"),
        "{e}"
    );
}

#[test]
fn cli_inspect_lists_mat_csv_and_guess() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let p = write_tmp(tmp.path(), "lab.mat", &synthetic(true));
    let (ok, out, err) = servo_e2e::servo(&["inspect", p.to_str().unwrap()]);
    assert!(ok, "{err}");
    for needle in [
        "thl_u  1x1 struct",
        "Simulink Scope structure with time",
        "thl_u.signals(1).values  400x2 double",
        "label 'thl[deg]'",
        "obj  ? opaque object FileWrapper__",
        "c{2}  1x1 char 'x'",
        "guessed map: --columns time=thl_u.time",
    ] {
        assert!(out.contains(needle), "{needle}\n{out}");
    }
    let (ok, out, _) = servo_e2e::servo(&["export", p.to_str().unwrap()]);
    assert!(ok && out.contains("400 samples"), "{out}");
    // A CSV: its columns and the map servo would guess.
    let csv = write_tmp(
        tmp.path(),
        "lab.csv",
        b"t_s,thl_meas_deg,ia_A\n0,0,0\n0.001,1,0.1\n",
    );
    let (ok, out, _) = servo_e2e::servo(&["inspect", csv.to_str().unwrap()]);
    assert!(
        ok && out.contains("2 data rows")
            && out.contains("guessed map: --columns time=t_s,theta_l=thl_meas_deg:deg,i_a=ia_A"),
        "{out}"
    );
}

// ---------------------------------------------------------------- the real lab files

fn mat_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for g in std::fs::read_dir(dir).unwrap() {
        let m = g.unwrap().path().join("mat");
        if let Ok(rd) = std::fs::read_dir(&m) {
            out.extend(rd.map(|e| e.unwrap().path()));
        }
    }
    out.sort();
    out
}

/// Column maps of the lab logs among the .mat files (the others hold results and gains).
fn log_map(file: &str) -> Option<&'static str> {
    Some(match file {
        "least_square_positive.mat" | "least_square_negative.mat" => {
            "time=wm_best_meas.time,omega_m=wm_best_meas.signals.values:deg/s,i_a=ia_best.signals.values,u=thl_u_best.signals(2).values,theta_l=thl_u_best.signals(1).values(:,1):deg,ref=thl_u_best.signals(1).values(:,2):deg"
        }
        "accel_decel.mat" => {
            "time=al_best_meas1.time,omega_l=al_best_meas1.signals.values:deg/s,i_a=ia_best.signals.values,u=thl_u_best.signals(2).values"
        }
        "testerPIDBode.mat" => TESTER_BODE,
        "tester_PID_Best.mat" => TESTER_BEST,
        "DATA.mat" => "time=MotorData.time,omega_l=MotorData.signals(2).values,i_a=MotorData.signals(1).values",
        "LAB_FrictionEstPosRamp.mat" | "LAB_FrictionEstNegRamp.mat" => MUS_FRICTION,
        "LAB_InertiaEstLab.mat" => MUS_INERTIA,
        "PID_antiWindup_withStepAmplitude360.mat" => MUS_STEP,
        _ => return None,
    })
}

const TESTER_BODE: &str = "time=thl_u.time,theta_l=thl_u.signals(1).values(:,1):deg,ref=thl_u.signals(1).values(:,2):deg,u=thl_u.signals(2).values";
const TESTER_BEST: &str = "time=thl_u_best.time,theta_l=thl_u_best.signals(1).values(:,1):deg,ref=thl_u_best.signals(1).values(:,2):deg,u=thl_u_best.signals(2).values";
const MUS_FRICTION: &str = "time=ScopeData5.time,omega_m=ScopeData5.signals(1).values:rpm,i_a=ScopeData5.signals(2).values";
const MUS_INERTIA: &str = "time=ScopeData11.time,omega_m=ScopeData11.signals(1).values:rpm,i_a=ScopeData11.signals(3).values";
const MUS_STEP: &str = "time=ScopeData1.time,theta_l=ScopeData1.signals(1).values:deg,ref=ScopeData1.signals(2).values:deg,i_a=ScopeData2.signals.values";

#[test]
fn every_realdata_mat_imports() {
    let _machine = servo_e2e::shared();
    let Some(dir) = servo_e2e::realdata_dir() else {
        return;
    };
    let files = mat_files(&dir);
    assert!(
        files.len() >= 13,
        "expected the 13 lab .mat files, found {}",
        files.len()
    );
    let mut logs = 0;
    for f in &files {
        let mf = servo_cli::io::mat_read::read_mat_file(f)
            .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        assert!(!mf.variables.is_empty(), "{}", f.display());
        let name = f.file_name().unwrap().to_str().unwrap();
        if name == "DATA.mat" {
            // The workspace dump with MATLAB objects (tf, Axes): skipped, the rest read.
            let skipped = mf
                .variables
                .iter()
                .filter(|v| matches!(v.value, MatValue::Skipped { .. }))
                .count();
            assert!(skipped >= 5 && mf.get("wl1").is_some(), "{skipped}");
        }
        if let Some(map) = log_map(name) {
            let (rec, _) = read_log_with_meta(f, Some(map))
                .unwrap_or_else(|e| panic!("{}: {e:#}", f.display()));
            assert!(rec.len() > 4000 && rec.signals().len() >= 2, "{name}");
            assert!((rec.sample_period_s() - 1e-3).abs() < 1e-9, "{name}");
            logs += 1;
        }
        println!("{name}: {} variables", mf.variables.len());
    }
    assert_eq!(logs, 10);
}

/// Runs `servo identify --json` and returns (B_eq, tau_sf, J_eq).
fn identify(args: &[&str]) -> [f64; 3] {
    let (ok, out, err) = servo_e2e::servo(args);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    ["b_eq_n_m_s_rad", "tau_sf_n_m", "j_eq_kg_m2"].map(|k| v[k]["value"].as_f64().unwrap())
}

#[test]
fn identify_on_mat_matches_csv_and_published() {
    let _machine = servo_e2e::shared();
    let Some(root) = servo_e2e::realdata_dir() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let params = tmp.path().join("course.toml");
    servo_cli::model_file::ModelFile {
        params: servo_core::PlantParams {
            k_t: 7.68128e-3,
            k_e: 7.6776e-3,
            n: 14.0,
            ..servo_core::PlantParams::TABLE2
        },
        ..Default::default()
    }
    .save(&params)
    .unwrap();
    let params = params.to_str().unwrap();
    let jf = "time=wm_best_meas.time,omega_m=wm_best_meas.signals.values:deg/s,i_a=ia_best.signals.values,u=thl_u_best.signals(2).values";
    let ji = "time=al_best_meas1.time,omega_l=al_best_meas1.signals.values:deg/s,i_a=ia_best.signals.values,u=thl_u_best.signals(2).values";
    // (group, csv files and maps, mat files and maps, published B_eq, tau_sf, J_eq, extra args)
    type Case<'a> = (
        &'a str,
        [(&'a str, &'a str); 3],
        [(&'a str, &'a str); 3],
        [f64; 3],
        &'a [&'a str],
    );
    let cases: [Case; 3] = [
        (
            "padova2021-jacopisky",
            [
                ("friction_pos.csv", "time=t_s,omega_m=wm_deg_per_s:deg/s,i_a=ia_A,u=u_V"),
                ("friction_neg.csv", "time=t_s,omega_m=wm_deg_per_s:deg/s,i_a=ia_A,u=u_V"),
                ("accel_decel.csv", "time=t_s,omega_l=wl_deg_per_s:deg/s,i_a=ia_A,u=u_V"),
            ],
            [
                ("least_square_positive.mat", jf),
                ("least_square_negative.mat", jf),
                ("accel_decel.mat", ji),
            ],
            [7.040304e-7, 9.787708e-3, 7.411006e-7],
            &[],
        ),
        (
            "padova2022-mustacchi",
            [
                ("friction_pos.csv", "time=t_s,omega_m=wm_rpm:rpm,i_a=ia_A"),
                ("friction_neg.csv", "time=t_s,omega_m=wm_rpm:rpm,i_a=ia_A"),
                ("inertia.csv", "time=t_s,omega_m=wm_rpm:rpm,i_a=ia_A"),
            ],
            [
                ("LAB_FrictionEstPosRamp.mat", MUS_FRICTION),
                ("LAB_FrictionEstNegRamp.mat", MUS_FRICTION),
                ("LAB_InertiaEstLab.mat", MUS_INERTIA),
            ],
            [1.2744866709519896e-6, 0.01063783718605647, 5.556686421833261e-7],
            &[],
        ),
        (
            "padova2021-savian",
            [
                ("friction_pos.csv", "time=t_s,omega_l=wl_rad_per_s,i_a=ia_A"),
                ("friction_neg.csv", "time=t_s,omega_l=wl_rad_per_s,i_a=ia_A"),
                ("inertia.csv", "time=t_s,omega_l=wl_rad_per_s,i_a=ia_A"),
            ],
            [
                ("DATA.mat", "time=t1,omega_l=wl1,i_a=cur1"),
                ("DATA.mat", "time=t2,omega_l=wl2,i_a=cur2"),
                // The scope says w[rpm]; SOURCE.txt shows it is the load speed in rad/s.
                ("DATA.mat", "time=MotorData.time,omega_l=MotorData.signals(2).values,i_a=MotorData.signals(1).values"),
            ],
            [1.071e-6, 0.0071, 8.035e-7],
            // The group averaged each inertia phase over 0.7..0.9 of its length.
            &["--phase-window", "0.7,0.9"],
        ),
    ];
    for (group, csvs, mats, published, extra) in cases {
        let run = |sub: &str, files: &[(&str, &str); 3]| {
            let paths: Vec<String> = files
                .iter()
                .map(|(f, _)| root.join(group).join(sub).join(f).display().to_string())
                .collect();
            let mut args: Vec<&str> = vec!["identify"];
            args.extend(paths.iter().map(String::as_str));
            for (_, m) in files {
                args.extend(["--columns", m]);
            }
            args.extend(["--params", params, "--json"]);
            args.extend_from_slice(extra);
            identify(&args)
        };
        let (csv, mat) = (run("csv", &csvs), run("mat", &mats));
        for (k, name) in ["B_eq", "tau_sf", "J_eq"].iter().enumerate() {
            let vs_csv = (mat[k] / csv[k] - 1.0) * 100.0;
            let vs_pub = (mat[k] / published[k] - 1.0) * 100.0;
            println!(
                "{group} {name}: mat {:.5e}, csv {:.5e} ({vs_csv:+.4} %), published {:.5e} ({vs_pub:+.2} %)",
                mat[k], csv[k], published[k]
            );
            assert!(vs_csv.abs() < 0.5, "{group} {name}: mat vs csv {vs_csv} %");
            assert!(
                vs_pub.abs() < 3.0,
                "{group} {name}: mat vs published {vs_pub} %"
            );
        }
    }
}

fn compare_json(args: &[&str]) -> serde_json::Value {
    let (ok, out, err) = servo_e2e::servo(args);
    assert!(ok, "{args:?}: {err}");
    serde_json::from_str(&out).unwrap()
}

/// Model file of a motor: course constants and the group's published estimates.
fn model(dir: &Path, name: &str, b: f64, tau: f64, j: f64) -> String {
    let p = dir.join(name);
    servo_cli::model_file::ModelFile {
        params: servo_core::PlantParams {
            k_t: 7.68128e-3,
            k_e: 7.6776e-3,
            n: 14.0,
            b_eq: Some(b),
            tau_sf: Some(tau),
            j_eq: Some(j),
            ..servo_core::PlantParams::TABLE2
        },
        ..Default::default()
    }
    .save(&p)
    .unwrap();
    p.display().to_string()
}

#[test]
fn compare_runs_on_tester_pid_mat_files() {
    let _machine = servo_e2e::shared();
    let Some(root) = servo_e2e::realdata_dir() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let m = model(tmp.path(), "jac.toml", 7.17e-7, 9.71e-3, 7.35e-7);
    let dir = root.join("padova2021-jacopisky/mat");
    let csv = root.join("padova2021-jacopisky/csv/pid_bode_steps.csv");
    let csv_v = compare_json(&[
        "compare",
        csv.to_str().unwrap(),
        "--columns",
        "time=t_s,theta_l=thl_meas_deg:deg,ref=thl_ref_deg:deg,u=u_V",
        "--model",
        &m,
        "--gains-from-log",
        "--json",
    ]);
    for (file, map) in [
        ("testerPIDBode.mat", TESTER_BODE),
        ("tester_PID_Best.mat", TESTER_BEST),
    ] {
        let p = dir.join(file);
        let v = compare_json(&[
            "compare",
            p.to_str().unwrap(),
            "--columns",
            map,
            "--model",
            &m,
            "--gains-from-log",
            "--json",
        ]);
        let fit = v["fit_pct"].as_f64().unwrap();
        println!(
            "{file}: mode {}, fit {fit:.2} %, rmse {}",
            v["mode"], v["rmse"]
        );
        assert_eq!(v["mode"], "closed-loop", "{file}");
        assert!(fit > 80.0, "{file}: fit {fit}");
        if file == "testerPIDBode.mat" {
            // The same data as the CSV conversion: the same figures.
            let f_csv = csv_v["fit_pct"].as_f64().unwrap();
            assert!((fit - f_csv).abs() < 0.05, "mat {fit} vs csv {f_csv}");
        }
    }
}

#[test]
fn compare_replays_step_without_u_from_gains_and_reference() {
    let _machine = servo_e2e::shared();
    let Some(root) = servo_e2e::realdata_dir() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let m = model(
        tmp.path(),
        "mus.toml",
        1.2744866709519896e-6,
        0.01063783718605647,
        5.556686421833261e-7,
    );
    // The report's anti-windup PID (SOURCE.txt): Kp, Ki, Kd, TL, Kw; the lab DAC's +/-10 V.
    let gains = tmp.path().join("gains.toml");
    std::fs::write(
        &gains,
        "[pid]\nkp = 8.6774\nki = 119.6293\nkd = 0.1575\ntl_s = 0.0059\nts_s = 0.001\nkw = 33.33\nu_limit_v = 10.0\n",
    )
    .unwrap();
    let log = root.join("padova2022-mustacchi/mat/PID_antiWindup_withStepAmplitude360.mat");
    let log = log.to_str().unwrap();
    let base = ["compare", log, "--columns", MUS_STEP, "--model", &m];
    let mut args = base.to_vec();
    args.extend(["--gains", gains.to_str().unwrap(), "--json"]);
    let v = compare_json(&args);
    let fit = v["fit_pct"].as_f64().unwrap();
    println!(
        "pid_aw_step360 without u: mode {}, fit {fit:.2} %, rmse {} rad; notes {}",
        v["mode"], v["rmse"], v["logs"][0]["controller"]["notes"]
    );
    assert_eq!(v["mode"], "closed-loop");
    assert_eq!(v["signal"], "theta_l");
    assert!(fit > 95.0, "fit {fit}");
    assert!(
        v["logs"][0]["controller"]["notes"][0]
            .as_str()
            .unwrap()
            .contains("has no u"),
        "{}",
        v["logs"][0]
    );
    // Without the controller: a clear error, not "the log has no u".
    let (ok, _, err) = servo_e2e::servo(&base);
    assert!(!ok && err.contains("--gains"), "{err}");
}

#[test]
fn foreign_mcap_without_nullable_fields_is_read() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("foreign.mcap");
    let mut w = mcap::Writer::new(std::io::BufWriter::new(
        std::fs::File::create(&path).unwrap(),
    ))
    .unwrap();
    let ch = w
        .add_channel(0, "/servo/loop", "json", &Default::default())
        .unwrap();
    for k in 0..50u32 {
        let t = k as f64 * 1e-3;
        // Only time, angle and u: no omega_l_rad_s, i_a_a, ref_rad, err, PID terms, saturated.
        let msg = format!(r#"{{"time_s":{t},"theta_l_rad":{},"u_v":1.5}}"#, 2.0 * t);
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: ch,
                sequence: k,
                log_time: (t * 1e9) as u64,
                publish_time: (t * 1e9) as u64,
            },
            msg.as_bytes(),
        )
        .unwrap();
    }
    w.finish().unwrap();
    drop(w);
    let (rec, _) = read_log_with_meta(&path, None).unwrap();
    assert_eq!(rec.len(), 50);
    assert_eq!(rec.signals(), ["u", "theta_l"]);
    assert!((rec.theta_l_rad.as_ref().unwrap()[10] - 0.02).abs() < 1e-12);
}

// ---------------------------------------------------------------- fuzz

/// A file with every compressed element replaced by its inflated contents (a -v6 style file), so
/// mutations reach the structure walker instead of stopping at the zlib checksum.
fn inflated(bytes: &[u8]) -> Vec<u8> {
    use std::io::Read;
    let mut out = bytes[..128].to_vec();
    let mut pos = 128;
    while pos + 8 <= bytes.len() {
        let ty = u32::from_le_bytes(bytes[pos..pos + 4].try_into().unwrap());
        let n = u32::from_le_bytes(bytes[pos + 4..pos + 8].try_into().unwrap()) as usize;
        let data = &bytes[pos + 8..(pos + 8 + n).min(bytes.len())];
        if ty == 15 {
            let mut inner = Vec::new();
            flate2::read::ZlibDecoder::new(data)
                .read_to_end(&mut inner)
                .unwrap();
            while inner.len() % 8 != 0 {
                inner.push(0);
            }
            out.extend(inner);
            pos += 8 + n;
        } else {
            out.extend_from_slice(&bytes[pos..(pos + 8 + n.div_ceil(8) * 8).min(bytes.len())]);
            pos += 8 + n.div_ceil(8) * 8;
        }
    }
    out
}

/// One deterministic mutation: bit flips, bytes set to 0/0xff, a u32 overwritten with a large
/// or small count, a truncation, a chunk duplicated.
fn mutate(base: &[u8], rng: &mut SplitMix64, focus: usize) -> Vec<u8> {
    let mut b = base.to_vec();
    // Mostly near the structure (the first `focus` bytes), sometimes anywhere.
    let at = |rng: &mut SplitMix64, len: usize| {
        let span = if rng.next_u64() & 3 == 0 {
            len
        } else {
            focus.min(len)
        };
        (rng.next_u64() as usize) % span.max(1)
    };
    for _ in 0..1 + rng.next_u64() % 4 {
        let len = b.len();
        if len < 8 {
            break;
        }
        match rng.next_u64() % 6 {
            0 => {
                let i = at(rng, len);
                b[i] ^= 1 << (rng.next_u64() % 8);
            }
            1 => {
                let i = at(rng, len);
                b[i] = if rng.next_u64() & 1 == 0 { 0 } else { 0xff };
            }
            2 => {
                let i = at(rng, len - 4) & !3;
                let v: u32 = match rng.next_u64() % 4 {
                    0 => u32::MAX,
                    1 => 0x7fff_ffff,
                    2 => (rng.next_u64() % 64) as u32,
                    _ => rng.next_u64() as u32,
                };
                b[i..i + 4].copy_from_slice(&v.to_le_bytes());
            }
            3 => {
                let i = at(rng, len);
                b.truncate(i.max(1));
            }
            4 => {
                let i = at(rng, len);
                let j = (i + 1 + (rng.next_u64() as usize % 64)).min(len);
                let chunk = b[i..j].to_vec();
                b.splice(i..i, chunk);
            }
            _ => {
                let i = at(rng, len);
                b[i] = rng.next_u64() as u8;
            }
        }
    }
    b
}

/// Mutates `base` `iterations` times; whatever still parses is also listed (`servo inspect`),
/// guessed and imported with `map`: none of it may panic.
fn fuzz(name: &str, base: &[u8], map: Option<&str>, iterations: u64, seed: u64) -> (u64, u64) {
    let mut rng = SplitMix64(seed);
    let focus = base.len().min(4096);
    let mut ok = 0;
    for i in 0..iterations {
        let m = mutate(base, &mut rng, focus);
        let r = std::panic::catch_unwind(|| {
            parse_mat(&m).map(|f| {
                let _ = mat_log::describe(&f);
                let _ = mat_log::guess(&f);
                if let Some(map) = map {
                    let _ = mat_log::import(&f, name, Some(map));
                }
                f.variables.len()
            })
        });
        match r {
            Ok(Ok(_)) => ok += 1,
            Ok(Err(e)) => assert!(!e.to_string().is_empty()),
            Err(_) => panic!("{name}: the reader panicked on mutation {i} (seed {seed})"),
        }
    }
    (ok, iterations)
}

#[test]
fn mat_reader_survives_mutations() {
    let _machine = servo_e2e::shared();
    // Synthetic files, compressed and not, and hand-made hostile headers.
    for (k, compressed) in [true, false].into_iter().enumerate() {
        let (ok, n) = fuzz(
            "synthetic",
            &synthetic(compressed),
            Some(SYNTHETIC_MAP),
            6000,
            11 + k as u64,
        );
        println!("synthetic (compressed {compressed}): {ok}/{n} mutations still parse");
    }
    let mut bomb = synthetic(false)[..128].to_vec();
    // A compressed element that claims 4 GiB, and a matrix whose dimensions say 2^31 x 2^31.
    bomb.extend_from_slice(&15u32.to_le_bytes());
    bomb.extend_from_slice(&u32::MAX.to_le_bytes());
    assert!(parse_mat(&bomb).is_err());
    let mut dims = synthetic(false)[..128].to_vec();
    dims.extend(matrix(1, &[i32::MAX, i32::MAX], "c", &[]));
    assert!(parse_mat(&dims).is_err());
    let Some(dir) = servo_e2e::realdata_dir() else {
        return;
    };
    // Real files, each as saved and inflated (fewer mutations of the large ones, to keep the
    // run short; most land in the first 4 KiB, where the structure is).
    for (i, f) in mat_files(&dir).iter().enumerate() {
        let bytes = std::fs::read(f).unwrap();
        let name = f.file_name().unwrap().to_string_lossy().into_owned();
        let inf = inflated(&bytes);
        parse_mat(&inf).unwrap_or_else(|e| panic!("{name} inflated: {e}"));
        let iters = if bytes.len() > 200_000 { 100 } else { 1000 };
        let (a, n) = fuzz(&name, &bytes, log_map(&name), iters, 100 + i as u64);
        let (b, m) = fuzz(&name, &inf, log_map(&name), iters, 200 + i as u64);
        println!("{name}: {a}/{n} compressed and {b}/{m} inflated mutations still parse");
    }
}
