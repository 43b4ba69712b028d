//! Every `--json` output names its schema and validates against docs/schemas/*.json.
//!
//! `servo_e2e::servo` validates any `--json` output that any test produces; this file runs each
//! command once in its main variants on short simulated logs (a few seconds in all), checks the
//! schema files themselves and shows that the check fails on an output that breaks the key
//! convention.

use servo_e2e::{schema_path, servo, validate_output};
use std::path::Path;

const COMMANDS: [&str; 6] = ["design", "identify", "compare", "diagnose", "frf", "trend"];

/// Runs `args` (ending in `--json`), which validates the output, and returns it.
fn json(args: &[&str]) -> serde_json::Value {
    let (ok, out, err) = servo(args);
    assert!(ok, "servo {args:?} failed: {err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let want = format!("servo.{}/1", args[0]);
    assert_eq!(v["schema"], want.as_str(), "servo {args:?}");
    v
}

#[test]
fn schema_files_are_valid_2020_12_and_documented() {
    let _machine = servo_e2e::shared();
    let readme = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/schemas/README.md"),
    )
    .unwrap();
    for c in COMMANDS {
        let id = format!("servo.{c}/1");
        let path = schema_path(&id).unwrap();
        let schema: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        assert_eq!(
            schema["$schema"],
            "https://json-schema.org/draft/2020-12/schema"
        );
        assert_eq!(schema["title"], id.as_str());
        assert_eq!(schema["properties"]["schema"]["const"], id.as_str());
        jsonschema::meta::validate(&schema)
            .unwrap_or_else(|e| panic!("{}: not a valid schema: {e}", path.display()));
        assert!(readme.contains(&format!("`{id}`")), "README lacks {id}");
    }
}

#[test]
fn every_command_output_follows_its_schema() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    // design: plain Bode, time-domain specs with the range check, and --meet-specs
    let plain = json(&["design", "--wc", "30", "--pm", "60", "--json"]);
    assert!(plain["wgc_rad_s"].as_f64().unwrap() == 30.0 && plain["ts_s"].is_number());
    // design on a model file with effects, verified with and without their compensation
    let with_effects = p("effects.toml");
    let (ok, params, _) = servo(&["params"]);
    assert!(ok);
    std::fs::write(
        &with_effects,
        format!("{params}\n[effects.imbalance]\namplitude = 0.02\nphase = 0.0\n"),
    )
    .unwrap();
    let c = json(&[
        "design",
        "--wc",
        "30",
        "--pm",
        "60",
        "--model",
        &with_effects,
        "--ff",
        "all",
        "--json",
    ]);
    assert!(c["compensation_check"]["tracking"]["ladder"].is_array());
    json(&[
        "design",
        "--overshoot",
        "0.1",
        "--settling-time",
        "0.15",
        "--alpha",
        "6",
        "--exact",
        "--json",
    ]);
    let (gains, model) = (p("gains.toml"), p("model.toml"));
    json(&[
        "design",
        "--overshoot",
        "0.1",
        "--settling-time",
        "0.15",
        "--meet-specs",
        "-o",
        &gains,
        "--force",
        "--json",
    ]);
    // a closed-loop step and a chirp on the simulator
    let (run, chirp) = (p("run.mcap"), p("chirp.mcap"));
    let chirp_exp = Path::new(env!("CARGO_MANIFEST_DIR")).join("experiments/chirp.toml");
    for args in [
        vec![
            "run",
            "--gains",
            &gains,
            "--ref",
            "step:1.5",
            "--duration",
            "3",
            "--log",
            &run,
        ],
        vec![
            "run",
            "--gains",
            &gains,
            "--experiment",
            chirp_exp.to_str().unwrap(),
            "--log",
            &chirp,
        ],
    ] {
        let (ok, _, err) = servo(&args);
        assert!(ok, "{args:?}: {err}");
    }
    // identify from the logs (combined LS with the current) and without the current
    let id = json(&["identify", &run, &chirp, "-o", &model, "--json"]);
    assert!(id["j_eq_kg_m2"]["value"].as_f64().unwrap() > 0.0, "{id}");
    let csv = p("nocurrent.csv");
    let (ok, _, err) = servo(&["export", &chirp, "-o", &csv]);
    assert!(ok, "{err}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let header = text.lines().next().unwrap().to_string();
    let keep: Vec<usize> = header
        .split(',')
        .enumerate()
        .filter(|(_, h)| !h.starts_with("i_a"))
        .map(|(i, _)| i)
        .collect();
    let stripped: String = text
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            keep.iter().map(|&i| f[i]).collect::<Vec<_>>().join(",") + "\n"
        })
        .collect();
    std::fs::write(&csv, stripped).unwrap();
    let nocur = json(&["identify", &csv, "--json"]);
    assert_eq!(nocur["method"], "u-driven balance (no current logged)");
    // compare with and without --add, diagnose with and without --auto, frf closed loop
    let cmp = json(&["compare", &run, &chirp, "--model", &model, "--json"]);
    assert!(cmp["fit_pct"].is_number() && cmp["base"]["b_eq_n_m_s_rad"].is_number());
    json(&[
        "compare", &run, &chirp, "--model", &model, "--add", "backlash", "--json",
    ]);
    json(&["diagnose", &run, &chirp, "--model", &model, "--json"]);
    json(&[
        "diagnose", &run, &chirp, "--model", &model, "--auto", "--json",
    ]);
    // a joint search of one candidate is no joint search: refused, naming the flag
    let (ok, _, err) = servo(&["diagnose", &run, "--model", &model, "--joint", "1"]);
    assert!(!ok && err.contains("--joint"), "{err}");
    json(&[
        "frf", &chirp, "--gains", &gains, "--model", &model, "--json",
    ]);
}

#[test]
fn an_output_breaking_the_convention_is_refused() {
    let _machine = servo_e2e::shared();
    let (ok, out, err) = servo(&["design", "--wc", "30", "--pm", "60", "--json"]);
    assert!(ok, "{err}");
    let good: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(validate_output(&good), Ok(()));
    // the old spellings: `wgc` without its unit, a string where a number belongs, no schema
    let mut old = good.clone();
    let w = old.as_object_mut().unwrap().remove("wgc_rad_s").unwrap();
    old["wgc"] = w;
    let e = validate_output(&old).unwrap_err();
    assert!(e.contains("wgc"), "{e}");
    let mut wrong = good.clone();
    wrong["kp"] = "7.0".into();
    assert!(validate_output(&wrong).unwrap_err().contains("/kp"));
    let mut untagged = good;
    untagged.as_object_mut().unwrap().remove("schema");
    assert!(validate_output(&untagged).is_err());
}

#[test]
fn loop_message_schema_requires_only_the_time() {
    let _machine = servo_e2e::shared();
    let schema: serde_json::Value =
        serde_json::from_str(&servo_cli::io::loop_msg::loop_schema()).unwrap();
    jsonschema::meta::validate(&schema).unwrap();
    let v = jsonschema::draft202012::new(&schema).unwrap();
    // a foreign log's message: time and angle only, the current null
    assert!(v.is_valid(&serde_json::json!({"time_s": 0.001, "theta_l_rad": 0.5, "i_a_a": null})));
    assert!(!v.is_valid(&serde_json::json!({"theta_l_rad": 0.5})));
    assert!(!v.is_valid(&serde_json::json!({"time_s": null})));
    assert!(!v.is_valid(&serde_json::json!({"time_s": 0.0, "u_v": "1 V"})));
    // what servo writes validates
    let m = servo_cli::io::loop_msg::LoopMsg {
        time_s: 0.5,
        ref_rad: f64::NAN,
        theta_l_rad: 0.1,
        omega_l_rad_s: 2.0,
        err_rad: f64::NAN,
        u_v: 1.0,
        ff_v: 0.0,
        p_v: 1.0,
        i_v: 0.0,
        d_v: 0.0,
        i_a_a: 0.2,
        saturated: false,
        ref_omega_l_rad_s: f64::NAN,
        i_ref_a: f64::NAN,
        duty: f64::NAN,
    };
    assert!(v.is_valid(&serde_json::to_value(m).unwrap()));
    // A current drive's message (i_ref_a, u_v null) and a duty drive's validate too.
    for (i_ref_a, duty) in [(0.75, f64::NAN), (f64::NAN, -0.5)] {
        let d = servo_cli::io::loop_msg::LoopMsg {
            u_v: f64::NAN,
            i_ref_a,
            duty,
            ..m
        };
        assert!(v.is_valid(&serde_json::to_value(d).unwrap()));
    }
}
