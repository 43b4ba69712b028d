//! `servo export MODEL.toml -o NAME.xml`: the MuJoCo model of what servo knows, checked in
//! MuJoCo itself.
//!
//! For a voltage drive, a current drive and an arm with gravity: `servo run` simulates a closed
//! position loop on the model and logs the drive's command; the exported MJCF, loaded in MuJoCo
//! (the `mujoco` Python package) and driven open loop by that logged command, must follow servo's
//! load angle within 5 % of the travel (RMSE). What MuJoCo cannot express is listed with its
//! error, on the output and in the file.
//!
//! The Python interpreter is `SERVO_MUJOCO_PYTHON` (CI's venv) or `python3`; without `mujoco`
//! importable the MuJoCo half of each case is skipped with a message.

use servo_e2e::servo;
use std::path::{Path, PathBuf};
use std::process::Command;

/// MuJoCo replays a servo log: argv = model.xml log.csv command_column. Prints
/// "rmse_rad travel_rad n_joints n_actuators".
const REPLAY: &str = r#"
import csv, sys
import mujoco
xml, log, col = sys.argv[1:4]
m = mujoco.MjModel.from_xml_path(xml)
d = mujoco.MjData(m)
with open(log, newline="") as f:
    rows = list(csv.DictReader(f))
t = [float(r["time_s"]) for r in rows]
u = [float(r[col]) for r in rows]
th = [float(r["theta_l_rad"]) for r in rows]
sub = max(1, round((t[1] - t[0]) / m.opt.timestep))
sq = 0.0
for k in range(len(t)):
    sq += (d.qpos[0] - th[k]) ** 2
    d.ctrl[0] = u[k]
    mujoco.mj_step(m, d, nstep=sub)
print((sq / len(t)) ** 0.5, max(th) - min(th), m.njnt, m.nu)
"#;

/// A Python with `mujoco`, or None (the reason printed). A Python named by `SERVO_MUJOCO_PYTHON` must have it (CI's venv: the test fails there).
fn mujoco_python() -> Option<String> {
    let given = std::env::var("SERVO_MUJOCO_PYTHON").ok();
    let py = given.clone().unwrap_or_else(|| "python3".to_string());
    match Command::new(&py).args(["-c", "import mujoco"]).output() {
        Ok(o) if o.status.success() => Some(py),
        other => {
            assert!(
                given.is_none(),
                "SERVO_MUJOCO_PYTHON={py} cannot import mujoco: {other:?}"
            );
            eprintln!(
                "SKIPPED the MuJoCo replay: `{py} -c 'import mujoco'` failed (pip install mujoco, \
                 or set SERVO_MUJOCO_PYTHON to a Python that has it)"
            );
            None
        }
    }
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Designs a PID for `model`, runs a square position loop on it, exports the log to CSV and the
/// model to MJCF; returns the export's stdout, the XML's path and the CSV's path.
fn run_and_export(dir: &Path, model: &Path) -> (String, PathBuf, PathBuf) {
    let gains = dir.join("gains.toml");
    let (ok, out, err) = servo(&[
        "design",
        "--params",
        s(model),
        "--wc",
        "30",
        "--pm",
        "60",
        "-o",
        s(&gains),
    ]);
    assert!(ok, "design: {err}\n{out}");
    let (mcap, csv, xml) = (
        dir.join("run.mcap"),
        dir.join("run.csv"),
        dir.join("rig.xml"),
    );
    let (ok, out, err) = servo(&[
        "run",
        "--gains",
        s(&gains),
        "--plant",
        s(model),
        "--log",
        s(&mcap),
        "--ref",
        "square:amp=1.5,period=1",
        "--duration",
        "4",
    ]);
    assert!(ok, "run: {err}\n{out}");
    let (ok, out, err) = servo(&["export", s(&mcap), "-o", s(&csv)]);
    assert!(ok, "export log: {err}\n{out}");
    let (ok, out, err) = servo(&["export", s(model), "-o", s(&xml)]);
    assert!(ok, "export model: {err}\n{out}");
    (out, xml, csv)
}

/// MuJoCo's RMSE and servo's travel [rad] of the replay, if MuJoCo is here.
fn replay(xml: &Path, csv: &Path, column: &str) -> Option<(f64, f64)> {
    let py = mujoco_python()?;
    let o = Command::new(py)
        .args(["-c", REPLAY, s(xml), s(csv), column])
        .output()
        .expect("spawn python");
    assert!(
        o.status.success(),
        "MuJoCo replay failed (the MJCF does not load?):\n{}\n{}",
        String::from_utf8_lossy(&o.stderr),
        std::fs::read_to_string(xml).unwrap_or_default()
    );
    let v: Vec<f64> = String::from_utf8_lossy(&o.stdout)
        .split_whitespace()
        .map(|x| x.parse().unwrap())
        .collect();
    assert_eq!((v[2], v[3]), (1.0, 1.0), "one joint, one actuator");
    Some((v[0], v[1]))
}

fn check_follows(name: &str, text: &str, column: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("model.toml");
    std::fs::write(&model, text).unwrap();
    let (out, xml, csv) = run_and_export(dir.path(), &model);
    let body = std::fs::read_to_string(&xml).unwrap();
    assert!(body.contains("<mujoco model=\"rig\">"), "{body}");
    if let Some((rmse, travel)) = replay(&xml, &csv, column) {
        eprintln!(
            "{name}: MuJoCo follows servo within {rmse:.4} rad RMSE over a {travel:.3} rad travel \
             ({:.2} %)",
            100.0 * rmse / travel
        );
        assert!(travel > 2.0, "{name}: the loop did not move ({travel} rad)");
        assert!(
            rmse < 0.05 * travel,
            "{name}: MuJoCo's trajectory is {rmse} rad RMSE from servo's over {travel} rad\n{body}"
        );
    }
    out
}

/// The lab SRV-02 (voltage drive, viscous and Coulomb friction).
const LAB: &str = "[params]
r_a = 2.6
l_a = 1.8e-4
k_e = 7.68e-3
k_t = 7.682e-3
j_m = 3.9e-7
b_m = 0
n = 14
j_72 = 1.4e-6
j_d = 3e-5
b_l = 0
k_drv = 0.6
f_c_drv = 1.2e3
r_s = 0.5
j_eq = 7e-7
b_eq = 1e-6
tau_sf = 9e-3
";

#[test]
fn a_voltage_drive_follows_servo_in_mujoco() {
    let _machine = servo_e2e::shared();
    let out = check_follows("voltage drive", LAB, "u_V");
    assert!(out.contains("MuJoCo expresses every effect"), "{out}");
}

#[test]
fn a_current_drive_follows_servo_in_mujoco() {
    let _machine = servo_e2e::shared();
    let text = "[params]
k_t = 0.05
j_m = 5e-6
n = 10
j_eq = 2e-5
b_eq = 2e-5
tau_sf = 0.05

[drive]
kind = \"current\"
bandwidth_hz = 300
i_limit_a = 3
";
    let out = check_follows("current drive", text, "i_ref_A");
    assert!(out.contains("ctrl is the command [A]"), "{out}");
}

#[test]
fn an_arm_with_gravity_follows_servo_in_mujoco() {
    let _machine = servo_e2e::shared();
    // Gravity 9 times the Coulomb friction, off the vertical by 0.3 rad at theta_l = 0.
    let text = format!("{LAB}\n[effects.imbalance]\namplitude = 0.08\nphase = 0.3\n");
    let out = check_follows("arm with gravity", &text, "u_V");
    assert!(
        out.contains("gravity: servo identifies m g L = 0.08 N m"),
        "{out}"
    );
}

#[test]
fn what_mujoco_cannot_express_is_listed_with_its_error() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("model.toml");
    let text =
        format!("{LAB}\n[effects.deadzone]\nwidth = 0.5\n\n[effects.delay]\ndelay = 0.004\n");
    std::fs::write(&model, text).unwrap();
    let xml = dir.path().join("dz.xml");
    let (ok, out, err) = servo(&["export", s(&model), "-o", s(&xml)]);
    assert!(ok, "{err}\n{out}");
    let body = std::fs::read_to_string(&xml).unwrap();
    for name in ["deadzone", "delay"] {
        let line = out
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{name}:")))
            .unwrap_or_else(|| panic!("{name} not listed:\n{out}"));
        // "  NAME: RMSE rad (P % of the travel): why"
        let rmse: f64 = line.split_whitespace().nth(1).unwrap().parse().unwrap();
        assert!(rmse > 0.0, "{line}");
        assert!(
            body.contains(line.trim()),
            "{line} not in the XML comment:\n{body}"
        );
    }
    assert!(out.contains("all of them:"), "{out}");
    // A log's options are refused for a model file, and a non-XML output too.
    let (ok, _, err) = servo(&["export", s(&model), "-o", s(&dir.path().join("m.csv"))]);
    assert!(!ok && err.contains(".xml"), "{err}");
}
