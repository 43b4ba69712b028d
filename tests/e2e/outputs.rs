//! End-to-end tests of servo's writers, through the commands a user runs: a model written over a
//! hand-made model keeps its tables and the file itself (said), a `--log` over a log keeps the
//! old log, a reader never sees a partial file while `servo design -o` rewrites it, a full disk
//! leaves the old file whole and the printed sample counts true.

use servo_cli::io::mcap_read::read_mcap;
use servo_cli::model_file::ModelFile;
use servo_core::effects::EffectKind;
use servo_e2e::servo;
use std::path::{Path, PathBuf};

/// The file names in `dir`, sorted.
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A hand-made model: Table 2, a comment, a backlash, limits and provenance of its own.
fn hand_made_model() -> String {
    let mut text = String::from("# my motor, measured by hand on 2026-11-30\n");
    text.push_str(&ModelFile::default().to_toml().unwrap());
    text.push_str(
        "\n[effects.backlash]\ngap = 0.04\nstiffness = 5.0\ndamping = 0.01\n\
         load_inertia_fraction = 0.5\n\n[limits]\ntau_sf = 0.02\n\"backlash.gap\" = 0.06\n\n\
         [provenance]\nwho = \"the lab\"\n",
    );
    text
}

#[test]
fn identify_over_a_hand_made_model_keeps_it_beside_and_keeps_its_tables() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let hand = hand_made_model();
    ModelFile::parse(&hand).expect("the hand-made model is valid");
    let out = d.join("hand.toml");
    std::fs::write(&out, &hand).unwrap();
    let fr = d.join("fr.toml");
    std::fs::write(
        &fr,
        "speeds_rad_s = [150.0, 300.0, 450.0]\nstep_duration_s = 1.0\nboth_directions = true\nrest_s = 0.3\n",
    )
    .unwrap();
    let ir = d.join("ir.toml");
    std::fs::write(
        &ir,
        "accel_rad_s2 = 660.0\npeak_speed_rad_s = 500.0\nbase_speed_rad_s = 30.0\ncycles = 3\n",
    )
    .unwrap();
    let logs = d.join("logs");
    let (ok, stdout, stderr) = servo(&[
        "identify",
        "--ramp",
        "--plant-preset",
        "lab",
        "--friction-recipe",
        s(&fr),
        "--inertia-recipe",
        s(&ir),
        "--log-dir",
        s(&logs),
        "-o",
        s(&out),
    ]);
    assert!(ok, "{stdout}\n{stderr}");
    // The hand-made file is kept whole beside the new one, and said in one line.
    let backup = d.join("hand.toml.1");
    assert_eq!(std::fs::read_to_string(&backup).unwrap(), hand);
    let said: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("kept the previous"))
        .collect();
    assert!(
        said.iter().any(|l| l.contains("hand.toml.1")),
        "no line names the backup: {stderr}"
    );
    // The new model holds the identified friction and the tables identify does not fit.
    assert!(
        stderr.contains("[effects.backlash]") && stderr.contains("[limits]"),
        "{stderr}"
    );
    let m = ModelFile::load(&out).unwrap();
    assert!(m.params.b_eq.is_some() && m.params.tau_sf.is_some());
    let bl = m.effects.get(EffectKind::Backlash).expect("backlash kept");
    assert_eq!(bl.get("gap"), Some(0.04));
    assert_eq!(m.limits.get("tau_sf"), Some(&0.02));
    assert_eq!(m.limits.get("backlash.gap"), Some(&0.06));
    let prev = m.provenance.as_ref().unwrap()["previous"]
        .as_table()
        .unwrap();
    assert_eq!(prev["who"].as_str(), Some("the lab"));
    // The identification's own provenance is the file's.
    assert!(m.provenance.as_ref().unwrap().len() > 1);
    // Written again: the first output is kept as .2, the hand-made file stays .1.
    let (ok, _, stderr) = servo(&[
        "identify",
        logs.join("identify_friction.mcap").to_str().unwrap(),
        logs.join("identify_inertia.mcap").to_str().unwrap(),
        "--plant-preset",
        "lab",
        "-o",
        s(&out),
    ]);
    assert!(ok, "{stderr}");
    assert_eq!(std::fs::read_to_string(&backup).unwrap(), hand);
    let names = names(d);
    assert!(
        !names.iter().any(|n| n.contains("servo-tmp")),
        "a temporary file was left: {names:?}"
    );
    if d.join("hand.toml.2").exists() {
        assert!(stderr.contains("hand.toml.2"), "{stderr}");
    }
}

fn write_gains(dir: &Path) -> PathBuf {
    let g = dir.join("gains.toml");
    std::fs::write(
        &g,
        "[pid]\nkp = 7.0476\nki = 86.121\nkd = 0.14418\ntl_s = 6.67e-3\nts_s = 1e-3\n",
    )
    .unwrap();
    g
}

/// The samples "log: PATH (N samples" says.
fn said_samples(out: &str) -> u64 {
    let line = out.lines().find(|l| l.starts_with("log: ")).unwrap();
    let n = line.split('(').nth(1).unwrap().split(' ').next().unwrap();
    n.parse().unwrap()
}

#[test]
fn a_log_over_a_log_keeps_the_old_one_and_a_faulted_run_finishes_its_own() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let g = write_gains(d);
    let log = d.join("r.mcap");
    let run = |duration: &str, extra: &[&str]| {
        let reference = if extra.is_empty() {
            "step:1"
        } else {
            "ramp:10"
        };
        let mut a = vec![
            "run",
            "--gains",
            s(&g),
            "--ref",
            reference,
            "--duration",
            duration,
            "--log",
            s(&log),
        ];
        a.extend_from_slice(extra);
        servo(&a)
    };
    let (ok, out, err) = run("2", &[]);
    assert!(ok, "{err}");
    assert_eq!(said_samples(&out), 2000);
    assert_eq!(read_mcap(&log).unwrap().loop_msgs.len(), 2000);
    assert!(!err.contains("kept the previous"), "{err}");
    // The same command again: the first log is kept as r.mcap.1, and said.
    let (ok, out, err) = run("1", &[]);
    assert!(ok, "{err}");
    assert_eq!(said_samples(&out), 1000);
    assert!(
        err.contains("kept the previous") && err.contains("r.mcap.1"),
        "{err}"
    );
    assert_eq!(
        read_mcap(&d.join("r.mcap.1")).unwrap().loop_msgs.len(),
        2000
    );
    let r = read_mcap(&log).unwrap();
    assert!(r.finished);
    assert_eq!(r.loop_msgs.len(), 1000);
    // A run that faults at its position limit: its log is finished under its name with the
    // samples before the fault (the count said is the file's), the earlier logs kept.
    let (ok, _, err) = run("5", &["--soft-limit-rev", "0.1"]);
    assert!(!ok && err.contains("soft position limit"), "{err}");
    let line = err
        .lines()
        .find(|l| l.contains("finished with the"))
        .unwrap_or_else(|| panic!("{err}"));
    let n: usize = line
        .split("finished with the ")
        .nth(1)
        .unwrap()
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    let r = read_mcap(&log).unwrap();
    assert!(r.finished);
    assert_eq!(r.loop_msgs.len(), n);
    assert!(n > 10 && n < 5000, "{n}");
    assert!(err.contains("r.mcap.2"), "{err}");
    assert_eq!(
        read_mcap(&d.join("r.mcap.2")).unwrap().loop_msgs.len(),
        1000
    );
    assert_eq!(names(d), ["gains.toml", "r.mcap", "r.mcap.1", "r.mcap.2"]);
}

/// A process reading the gains file while `servo design -o` rewrites it (two designs in turn)
/// reads one of the two whole files every time: never an empty or a partial one.
#[test]
fn a_reader_never_sees_a_partial_gains_file_while_design_rewrites_it() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path().to_path_buf();
    let gains = d.join("gains.toml");
    let design = |wc: &str| {
        let out = std::process::Command::new(servo_e2e::servo_bin())
            .args([
                "design",
                "--plant-preset",
                "table2",
                "--wc",
                wc,
                "--pm",
                "60",
            ])
            .arg("-o")
            .arg(&gains)
            .output()
            .unwrap();
        assert!(out.status.success(), "{out:?}");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    design("30");
    let a = std::fs::read_to_string(&gains).unwrap();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let reader = {
        let (stop, gains) = (stop.clone(), gains.clone());
        std::thread::spawn(move || {
            let (mut reads, mut bad) = (0u32, Vec::new());
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                let text = std::fs::read_to_string(&gains).unwrap_or_default();
                if servo_cli::gains_file::GainsFile::parse(&text).is_err() {
                    bad.push(text.len());
                }
                reads += 1;
            }
            (reads, bad)
        })
    };
    let rewrites = 24;
    let mut notes = 0;
    for k in 0..rewrites {
        let err = design(if k % 2 == 0 { "40" } else { "30" });
        notes += err
            .lines()
            .filter(|l| l.contains("kept the previous"))
            .count();
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let (reads, bad) = reader.join().unwrap();
    println!(
        "{reads} reads during {rewrites} rewrites; {} bad",
        bad.len()
    );
    assert!(reads > 100, "only {reads} reads");
    assert!(
        bad.is_empty(),
        "{} of {reads} reads were partial: {bad:?}",
        bad.len()
    );
    // Every rewrite changed the file: each kept the previous one under the next number.
    assert_eq!(notes, rewrites);
    let listed = names(&d);
    assert_eq!(listed.len(), 1 + rewrites, "{listed:?}");
    // The backups alternate between the two designs, oldest first; the file is the last one.
    let b = std::fs::read_to_string(d.join("gains.toml.2")).unwrap();
    assert_ne!(a, b);
    for k in 1..=rewrites {
        let kept = std::fs::read_to_string(d.join(format!("gains.toml.{k}"))).unwrap();
        assert_eq!(&kept, if k % 2 == 1 { &a } else { &b }, "gains.toml.{k}");
    }
    assert_eq!(std::fs::read_to_string(&gains).unwrap(), a);
}

/// A tmpfs of `size` mounted on a fresh folder, unmounted on drop; `None` (and a message) where
/// mounting is not allowed.
struct Tmpfs {
    dir: tempfile::TempDir,
}

impl Tmpfs {
    fn mount(size: &str) -> Option<Tmpfs> {
        let dir = tempfile::tempdir().unwrap();
        let r = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(dir.path())
            .output();
        match r {
            Ok(o) if o.status.success() => Some(Tmpfs { dir }),
            Ok(o) => {
                println!(
                    "SKIPPED: cannot mount a tmpfs here ({}): the full-disk test needs root",
                    String::from_utf8_lossy(&o.stderr).trim()
                );
                None
            }
            Err(e) => {
                println!("SKIPPED: cannot run mount ({e}): the full-disk test needs it");
                None
            }
        }
    }
    fn path(&self) -> &Path {
        self.dir.path()
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount")
            .arg(self.dir.path())
            .status();
    }
}

/// Fills the file system holding `path` with the file `path`, up to the last byte.
fn fill(path: &Path) {
    use std::io::Write;
    let mut f = std::fs::File::create(path).unwrap();
    let block = vec![0x5au8; 1 << 16];
    while f.write_all(&block).is_ok() {}
    let mut small = vec![0x5au8; 512];
    while !small.is_empty() {
        if f.write_all(&small).is_err() {
            small.truncate(small.len() / 2);
        }
    }
    let _ = f.sync_all();
}

#[test]
fn export_on_a_full_disk_leaves_the_old_file_whole_and_says_so() {
    let _machine = servo_e2e::shared();
    let Some(fs) = Tmpfs::mount("1m") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let g = write_gains(tmp.path());
    let log = tmp.path().join("long.mcap");
    let (ok, _, err) = servo(&[
        "run",
        "--gains",
        s(&g),
        "--ref",
        "sine:amp=1,freq=0.5",
        "--duration",
        "30",
        "--log",
        s(&log),
    ]);
    assert!(ok, "{err}");
    let old = fs.path().join("old.csv");
    let old_text = "time_s,u_V,theta_l_rad\n0,0,0\n0.001,0.5,0.001\n".repeat(50);
    std::fs::write(&old, &old_text).unwrap();
    let (ok, _, err) = servo(&["export", s(&log), "-o", s(&old)]);
    assert!(!ok, "30 s of CSV fit in 1 MB? {err}");
    assert!(err.contains("No space left"), "{err}");
    assert!(
        err.contains("unchanged") && err.contains("old.csv"),
        "the error does not say what was kept: {err}"
    );
    assert_eq!(std::fs::read_to_string(&old).unwrap(), old_text);
    assert_eq!(names(fs.path()), ["old.csv"]);
}

/// A run whose disk fills during the run: the previous log stays whole, the new one stays as
/// `r.mcap.partial`, and the sample count said is the one `servo log recover` finds in it.
#[test]
fn a_run_whose_disk_fills_says_the_samples_its_log_holds() {
    let _machine = servo_e2e::shared();
    // servo keeps 256 MiB free when a log starts: the disk fills during the run.
    let Some(fs) = Tmpfs::mount("260m") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let g = write_gains(tmp.path());
    let log = fs.path().join("r.mcap");
    let old_log = b"an earlier log, kept whole".to_vec();
    std::fs::write(&log, &old_log).unwrap();
    let child = std::process::Command::new(servo_e2e::servo_bin())
        .args(["run", "--realtime", "--gains", s(&g)])
        .args(["--ref", "sine:amp=1,freq=0.5", "--duration", "20"])
        .arg("--log")
        .arg(&log)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let filler = fs.path().join("filler");
    fill(&filler);
    let out = child.wait_with_output().unwrap();
    // Free the memory of the tmpfs before anything else.
    let _ = std::fs::remove_file(&filler);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        !out.status.success(),
        "the run did not see the full disk: {err}"
    );
    assert!(err.contains("No space left"), "{err}");
    assert_eq!(std::fs::read(&log).unwrap(), old_log, "{err}");
    let partial = fs.path().join("r.mcap.partial");
    let line = err
        .lines()
        .find(|l| l.contains("holds the first"))
        .unwrap_or_else(|| panic!("{err}"));
    assert!(
        line.contains("r.mcap.partial") && line.contains("unchanged"),
        "{line}"
    );
    let n: u64 = line
        .split("holds the first ")
        .nth(1)
        .unwrap()
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    let fixed = tmp.path().join("fixed.mcap");
    let (ok, rec_out, rec_err) = servo(&["log", "recover", s(&partial), "-o", s(&fixed)]);
    assert!(ok, "{rec_err}");
    let got = read_mcap(&fixed).unwrap().loop_msgs.len() as u64;
    println!("said {n}, recovered {got}: {line}\n{rec_out}");
    assert!(n > 500, "{line}");
    assert_eq!(
        got, n,
        "the count said is not the file's: {line}\n{rec_out}"
    );
}
