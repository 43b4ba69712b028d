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
    let _machine = servo_e2e::shared();
    let Some(dir) = servo_e2e::realdata_dir() else {
        return;
    };
    let mut files = Vec::new();
    csv_files(&dir, &mut files);
    // the Padova lab motors' logs (1 kHz); the smart servo's logs have their own tests
    files.retain(|f| {
        f.components()
            .any(|c| c.as_os_str().to_string_lossy().starts_with("padova"))
    });
    files.sort();
    assert!(
        files.len() >= 12,
        "expected the 12 lab CSVs, found {}",
        files.len()
    );
    for f in &files {
        let (rec, meta) =
            read_log_with_meta(f, None).unwrap_or_else(|e| panic!("{}: {e:#}", f.display()));
        assert!(rec.len() > 1000, "{}: {} rows", f.display(), rec.len());
        assert!(
            (rec.sample_period_s() - 1e-3).abs() < 1e-9,
            "{}: Ts = {}",
            f.display(),
            rec.sample_period_s()
        );
        assert!(
            rec.signals().len() >= 2,
            "{}: only {:?}",
            f.display(),
            rec.signals()
        );
        println!(
            "{}: {} rows, {:?}, {:?}",
            f.display(),
            rec.len(),
            rec.signals(),
            meta.notes
        );
    }
}

/// The raw values of one column of a comma-separated file.
fn raw_column(path: &Path, column: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let i = header.iter().position(|h| *h == column).unwrap();
    lines
        .map(|l| l.split(',').nth(i).unwrap().parse::<f64>().unwrap())
        .collect()
}

#[test]
fn realdata_units_are_converted() {
    let _machine = servo_e2e::shared();
    let Some(dir) = servo_e2e::realdata_dir() else {
        return;
    };
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
    assert!(
        (600.0..700.0).contains(&wm[k]),
        "motor speed {} rad/s",
        wm[k]
    );
    assert_eq!(rec.u_v.as_ref().unwrap()[1], 2.93215);
    assert!(rec.ref_rad.is_some() && rec.i_a_a.is_some());

    // An explicit map gives the same as the guess; units apply (mA here on purpose).
    let rec2 = read_log(
        &f,
        Some("time=t_s:s,theta_l=thl_meas_deg:deg,u=u_V:V,i_a=ia_A:mA"),
    )
    .unwrap();
    assert_eq!(rec2.theta_l_rad, rec.theta_l_rad);
    assert!(
        (rec2.i_a_a.as_ref().unwrap()[30000] - rec.i_a_a.as_ref().unwrap()[30000] * 1e-3).abs()
            < 1e-15
    );

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
    let rec = read_log(
        &dir.join("padova2022-mustacchi/csv/pid_aw_step360.csv"),
        None,
    )
    .unwrap();
    let r = rec.ref_rad.as_ref().unwrap();
    assert!(
        (r[r.len() - 1] - 2.0 * PI).abs() < 1e-9,
        "{}",
        r[r.len() - 1]
    );
}

#[test]
fn bad_csv_inputs_name_file_line_column() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &str, Option<&str>, &[&str]); 6] = [
        (
            "num.csv",
            "time_s,u_V,theta_l_rad\n0,1,0\n0.001,1,x\n",
            None,
            &["num.csv", "line 3", "column 3", "theta_l_rad", "`x`"],
        ),
        (
            "time.csv",
            "time_s,u_V\n0,1\n0.002,1\n0.001,1\n",
            None,
            &["time.csv", "line 4", "increase"],
        ),
        (
            "fields.csv",
            "time_s,u_V\n0,1\n0.001\n",
            None,
            &["fields.csv", "line 3", "expected 2 fields"],
        ),
        (
            "hdr.csv",
            "foo,bar\n0,1\n",
            None,
            &["hdr.csv", "`foo,bar`", "--columns time="],
        ),
        (
            "map.csv",
            "t,x\n0,1\n",
            Some("time=t,theta_l=y:deg"),
            &["map.csv", "no column `y`", "`t,x`"],
        ),
        (
            "unit.csv",
            "t,x\n0,1\n",
            Some("time=t,theta_l=x:rpm"),
            &["--columns", "rpm", "angle"],
        ),
    ];
    for (name, text, cols, needles) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        let e = format!("{:#}", read_log(&p, cols).unwrap_err());
        for n in needles {
            assert!(e.contains(n), "{name}: `{n}` not in: {e}");
        }
    }
    let e = format!(
        "{:#}",
        read_log(Path::new("/nonexistent/x.csv"), None).unwrap_err()
    );
    assert!(e.contains("/nonexistent/x.csv"), "{e}");
    let e = format!("{:#}", read_log(Path::new("x.dat"), None).unwrap_err());
    assert!(e.contains(".mcap") && e.contains(".csv"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// MCAP logs of real runs.

use servo_cli::io::mcap_read::read_mcap;
use servo_cli::io::{LoopMsg, McapLog, McapLogOptions};
use servo_core::control::{PidConfig, PidGains, Program, Reference};
use servo_hw::run::{self as runner, LogSink, RunConfig, SinkError};
use std::collections::BTreeMap;

/// Writes to an MCAP log and remembers what it wrote.
struct Tee {
    log: McapLog,
    written: Vec<LoopMsg>,
}

impl LogSink for Tee {
    fn write_loop(&mut self, msg: &LoopMsg) -> Result<(), SinkError> {
        self.written.push(*msg);
        Ok(self.log.write_loop(msg)?)
    }
    fn flush(&mut self) -> Result<(), SinkError> {
        Ok(self.log.flush()?)
    }
}

fn bits(m: &LoopMsg) -> Vec<u64> {
    [
        m.time_s,
        m.ref_rad,
        m.theta_l_rad,
        m.omega_l_rad_s,
        m.err_rad,
        m.u_v,
        m.ff_v,
        m.p_v,
        m.i_v,
        m.d_v,
        m.i_a_a,
    ]
    .iter()
    .map(|x| if x.is_nan() { u64::MAX } else { x.to_bits() })
    .chain([m.saturated as u64])
    .collect()
}

fn handout_pid() -> PidConfig {
    PidConfig::new(
        PidGains {
            kp: 7.0476,
            ki: 86.121,
            kd: 0.14418,
            tl_s: 1.0 / 150.0,
        },
        1e-3,
    )
}

#[test]
fn mcap_of_a_run_reopens_equal_to_what_was_written() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let mut plant = servo_core::Plant::from_params(servo_core::PlantParams::TABLE2).unwrap();
    plant
        .effects
        .insert(servo_core::Effect::parse("coulomb:tau_sf=0.01").unwrap());
    let mut backend = servo_hw::SimBackend::new(&plant, Default::default(), 1e-3).unwrap();
    let mut meta = BTreeMap::new();
    meta.insert(
        "gains_toml".to_string(),
        "[pid]\nkp = 7.0476\nki = 86.121\nkd = 0.14418\n".to_string(),
    );
    meta.insert("reference".to_string(), "step:1.5".to_string());
    let log = McapLog::create(&path, &meta, McapLogOptions::default()).unwrap();
    let mut tee = Tee {
        log,
        written: Vec::new(),
    };
    let program = Program::Position(Reference::parse("step:1.5").unwrap());
    let cfg = RunConfig::closed_loop(program, handout_pid(), 3.0);
    let out = runner::run_loop(&mut backend, &cfg, Some(&mut tee)).unwrap();
    tee.log.finish().unwrap();
    assert_eq!(tee.written.len(), 3000);
    let run = read_mcap(&path).unwrap();
    assert!(run.finished && run.notes.is_empty(), "{:?}", run.notes);
    assert_eq!(run.loop_msgs.len(), tee.written.len());
    for (a, b) in run.loop_msgs.iter().zip(&tee.written) {
        assert_eq!(bits(a), bits(b), "{a:?} != {b:?}");
    }
    assert_eq!(run.record.theta_l_rad, out.record.theta_l_rad);
    assert_eq!(run.record.u_v, out.record.u_v);
    assert_eq!(run.metadata["reference"], "step:1.5");
    // The metadata carries the controller for a closed-loop replay.
    let (_, meta) = read_log_with_meta(&path, None).unwrap();
    assert_eq!(meta.gains().unwrap().unwrap().pid.kp, 7.0476);
    // Also a valid MCAP for other readers: summary with statistics, a schema per channel.
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert_eq!(summary.stats.as_ref().unwrap().message_count, 3000);
    for ch in summary.channels.values() {
        let schema = ch.schema.as_ref().expect("every channel has a schema");
        assert_eq!(schema.encoding, "jsonschema");
        assert_eq!(ch.message_encoding, "json");
    }
}

fn write_gains(dir: &Path) -> std::path::PathBuf {
    let g = dir.join("gains.toml");
    std::fs::write(
        &g,
        "[pid]\nkp = 7.0476\nki = 86.121\nkd = 0.14418\ntl_s = 6.67e-3\nts_s = 1e-3\n",
    )
    .unwrap();
    g
}

#[test]
fn killed_run_is_readable_up_to_100ms_before_the_kill() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let gains = write_gains(dir.path());
    let log = dir.path().join("killed.mcap");
    let mut child = std::process::Command::new(servo_e2e::servo_bin())
        .args([
            "run",
            "--realtime",
            "--duration",
            "5",
            "--ref",
            "sine:amp=1,freq=0.5",
            "--gains",
        ])
        .arg(&gains)
        .arg("--log")
        .arg(&log)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1200));
    child.kill().unwrap(); // SIGKILL: no cleanup at all
    let killed_at = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as f64;
    child.wait().unwrap();
    // Unfinished, the log keeps the name that says so; every reader opens it.
    assert!(!log.exists());
    let log = dir.path().join("killed.mcap.partial");
    let run = read_mcap(&log).unwrap();
    assert!(!run.finished);
    assert!(!run.notes.is_empty());
    let start_ns: f64 = run.metadata["start_time_unix_ns"].parse().unwrap();
    let t_last = run.loop_msgs.last().unwrap().time_s;
    let lost_s = (killed_at - start_ns) * 1e-9 - t_last;
    println!(
        "killed at run time {:.4} s, readable up to {t_last:.4} s: lost {:.1} ms",
        (killed_at - start_ns) * 1e-9,
        lost_s * 1e3
    );
    assert!(t_last > 0.8, "only {t_last} s readable");
    assert!(
        lost_s <= 0.100,
        "lost {:.1} ms of run time (> 100 ms)",
        lost_s * 1e3
    );
    // What was read is contiguous from the start at 1 kHz.
    for (k, m) in run.loop_msgs.iter().enumerate() {
        assert!((m.time_s - k as f64 * 1e-3).abs() < 1e-9);
    }
    // And `servo export` recovers it.
    let csv = dir.path().join("killed.csv");
    let (ok, _, err) =
        servo_e2e::servo(&["export", log.to_str().unwrap(), "-o", csv.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(
        err.contains("not finished") || err.contains("truncated"),
        "{err}"
    );
    assert_eq!(read_log(&csv, None).unwrap().len(), run.loop_msgs.len());
}

#[test]
fn ctrl_c_stops_at_zero_volts_and_finishes_the_log() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let gains = write_gains(dir.path());
    let log = dir.path().join("int.mcap");
    let child = std::process::Command::new(servo_e2e::servo_bin())
        .args([
            "run",
            "--realtime",
            "--duration",
            "5",
            "--ref",
            "step:1",
            "--gains",
        ])
        .arg(&gains)
        .arg("--log")
        .arg(&log)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(700));
    let st = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(st.success());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "Ctrl-C exits 130: {stderr}");
    assert!(stderr.contains("interrupted by Ctrl-C"), "{stderr}");
    let run = read_mcap(&log).unwrap();
    assert!(run.finished, "the log must be finished: {:?}", run.notes);
    let t_last = run.loop_msgs.last().unwrap().time_s;
    assert!((0.3..2.0).contains(&t_last), "{t_last}");
    assert!(!run.summary.is_empty(), "summary record written");
    // The summary says what really ran, beside the planned duration.
    assert_eq!(run.summary["stop_reason"], "interrupted by Ctrl-C");
    assert_eq!(run.summary["planned_duration_s"], "5");
    let ran: f64 = run.summary["duration_s"].parse().unwrap();
    assert!((ran - (t_last + 1e-3)).abs() < 1e-6, "{ran} vs {t_last}");
}

#[test]
fn diverging_simulation_and_soft_limit_stop_with_an_error() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let gains = write_gains(dir.path());
    let g = gains.to_str().unwrap();
    let (ok, _, err) = servo_e2e::servo(&[
        "run",
        "--gains",
        g,
        "--ref",
        "step:1.5",
        "--duration",
        "2",
        "--plant-effect",
        "imbalance:amplitude=1e300",
    ]);
    assert!(
        !ok && err.contains("diverged") && !err.contains("inf"),
        "{err}"
    );
    let (ok, _, err) = servo_e2e::servo(&[
        "run",
        "--gains",
        g,
        "--ref",
        "ramp:10",
        "--duration",
        "5",
        "--soft-limit-rev",
        "2",
    ]);
    assert!(
        !ok && err.contains("soft position limit") && err.contains("2.000 rev"),
        "{err}"
    );
    assert!(err.contains("0 V (acknowledged)"), "{err}");
    // Absurd durations are refused before anything runs (no allocation sized by them).
    let (ok, _, err) =
        servo_e2e::servo(&["run", "--gains", g, "--ref", "step:1", "--duration", "1e12"]);
    assert!(!ok && err.contains("samples"), "{err}");
}

#[test]
fn run_summary_figures_are_sane() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let gains = write_gains(dir.path());
    let csv = dir.path().join("small.csv");
    // A small step on the linear plant without sensor noise: no saturation; the overshoot of
    // the 60 deg phase-margin design is about 20-30 % and it settles within 0.5 s.
    let (ok, out, err) = servo_e2e::servo(&[
        "run",
        "--gains",
        gains.to_str().unwrap(),
        "--ref",
        "step:0.2",
        "--duration",
        "2",
        "--counts-per-rev",
        "0",
        "--current-noise-a",
        "0",
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let num = |key: &str| -> f64 {
        let line = out
            .lines()
            .find(|l| l.contains(key))
            .unwrap_or_else(|| panic!("no `{key}` in {out}"));
        line.split_whitespace()
            .find_map(|w| w.parse::<f64>().ok())
            .unwrap()
    };
    let os = num("overshoot (max)");
    assert!((15.0..35.0).contains(&os), "overshoot {os} %");
    let ts = num("settling time (max)");
    assert!((0.05..0.5).contains(&ts), "settling {ts} s");
    assert_eq!(num("saturation time"), 0.0);
    assert!(
        out.contains("rad (") && out.contains(" s ("),
        "units printed: {out}"
    );
    // Cross-check the printed overshoot against the CSV.
    let rec = read_log(&csv, None).unwrap();
    let peak = rec
        .theta_l_rad
        .as_ref()
        .unwrap()
        .iter()
        .cloned()
        .fold(f64::MIN, f64::max);
    assert!(
        (100.0 * (peak - 0.2) / 0.2 - os).abs() < 0.01,
        "peak {peak}"
    );
    // A big step saturates.
    let (ok, out, err) = servo_e2e::servo(&[
        "run",
        "--gains",
        gains.to_str().unwrap(),
        "--ref",
        "step:3",
        "--duration",
        "2",
    ]);
    assert!(ok, "{err}");
    assert!(num_in(&out, "saturation time") > 0.01, "{out}");
    // Open loop: no tracking figures.
    let (ok, out, err) = servo_e2e::servo(&["run", "--voltage", "step:2", "--duration", "0.5"]);
    assert!(ok, "{err}");
    assert!(out.contains("n/a (open loop)"), "{out}");
}

fn num_in(out: &str, key: &str) -> f64 {
    let line = out.lines().find(|l| l.contains(key)).unwrap();
    line.split_whitespace()
        .find_map(|w| w.parse::<f64>().ok())
        .unwrap()
}

#[test]
fn run_rejects_bad_input_clearly() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let gains = write_gains(dir.path());
    let g = gains.to_str().unwrap();
    for (args, needle) in [
        (vec!["run", "--ref", "step:1"], "--gains"),
        (vec!["run", "--gains", g, "--ref", "stp:1"], "--ref `stp:1`"),
        (
            vec!["run", "--gains", g, "--ref", "step:1", "--duration", "0"],
            "--duration",
        ),
        (
            vec!["run", "--gains", g, "--ref", "step:1", "--log", "x.csv"],
            ".mcap",
        ),
        (
            vec!["run", "--gains", g, "--ref", "step:1", "--ff", "magic"],
            "--ff",
        ),
        (
            vec!["run", "--gains", "/nonexistent/g.toml", "--ref", "step:1"],
            "/nonexistent/g.toml",
        ),
        // A generator the 1 kHz loop would alias (a 1 GHz sine sampled every 1 ms reads as a
        // constant: it ran, silently, until stop 51).
        (
            vec!["run", "--voltage", "sine:amp=2,freq=1e9", "--duration", "1"],
            "--voltage `sine:amp=2,freq=1e9`: 1000000000 Hz is above the Nyquist frequency 500 Hz",
        ),
        (
            vec![
                "run",
                "--gains",
                g,
                "--ref",
                "chirp:amp=0.1,f0=1,f1=900,duration=2",
            ],
            "above the Nyquist frequency",
        ),
        (
            vec![
                "run",
                "--gains",
                g,
                "--ref",
                "step:1",
                "--csv",
                "/nonexistent/dir/x.csv",
            ],
            "does not exist",
        ),
    ] {
        let (ok, _, err) = servo_e2e::servo(&args);
        assert!(!ok, "{args:?} should fail");
        assert!(err.contains(needle), "{args:?}: `{needle}` not in {err}");
    }
    // Runs too long for what they ask to keep are refused before they start (no allocation,
    // no disk filled): 9e7 s of log is at least 4.5 TB; 10 h of samples in memory for a CSV.
    let log = dir.path().join("long.mcap");
    let csv = dir.path().join("long.csv");
    let common = ["run", "--gains", g, "--ref", "square:amp=1,period=2"];
    for (extra, needle) in [
        (
            ["--duration", "9e7", "--log", log.to_str().unwrap()],
            "free",
        ),
        (
            ["--duration", "36000", "--csv", csv.to_str().unwrap()],
            "log to MCAP instead",
        ),
    ] {
        let args: Vec<&str> = common.iter().chain(extra.iter()).copied().collect();
        let (ok, _, err) = servo_e2e::servo(&args);
        assert!(!ok, "{args:?} should be refused");
        assert!(err.contains(needle), "{args:?}: `{needle}` not in {err}");
    }
    assert!(!log.exists() && !csv.exists(), "a refused run left a file");
}

#[test]
fn demo_leaves_its_files_and_says_where() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("demo");
    let (ok, out, err) = servo_e2e::servo(&["demo", "--out", out_dir.to_str().unwrap()]);
    assert!(ok, "{err}");
    for f in [
        "gains.toml",
        "run.mcap",
        "run.csv",
        "run.svg",
        "truth_hidden.toml",
    ] {
        assert!(out_dir.join(f).is_file(), "{f} missing; output:\n{out}");
    }
    // The default text says where the files are (each one is listed under --verbose).
    assert!(
        out.contains(&format!("files in {}", out_dir.display())),
        "the folder not announced:\n{out}"
    );
    let rec = read_log(&out_dir.join("run.mcap"), None).unwrap();
    assert_eq!(rec.len(), 6000);
    assert!(out.contains("== [1/"), "{out}");
}
