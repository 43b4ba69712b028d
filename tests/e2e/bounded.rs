//! Files that would cost memory sized by the file, and inputs cut short, through the commands a
//! user runs: a 64 MB header line, a 2 GB sparse file of NUL bytes (CSV, MCAP, MAT), `servo
//! inspect` on files it cannot read, `servo log recover` keeping the log's notes, a model file
//! that lost its friction lines. The peak memory of each `servo` process is measured by GNU
//! time (`/usr/bin/time`; skipped with a message where it is absent).

use servo_cli::io::{LoopMsg, McapLog, McapLogOptions};
use std::collections::BTreeMap;
use std::path::Path;
use std::time::{Duration, Instant};

/// What one `servo` process did: exit success, stdout, stderr, peak resident memory [bytes]
/// (`None` where it cannot be measured) and wall time.
struct Measured {
    ok: bool,
    out: String,
    err: String,
    peak_bytes: Option<u64>,
    wall: Duration,
}

/// GNU time, which measures the peak resident set of the process it starts (`%M`, its
/// `wait4` rusage). A process the test starts itself would not do: Linux carries the parent's
/// peak over `exec` into the child's `ru_maxrss` (the test process held the 64 MB files).
const GNU_TIME: &str = "/usr/bin/time";

/// Runs `servo args`, measuring its peak resident memory with [`GNU_TIME`] when present.
fn measured(args: &[&str]) -> Measured {
    let bin = servo_e2e::servo_bin();
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let rss = dir.path().join("maxrss_kb");
    let timed = Path::new(GNU_TIME).exists();
    let mut cmd = if timed {
        let mut c = std::process::Command::new(GNU_TIME);
        c.arg("-f").arg("%M").arg("-o").arg(&rss).arg(&bin);
        c
    } else {
        eprintln!("{GNU_TIME} is absent: peak memory not measured");
        std::process::Command::new(&bin)
    };
    let start = Instant::now();
    let out = cmd.args(args).output().expect("spawn servo");
    let wall = start.elapsed();
    let peak_bytes = timed.then(|| {
        let kb = std::fs::read_to_string(&rss).unwrap();
        // The last line (GNU time first says "Command exited with non-zero status 1").
        let kb: u64 = kb.lines().last().unwrap().trim().parse().unwrap();
        kb * 1024
    });
    Measured {
        ok: out.status.success(),
        out: String::from_utf8_lossy(&out.stdout).into_owned(),
        err: String::from_utf8_lossy(&out.stderr).into_owned(),
        peak_bytes,
        wall,
    }
}

/// Megabytes of a peak, for messages.
fn mb(peak: Option<u64>) -> String {
    peak.map_or("(not measured)".to_string(), |b| format!("{} MB", b / MB))
}

const MB: u64 = 1 << 20;

/// A CSV whose header is one 64 MB line (then a short data row), and one whose third line
/// holds a 64 MB cell: `servo inspect` and `servo identify` refuse them naming the file and the
/// line, with a message under 20 kB, in under 300 MB.
#[test]
fn a_64_mb_line_is_refused_in_bounded_memory_with_a_short_message() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let header = dir.path().join("header.csv");
    let mut text = vec![b'a'; 64 << 20];
    text.extend_from_slice(b"\n0\n");
    std::fs::write(&header, &text).unwrap();
    let cell = dir.path().join("cell.csv");
    let mut text = b"time_s,u_V,theta_l_rad\n0,1,0\n0.001,".to_vec();
    text.extend(std::iter::repeat_n(b'7', 64 << 20));
    text.extend_from_slice(b",0\n");
    std::fs::write(&cell, &text).unwrap();
    drop(text);
    for (file, line) in [(&header, 1), (&cell, 3)] {
        let f = file.to_str().unwrap();
        for cmd in [vec!["inspect", f], vec!["identify", f]] {
            let m = measured(&cmd);
            assert!(!m.ok, "servo {cmd:?} accepted it: {}", m.out);
            assert!(
                m.err.contains(f) && m.err.contains(&format!("line {line} is longer than")),
                "servo {cmd:?}: {}",
                &m.err[..m.err.len().min(2000)]
            );
            assert!(
                m.err.len() + m.out.len() < 20_000,
                "servo {cmd:?}: {} bytes of message",
                m.err.len() + m.out.len()
            );
            assert!(
                m.peak_bytes.is_none_or(|b| b < 300 * MB),
                "servo {cmd:?}: peak memory {}",
                mb(m.peak_bytes)
            );
            eprintln!(
                "servo {} on a 64 MB line {line}: refused in {:.2} s, peak {}, {} bytes of message",
                cmd[0],
                m.wall.as_secs_f64(),
                mb(m.peak_bytes),
                m.err.len()
            );
        }
    }
}

/// A 2 GB sparse file of NUL bytes named .csv, .mcap and .mat: refused by `servo inspect` and
/// `servo identify` in bounded memory (under 100 MB) and time (under 10 s).
#[test]
fn a_2_gb_file_of_nuls_is_refused_in_bounded_memory_and_time() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    for ext in ["csv", "mcap", "mat"] {
        let p = dir.path().join(format!("nul.{ext}"));
        let f = std::fs::File::create(&p).unwrap();
        f.set_len(2 << 30).unwrap();
        let s = p.to_str().unwrap();
        for cmd in [vec!["inspect", s], vec!["identify", s]] {
            let m = measured(&cmd);
            assert!(!m.ok, "servo {cmd:?} accepted it: {}", m.out);
            assert!(m.err.contains(s), "servo {cmd:?}: {}", m.err);
            assert!(m.err.len() < 20_000, "servo {cmd:?}: {} bytes", m.err.len());
            assert!(
                m.peak_bytes.is_none_or(|b| b < 100 * MB),
                "servo {cmd:?}: peak memory {}",
                mb(m.peak_bytes)
            );
            assert!(
                m.wall < Duration::from_secs(10),
                "servo {cmd:?}: {:?}",
                m.wall
            );
            eprintln!(
                "servo {} on 2 GB of NULs (.{ext}): refused in {:.2} s, peak {}: {}",
                cmd[0],
                m.wall.as_secs_f64(),
                mb(m.peak_bytes),
                m.err.trim()
            );
        }
    }
}

fn msg(k: usize) -> LoopMsg {
    let t = k as f64 * 1e-3;
    LoopMsg {
        time_s: t,
        ref_rad: 1.0,
        theta_l_rad: 1.0 - (-t * 20.0).exp(),
        omega_l_rad_s: 20.0 * (-t * 20.0).exp(),
        err_rad: (-t * 20.0).exp(),
        u_v: 5.0 * (-t * 20.0).exp(),
        ff_v: f64::NAN,
        p_v: 1.0,
        i_v: 0.0,
        d_v: 0.0,
        i_a_a: 0.1,
        saturated: false,
        ref_omega_l_rad_s: f64::NAN,
        i_ref_a: f64::NAN,
        duty: f64::NAN,
    }
}

/// A servo log of `n` samples at 1 kHz flushed every 20 ms, planned for 2 s; unfinished (the
/// writer dropped, as when the run is killed) unless `finish`.
fn write_log(p: &Path, n: usize, finish: bool) {
    let mut meta = BTreeMap::new();
    meta.insert("duration_s".to_string(), "2".to_string());
    meta.insert("backend".to_string(), "sim".to_string());
    let mut log = McapLog::create(
        p,
        &meta,
        McapLogOptions {
            flush_period_s: 0.02,
            start_unix_ns: 1_000,
            ..McapLogOptions::default()
        },
    )
    .unwrap();
    for k in 0..n {
        log.write_loop(&msg(k)).unwrap();
    }
    if finish {
        log.finish().unwrap();
    } else {
        // As a killed run leaves it: flushed, never finished (dropping it would finish it).
        log.flush().unwrap();
        std::mem::forget(log);
        // a killed run's log keeps its growing name, NAME.partial: give it the test's name
        std::fs::rename(format!("{}.partial", p.display()), p).unwrap();
    }
}

#[test]
fn inspect_exits_nonzero_on_a_file_it_cannot_read() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.mcap");
    write_log(&good, 200, true);
    let bytes = std::fs::read(&good).unwrap();
    let csv = dir.path().join("good.csv");
    std::fs::write(&csv, "time_s,u_V,theta_l_rad\n0,1,0\n0.001,1,0.1\n").unwrap();
    for f in [&good, &csv] {
        let (ok, out, err) = servo_e2e::servo(&["inspect", f.to_str().unwrap()]);
        assert!(ok, "{err}");
        assert!(out.starts_with(f.to_str().unwrap()), "{out}");
    }
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        (
            "cut.mcap",
            bytes[..20].to_vec(),
            "not readable as a servo log",
        ),
        ("text.mcap", b"hello".to_vec(), "not an MCAP file"),
        ("empty.csv", Vec::new(), "empty or has no header"),
        (
            "ragged.csv",
            b"time_s,u_V\n0,1\n0.001,1,7\n".to_vec(),
            "line 3: expected 2 fields",
        ),
        ("latin1.csv", b"t_s,\xe9\n0,1\n".to_vec(), "header"),
        ("short.mat", b"MATLAB 5.0".to_vec(), "not a MAT-file"),
    ];
    for (name, b, says) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, b).unwrap();
        let (ok, out, err) = servo_e2e::servo(&["inspect", p.to_str().unwrap()]);
        assert!(!ok, "{name}: exit 0 with {out}");
        assert!(err.contains(name) && err.contains(says), "{name}: {err}");
    }
    let (ok, _, err) =
        servo_e2e::servo(&["inspect", dir.path().join("absent.csv").to_str().unwrap()]);
    assert!(!ok && err.contains("absent.csv"), "{err}");
}

#[test]
fn log_recover_keeps_the_notes_of_the_log_it_recovers() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let broken = dir.path().join("broken.mcap");
    write_log(&broken, 250, false);
    let b = broken.to_str().unwrap();
    let (ok, out, err) = servo_e2e::servo(&["inspect", b]);
    assert!(ok, "{err}");
    let killed = out
        .lines()
        .find(|l| l.contains("run killed?"))
        .unwrap_or_else(|| panic!("{out}"))
        .trim()
        .trim_start_matches("note: ")
        .to_string();
    let fixed = dir.path().join("fixed.mcap");
    let f = fixed.to_str().unwrap();
    let (ok, out, err) = servo_e2e::servo(&["log", "recover", b, "-o", f]);
    assert!(ok, "{err}");
    assert!(out.contains(&killed), "{out}");
    // Read back: the log's note and its metadata, with where it was recovered from.
    let (ok, out, err) = servo_e2e::servo(&["inspect", f]);
    assert!(ok, "{err}");
    let note = out
        .lines()
        .find(|l| l.contains("recovered by `servo log recover`"))
        .unwrap_or_else(|| panic!("{out}"));
    assert!(
        note.contains(&format!("from {b}")) && note.contains(&killed),
        "{note}\nnot: {killed}"
    );
    let keys = out
        .lines()
        .find(|l| l.trim_start().starts_with("metadata: "))
        .unwrap_or_else(|| panic!("{out}"));
    assert!(
        keys.contains("backend") && keys.contains("duration_s"),
        "{keys}"
    );
    // Every command that reads the recovered log says it.
    let csv = dir.path().join("x.csv");
    let (ok, _, err) = servo_e2e::servo(&["export", f, "-o", csv.to_str().unwrap()]);
    assert!(
        ok && err.contains("recovered by `servo log recover`"),
        "{err}"
    );
    // A finished log recovered carries no such note.
    let good = dir.path().join("good.mcap");
    write_log(&good, 250, true);
    let again = dir.path().join("again.mcap");
    let (ok, _, err) = servo_e2e::servo(&[
        "log",
        "recover",
        good.to_str().unwrap(),
        "-o",
        again.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let (ok, out, err) = servo_e2e::servo(&["inspect", again.to_str().unwrap()]);
    assert!(ok && !out.contains("note:"), "{err}{out}");
}

/// A model file that lost its `b_eq` and `tau_sf` lines: every command that simulates or
/// compares with it says which friction it takes as zero, naming the flag and the file; the
/// whole file, or one that writes the zeros, says nothing.
#[test]
fn a_model_without_its_friction_lines_says_so() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let (ok, model, err) = servo_e2e::servo(&["params"]);
    assert!(ok, "{err}");
    assert!(
        model.contains("\nb_eq = ") && model.contains("\ntau_sf = "),
        "{model}"
    );
    let cut: String = model
        .lines()
        .filter(|l| !l.starts_with("b_eq") && !l.starts_with("tau_sf"))
        .map(|l| format!("{l}\n"))
        .collect();
    let zeros = cut.replacen("[params]\n", "[params]\nb_eq = 0\ntau_sf = 0\n", 1);
    std::fs::write(p("whole.toml"), &model).unwrap();
    std::fs::write(p("cut.toml"), &cut).unwrap();
    std::fs::write(p("zeros.toml"), &zeros).unwrap();
    let (ok, _, err) =
        servo_e2e::servo(&["design", "--wc", "30", "--pm", "60", "-o", &p("g.toml")]);
    assert!(ok, "{err}");
    let gains = p("g.toml");
    let run = |plant: &str, extra: &[&str]| {
        let mut a = vec![
            "run",
            "--plant",
            plant,
            "--gains",
            &gains,
            "--ref",
            "step:1",
            "--duration",
            "0.2",
        ];
        a.extend_from_slice(extra);
        let (ok, _, err) = servo_e2e::servo(&a);
        assert!(ok, "{err}");
        err
    };
    let err = run(&p("cut.toml"), &["--log", &p("r.mcap")]);
    let cut_p = p("cut.toml");
    for (key, what) in [("tau_sf", "Coulomb"), ("b_eq", "viscous")] {
        let w = err
            .lines()
            .find(|l| l.contains(&format!("no [params] {key}")))
            .unwrap_or_else(|| panic!("no warning on {key}: {err}"));
        assert!(
            w.starts_with(&format!("warning: --plant {cut_p}: "))
                && w.contains(&format!("no {what} friction"))
                && w.contains(&format!("`{key} = 0`")),
            "{w}"
        );
    }
    // Friction given on the command line is not said to be missing.
    let err = run(&p("cut.toml"), &["--plant-effect", "coulomb:tau_sf=0.01"]);
    assert!(
        !err.contains("no [params] tau_sf") && err.contains("no [params] b_eq"),
        "{err}"
    );
    for f in ["whole.toml", "zeros.toml"] {
        let err = run(&p(f), &[]);
        assert!(!err.contains("friction"), "{f}: {err}");
    }
    for cmd in ["compare", "diagnose"] {
        let (_, _, err) = servo_e2e::servo(&[cmd, &p("r.mcap"), "--model", &cut_p]);
        assert!(
            err.contains(&format!("warning: --model {cut_p}: no [params] tau_sf"))
                && err.contains(&format!("warning: --model {cut_p}: no [params] b_eq")),
            "{cmd}: {err}"
        );
    }
}
