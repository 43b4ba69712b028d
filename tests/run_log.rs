//! End-to-end tests of `servo run` and its logs: MCAP written and reopened equal, a killed run
//! readable up to its last flush, every real-lab CSV importable with the right units, bad CSVs
//! rejected with file/line/column, the run summary sane.

use servo_cli::io::{read_log, read_log_with_meta};
use std::f64::consts::PI;
use std::path::Path;

/// Every CSV under `dir`, recursively.
fn csv_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            csv_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "csv") {
            out.push(p);
        }
    }
}

#[test]
fn every_realdata_csv_imports() {
    let Some(dir) = servo_e2e::realdata_dir() else { return };
    let mut files = Vec::new();
    csv_files(&dir, &mut files);
    files.sort();
    assert!(files.len() >= 12, "expected the 12 lab CSVs, found {}", files.len());
    for f in &files {
        let (rec, meta) = read_log_with_meta(f, None).unwrap_or_else(|e| panic!("{}: {e:#}", f.display()));
        assert!(rec.len() > 1000, "{}: {} rows", f.display(), rec.len());
        assert!((rec.sample_period_s() - 1e-3).abs() < 1e-9, "{}: Ts = {}", f.display(), rec.sample_period_s());
        assert!(rec.signals().len() >= 2, "{}: only {:?}", f.display(), rec.signals());
        println!("{}: {} rows, {:?}, {:?}", f.display(), rec.len(), rec.signals(), meta.notes);
    }
}

/// The raw values of one column of a comma-separated file.
fn raw_column(path: &Path, column: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let i = header.iter().position(|h| *h == column).unwrap();
    lines.map(|l| l.split(',').nth(i).unwrap().parse::<f64>().unwrap()).collect()
}

#[test]
fn realdata_units_are_converted() {
    let Some(dir) = servo_e2e::realdata_dir() else { return };
    // jacopisky: thl in deg -> rad, wm in deg/s (motor side) -> rad/s, u in V, ia in A.
    let f = dir.join("padova2021-jacopisky/csv/friction_pos.csv");
    let rec = read_log(&f, None).unwrap();
    let deg = raw_column(&f, "thl_meas_deg");
    let th = rec.theta_l_rad.as_ref().unwrap();
    for k in (0..deg.len()).step_by(997) {
        assert!((th[k] - deg[k] * PI / 180.0).abs() < 1e-12 * (1.0 + deg[k].abs()));
    }
    // Encoder grid of 4096 counts/rev, now in rad (the CSV has 10 significant digits).
    let q = 2.0 * PI / 4096.0;
    assert!(th.iter().all(|x| ((x / q) - (x / q).round()).abs() < 1e-4));
    let wm = rec.omega_m_rad_s.as_ref().unwrap();
    let wm_deg = raw_column(&f, "wm_deg_per_s");
    let k = wm.len() - 2000; // last speed step: ~660 rad/s at the motor
    assert!((wm[k] - wm_deg[k] * PI / 180.0).abs() < 1e-9 * wm_deg[k].abs());
    assert!((600.0..700.0).contains(&wm[k]), "motor speed {} rad/s", wm[k]);
    assert_eq!(rec.u_v.as_ref().unwrap()[1], 2.93215);
    assert!(rec.ref_rad.is_some() && rec.i_a_a.is_some());

    // An explicit map gives the same as the guess; units apply (mA here on purpose).
    let rec2 = read_log(&f, Some("time=t_s:s,theta_l=thl_meas_deg:deg,u=u_V:V,i_a=ia_A:mA")).unwrap();
    assert_eq!(rec2.theta_l_rad, rec.theta_l_rad);
    assert!((rec2.i_a_a.as_ref().unwrap()[30000] - rec.i_a_a.as_ref().unwrap()[30000] * 1e-3).abs() < 1e-15);

    // mustacchi: wm in rpm -> rad/s; last step 6300 rpm = 659.7 rad/s.
    let rec = read_log(&dir.join("padova2022-mustacchi/csv/friction_pos.csv"), None).unwrap();
    let wm = rec.omega_m_rad_s.as_ref().unwrap();
    let mean: f64 = wm[42000..44000].iter().sum::<f64>() / 2000.0;
    assert!((mean - 6300.0 * 2.0 * PI / 60.0).abs() < 10.0, "{mean}");
    // savian: load speed in rad/s, last step 450 rpm at the load = 47.1 rad/s.
    let rec = read_log(&dir.join("padova2021-savian/csv/friction_pos.csv"), None).unwrap();
    let wl = rec.omega_l_rad_s.as_ref().unwrap();
    let mean: f64 = wl[42000..44000].iter().sum::<f64>() / 2000.0;
    assert!((mean - 450.0 * 2.0 * PI / 60.0).abs() < 2.0, "{mean}");
    // mustacchi step: 360 deg reference = 2 pi rad.
    let rec = read_log(&dir.join("padova2022-mustacchi/csv/pid_aw_step360.csv"), None).unwrap();
    let r = rec.ref_rad.as_ref().unwrap();
    assert!((r[r.len() - 1] - 2.0 * PI).abs() < 1e-9, "{}", r[r.len() - 1]);
}

#[test]
fn bad_csv_inputs_name_file_line_column() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &str, Option<&str>, &[&str]); 6] = [
        ("num.csv", "time_s,u_V,theta_l_rad\n0,1,0\n0.001,1,x\n", None, &["num.csv", "line 3", "column 3", "theta_l_rad", "`x`"]),
        ("time.csv", "time_s,u_V\n0,1\n0.002,1\n0.001,1\n", None, &["time.csv", "line 4", "increase"]),
        ("fields.csv", "time_s,u_V\n0,1\n0.001\n", None, &["fields.csv", "line 3", "expected 2 fields"]),
        ("hdr.csv", "foo,bar\n0,1\n", None, &["hdr.csv", "`foo,bar`", "--columns time="]),
        ("map.csv", "t,x\n0,1\n", Some("time=t,theta_l=y:deg"), &["map.csv", "no column `y`", "`t,x`"]),
        ("unit.csv", "t,x\n0,1\n", Some("time=t,theta_l=x:rpm"), &["--columns", "rpm", "angle"]),
    ];
    for (name, text, cols, needles) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        let e = format!("{:#}", read_log(&p, cols).unwrap_err());
        for n in needles {
            assert!(e.contains(n), "{name}: `{n}` not in: {e}");
        }
    }
    let e = format!("{:#}", read_log(Path::new("/nonexistent/x.csv"), None).unwrap_err());
    assert!(e.contains("/nonexistent/x.csv"), "{e}");
    let e = format!("{:#}", read_log(Path::new("x.dat"), None).unwrap_err());
    assert!(e.contains(".mcap or .csv"), "{e}");
}
