//! No quiet failures, through the command a user runs: logs that are not what their headers say
//! are refused with the unit to write, a supply voltage is never the command u, another motor's
//! `--ramp --plant` identifies with that motor's constants, a parameter added from zero prints
//! no long number, a parameter pinned at its bound is "not determined".
//!
//! The logs are made with `servo run` on the simulator, then their columns rewritten here.

use servo_e2e::servo;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

/// A 4 s open-loop sine of the lab plant as servo's CSV (time_s,u_V,theta_l_rad,i_a_A,
/// omega_l_rad_s), with `extra` options for `servo run`.
fn sine_csv(dir: &Path, name: &str, extra: &[&str]) -> PathBuf {
    run_csv(dir, name, "sine:amp=3,freq=1.5", "4", extra)
}

/// An open-loop run of `voltage` for `duration` seconds as servo's CSV.
fn run_csv(dir: &Path, name: &str, voltage: &str, duration: &str, extra: &[&str]) -> PathBuf {
    let path = dir.join(name);
    let p = path.to_str().unwrap();
    let mut args = vec![
        "run",
        "--voltage",
        voltage,
        "--duration",
        duration,
        "--csv",
        p,
        "--progress",
        "never",
    ];
    args.extend_from_slice(extra);
    let (ok, _, err) = servo(&args);
    assert!(ok, "servo run: {err}");
    path
}

/// The CSV at `src` rewritten: header `rename(old) -> new`, values of column `col` times
/// `scale`; `drop` columns left out.
fn rewrite(
    src: &Path,
    dst: &Path,
    rename: &[(&str, &str)],
    scale: Option<(&str, f64)>,
    drop: &[&str],
) {
    let text = std::fs::read_to_string(src).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let keep: Vec<usize> = (0..header.len())
        .filter(|i| !drop.contains(&header[*i]))
        .collect();
    let scaled = scale.map(|(c, f)| (header.iter().position(|h| *h == c).unwrap(), f));
    let mut out = String::new();
    let names: Vec<String> = keep
        .iter()
        .map(|&i| {
            rename
                .iter()
                .find(|(o, _)| *o == header[i])
                .map_or(header[i].to_string(), |(_, n)| n.to_string())
        })
        .collect();
    out.push_str(&names.join(","));
    out.push('\n');
    for l in lines {
        let cells: Vec<&str> = l.split(',').collect();
        let row: Vec<String> = keep
            .iter()
            .map(|&i| match scaled {
                Some((c, f)) if c == i => format!("{}", cells[i].parse::<f64>().unwrap() * f),
                _ => cells[i].to_string(),
            })
            .collect();
        out.push_str(&row.join(","));
        out.push('\n');
    }
    std::fs::write(dst, out).unwrap();
}

fn lab_model(dir: &Path) -> PathBuf {
    let (ok, text, err) = servo(&["params"]);
    assert!(ok, "{err}");
    let p = dir.join("lab.toml");
    std::fs::write(&p, text).unwrap();
    p
}

/// Degrees, rotations and rpm under rad headers: every command that reads the log (compare,
/// identify) refuses it, naming the unit and the `--columns` to write; with that map the same
/// log is read.
#[test]
fn wrong_units_under_rad_headers_are_named_with_the_fix() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let run = sine_csv(tmp.path(), "run.csv", &[]);
    let model = lab_model(tmp.path());
    for (name, col, factor, words, fix) in [
        (
            "deg.csv",
            "theta_l_rad",
            180.0 / PI,
            "degrees",
            "theta_l=theta_l_rad:deg",
        ),
        (
            "rev.csv",
            "theta_l_rad",
            1.0 / (2.0 * PI),
            "revolutions",
            "theta_l=theta_l_rad:rev",
        ),
        (
            "rpm.csv",
            "omega_l_rad_s",
            60.0 / (2.0 * PI),
            "rpm",
            "omega_l=omega_l_rad_s:rpm",
        ),
    ] {
        let log = tmp.path().join(name);
        rewrite(&run, &log, &[], Some((col, factor)), &[]);
        let l = log.to_str().unwrap();
        for args in [
            vec!["compare", "--model", model.to_str().unwrap(), l],
            vec!["identify", l],
        ] {
            let (ok, out, err) = servo(&args);
            assert!(!ok, "{args:?} accepted {name}:\n{out}");
            assert!(
                err.contains(words) && err.contains(fix) && err.contains("--columns"),
                "{args:?} on {name}: {err}"
            );
        }
        // The fix it names reads the log.
        let map = err_map(&log, &model);
        let (ok, _, err) = servo(&[
            "compare",
            "--model",
            model.to_str().unwrap(),
            l,
            "--columns",
            &map,
        ]);
        assert!(ok, "{name} with --columns {map}: {err}");
    }
    // The log as written is read without a word about units.
    let (ok, _, err) = servo(&[
        "compare",
        "--model",
        model.to_str().unwrap(),
        run.to_str().unwrap(),
    ]);
    assert!(ok && !err.contains("times as fast"), "{err}");
}

/// The `--columns` value a refusal names.
fn err_map(log: &Path, model: &Path) -> String {
    let (_, _, err) = servo(&[
        "compare",
        "--model",
        model.to_str().unwrap(),
        log.to_str().unwrap(),
    ]);
    let at = err.find("--columns ").expect("a --columns fix") + "--columns ".len();
    err[at..].split_whitespace().next().unwrap().to_string()
}

/// A length column on a rotary rig is refused with what to write instead (never dropped, which
/// made compare replay the speed alone).
#[test]
fn a_length_on_a_rotary_rig_is_refused() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let run = sine_csv(tmp.path(), "run.csv", &[]);
    let model = lab_model(tmp.path());
    let log = tmp.path().join("mm.csv");
    rewrite(&run, &log, &[("theta_l_rad", "theta_l_mm")], None, &[]);
    let (ok, out, err) = servo(&[
        "compare",
        "--model",
        model.to_str().unwrap(),
        log.to_str().unwrap(),
    ]);
    assert!(!ok, "accepted:\n{out}");
    assert!(
        err.contains("`theta_l_mm`")
            && err.contains("rotary")
            && err.contains("theta_l=theta_l_mm:deg")
            && err.contains("[transmission]"),
        "{err}"
    );
}

/// A supply voltage is never guessed as u: `inspect` maps it as v_supply, and identify on a log
/// whose only voltage is the supply does not fit J_eq to it.
#[test]
fn a_supply_column_is_never_u() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let run = sine_csv(tmp.path(), "run.csv", &[]);
    for header in ["v_supply_V", "vin_V", "vbus_V", "input_voltage_V"] {
        let log = tmp.path().join(format!("{header}.csv"));
        rewrite(&run, &log, &[("u_V", header)], None, &[]);
        let (ok, out, err) = servo(&["inspect", log.to_str().unwrap()]);
        assert!(ok, "{err}");
        assert!(
            out.contains(&format!("v_supply={header}")) && !out.contains("u="),
            "{header}: {out}"
        );
        // Without the current, nothing is left to identify from: refused, never a J_eq.
        let nocur = tmp.path().join(format!("{header}_noi.csv"));
        rewrite(&run, &nocur, &[("u_V", header)], None, &["i_a_A"]);
        let (ok, out, _) = servo(&["identify", nocur.to_str().unwrap()]);
        assert!(!ok || !out.contains("J_eq"), "{header}: {out}");
    }
    // Two columns that both look like u: not guessed.
    let log = tmp.path().join("two_u.csv");
    rewrite(&run, &log, &[("omega_l_rad_s", "u_cmd_V")], None, &[]);
    let (ok, _, err) = servo(&["identify", log.to_str().unwrap()]);
    assert!(
        !ok && err.contains("`u_V` and `u_cmd_V`") && err.contains("--columns"),
        "{err}"
    );
}

/// A current in milliamperes under an ampere header, or of the other sign: identify, compare and
/// diagnose refuse the log naming the unit (with the `--columns` to write) or the sign; with
/// the named map the log is read; the log as written passes without a word on the current.
#[test]
fn a_current_that_disagrees_with_its_voltage_balance_is_named() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let run = sine_csv(tmp.path(), "run.csv", &[]);
    let model = lab_model(tmp.path());
    let m = model.to_str().unwrap();
    let ma = tmp.path().join("ma.csv");
    rewrite(&run, &ma, &[], Some(("i_a_A", 1000.0)), &[]);
    let neg = tmp.path().join("neg.csv");
    rewrite(&run, &neg, &[], Some(("i_a_A", -1.0)), &[]);
    for (log, words) in [(&ma, "milliamperes"), (&neg, "other sign")] {
        let l = log.to_str().unwrap();
        for args in [
            vec!["identify", l, "--params", m],
            vec!["compare", "--model", m, l],
            vec!["diagnose", "--model", m, l],
        ] {
            let (ok, out, err) = servo(&args);
            assert!(!ok, "{args:?} accepted {}:\n{out}", log.display());
            assert!(err.contains(words), "{args:?}: {err}");
        }
    }
    let map = err_map(&ma, &model);
    assert!(map.contains("i_a=i_a_A:mA"), "{map}");
    let (ok, _, err) = servo(&[
        "compare",
        "--model",
        m,
        ma.to_str().unwrap(),
        "--columns",
        &map,
    ]);
    assert!(ok && !err.contains("voltage balance"), "{map}: {err}");
    let (ok, _, err) = servo(&["identify", run.to_str().unwrap(), "--params", m]);
    assert!(ok && !err.contains("voltage balance"), "{err}");
}

/// Another motor (24 V drive, k_t 0.0389, N = 10) with `--ramp --plant` and no `--params`:
/// identified with that motor's constants (J_eq within 10 % of its truth, the model written
/// keeps its k_t, N and drive gain); without `--plant` the Table 2 constants are said in the
/// output and in the file.
#[test]
fn another_motor_ramp_uses_its_own_constants() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let (_, lab, _) = servo(&["params"]);
    let set = |text: &str, key: &str, v: &str| -> String {
        text.lines()
            .map(|l| {
                if l.starts_with(&format!("{key} = ")) {
                    format!("{key} = {v}")
                } else {
                    l.to_string()
                }
            })
            .collect::<Vec<_>>()
            .join("\n")
    };
    let (j_true, k_t, n) = (8e-6, 0.0389, 10.0);
    let mut other = lab.clone();
    for (k, v) in [
        ("r_a", "1.5"),
        ("l_a", "5e-4"),
        ("k_e", "0.0389"),
        ("k_t", "0.0389"),
        ("j_m", "4e-6"),
        ("n", "10"),
        ("k_drv", "2.4"),
        ("j_eq", "8e-6"),
        ("b_eq", "5e-6"),
        ("tau_sf", "0.03"),
    ] {
        other = set(&other, k, v);
    }
    let plant = tmp.path().join("other.toml");
    std::fs::write(&plant, &other).unwrap();
    let out_model = tmp.path().join("model.toml");
    let dir = tmp.path().join("logs");
    let (ok, out, err) = servo(&[
        "identify",
        "--ramp",
        "--plant",
        plant.to_str().unwrap(),
        "--log-dir",
        dir.to_str().unwrap(),
        "--progress",
        "never",
        "-o",
        out_model.to_str().unwrap(),
        "--json",
    ]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let j = v["j_eq_kg_m2"]["value"].as_f64().unwrap();
    assert!((j / j_true - 1.0).abs() < 0.1, "J_eq {j} vs {j_true}");
    assert!(
        err.contains("--plant") && err.contains("constants"),
        "{err}"
    );
    let written = std::fs::read_to_string(&out_model).unwrap();
    let num = |key: &str| -> f64 {
        written
            .lines()
            .find_map(|l| l.strip_prefix(&format!("{key} = ")))
            .and_then(|r| r.split_whitespace().next())
            .and_then(|x| x.parse().ok())
            .unwrap_or_else(|| panic!("{key} in\n{written}"))
    };
    assert_eq!(num("k_t"), k_t);
    assert_eq!(num("n"), n);
    assert_eq!(num("k_drv"), 2.4);
    // Without --params or --plant: the Table 2 constants are said where they are used.
    let out2 = tmp.path().join("model2.toml");
    let run = sine_csv(tmp.path(), "run.csv", &[]);
    let (ok, out, err) = servo(&[
        "identify",
        run.to_str().unwrap(),
        "-o",
        out2.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(
        out.contains("no --params") && out.contains("Table 2") && out.contains("k_t = "),
        "{out}"
    );
    let written = std::fs::read_to_string(&out2).unwrap();
    assert!(
        written
            .lines()
            .any(|l| l.starts_with("# NOTE: no --params") && l.contains("Table 2")),
        "{written}"
    );
}

/// A parameter added from zero prints its new value, never a percentage of zero, and no number
/// of `compare --add` carries more than about six significant figures.
#[test]
fn a_parameter_added_from_zero_prints_no_long_number() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let run = sine_csv(
        tmp.path(),
        "run.csv",
        &["--plant-effect", "viscous:b_eq=2e-6"],
    );
    // A model whose viscous friction is zero: compare --add refits it from zero.
    let (_, lab, _) = servo(&["params"]);
    let model = tmp.path().join("zero_b.toml");
    let text: String = lab
        .lines()
        .map(|l| {
            if l.starts_with("b_eq = ") {
                "b_eq = 0".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(&model, text).unwrap();
    let saved = tmp.path().join("saved.toml");
    let (ok, out, err) = servo(&[
        "compare",
        "--model",
        model.to_str().unwrap(),
        run.to_str().unwrap(),
        "--add",
        "viscous",
        "--save",
        saved.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let line = out
        .lines()
        .find(|l| l.contains("refitted with the effects"))
        .unwrap_or_else(|| panic!("no refitted line:\n{out}"));
    assert!(
        line.contains("b_eq 0 -> ") && line.contains("(new, was 0)"),
        "{line}"
    );
    for l in out.lines().chain(err.lines()) {
        let longest = l
            .split(|c: char| !(c.is_ascii_digit()))
            .map(str::len)
            .max()
            .unwrap_or(0);
        assert!(longest <= 7, "a long number: {l}");
    }
}

/// B_eq pinned at its bound by the fit of a log without current (a Stribeck friction, whose
/// torque falls with speed, leaves the viscous term nothing): said "not determined by these
/// logs" with the experiment that would, never "0 +/- NaN".
#[test]
fn a_parameter_at_its_bound_is_not_determined() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let run = run_csv(
        tmp.path(),
        "run.csv",
        "prbs:amp=4,bit=0.05",
        "8",
        &[
            "--plant-effect",
            "viscous:b_eq=0",
            "--plant-effect",
            "stribeck:tau_s=0.02,omega_s=3",
        ],
    );
    let log = tmp.path().join("noi.csv");
    rewrite(&run, &log, &[], None, &["i_a_A"]);
    let (ok, out, err) = servo(&["identify", log.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(!out.contains("NaN"), "{out}");
    let b = out
        .lines()
        .find(|l| l.trim_start().starts_with("b_eq"))
        .unwrap_or("");
    assert!(b.contains("not determined by these logs"), "{out}");
    assert!(
        out.contains("b_eq not determined by these logs") && out.contains("staircase"),
        "{out}"
    );
}
