//! `servo demo` end to end: it tells the whole story (design, run, identify, compare, diagnose,
//! add the effect, diagnose again), names the hidden effect, shows the fit rising and leaves its
//! files in the output folder.

use servo_e2e::servo;

/// The `-> headline` line of a stage.
fn headline<'a>(stdout: &'a str, stage: &str) -> &'a str {
    let mut lines = stdout.lines();
    while let Some(l) = lines.next() {
        if l.starts_with("== [") && l.contains(&format!("] {stage}: ")) {
            for h in lines.by_ref() {
                if let Some(rest) = h.trim_start().strip_prefix("-> ") {
                    return rest;
                }
            }
        }
    }
    panic!("no headline for stage `{stage}` in:\n{stdout}");
}

/// The numbers in `s` (e.g. "fit 71.3 % -> 94.8 %" gives [71.3, 94.8]).
fn numbers(s: &str) -> Vec<f64> {
    s.split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == 'e'))
        .filter_map(|w| {
            w.trim_matches(|c| c == '.' || c == '-' || c == 'e')
                .parse()
                .ok()
        })
        .collect()
}

#[test]
fn demo_tells_the_whole_story() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo out");
    let (ok, stdout, stderr) = servo(&["demo", "--out", out.to_str().unwrap()]);
    println!("{stdout}");
    assert!(ok, "servo demo failed: {stderr}\n{stdout}");
    // The default text is the story, short: each step's command and its one-line result, and
    // its normal path says nothing that reads as an error.
    let lines = stdout.lines().count();
    assert!(lines <= 40, "the demo prints {lines} lines:\n{stdout}");
    for l in stdout.lines().chain(stderr.lines()) {
        let low = l.to_ascii_lowercase();
        for word in [
            "error:",
            "warning",
            "not identified",
            "negative",
            "unphysical",
            "failed",
        ] {
            assert!(!low.contains(word), "the demo says `{word}`: {l}");
        }
    }

    for f in [
        "gains.toml",
        "truth_hidden.toml",
        "run.mcap",
        "run.csv",
        "run.svg",
        "identify_openloop.csv",
        "model_identified.toml",
        "compare.svg",
        "diagnose.html",
        "model_plus_imbalance.toml",
        "compare_plus_imbalance.svg",
        "diagnose_after.html",
    ] {
        let p = out.join(f);
        let len = std::fs::metadata(&p)
            .unwrap_or_else(|e| panic!("{} missing: {e}", p.display()))
            .len();
        assert!(len > 0, "{} is empty", p.display());
    }
    // The printed story names the hidden effect and the diagnosis finds it.
    let diag = headline(&stdout, "diagnose");
    assert!(
        diag.starts_with("missing effect: imbalance") && diag.contains("; the hidden effect"),
        "diagnose headline: {diag}"
    );
    // The fit rises when the effect is added, and the amplitude is recovered within 15 %.
    let add = headline(&stdout, "add");
    assert!(
        add.contains("after adding imbalance"),
        "add headline: {add}"
    );
    let v = numbers(add);
    let (before, after) = (v[0], v[1]);
    assert!(after > before + 1.0, "fit did not rise: {add}");
    let amp = add
        .split("amplitude ")
        .nth(1)
        .map(numbers)
        .and_then(|n| n.first().copied())
        .unwrap_or_else(|| panic!("no amplitude in: {add}"));
    assert!(
        (amp / 0.01 - 1.0).abs() < 0.15,
        "amplitude {amp} N m vs truth 0.01: {add}"
    );
    // The identified model was the base model the story starts from.
    let cmp = headline(&stdout, "compare");
    assert!(
        cmp.starts_with("fit ") && cmp.contains("where it fails:"),
        "compare headline: {cmp}"
    );
    assert!(
        (numbers(cmp)[0] - before).abs() < 0.05,
        "compare fit and ladder start differ: {cmp} / {add}"
    );
    // Nothing significant is left.
    let again = headline(&stdout, "re-diagnose");
    assert!(
        again.starts_with("nothing significant left"),
        "re-diagnose headline: {again}"
    );
    // The story ends with the added effect compensated in the loop: the tracking error falls
    // by at least half against the friction feedforward (issue #29).
    let comp = headline(&stdout, "compensate");
    let n = numbers(comp);
    assert!(
        comp.contains("compensating") && comp.contains("imbalance") && n.len() >= 3,
        "compensate headline: {comp}"
    );
    assert!(
        n[1] < 0.5 * n[0] && n[2] >= 50.0 && comp.contains("(-"),
        "the compensation did not halve the tracking error: {comp}"
    );
    // It prints where its files are.
    assert!(stdout.contains("demo done in"), "{stdout}");
    assert!(stdout.contains("diagnose.html"), "{stdout}");
}

#[test]
fn demo_rejects_an_unusable_out_folder() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a file");
    std::fs::write(&file, "x").unwrap();
    let (ok, _, stderr) = servo(&["demo", "--out", file.to_str().unwrap()]);
    assert!(!ok, "demo into a file should fail");
    assert!(stderr.contains("--out"), "{stderr}");
}

/// `servo ... | head`: a reader that leaves early must not make servo panic (plain `println!`
/// does on a closed stdout); the command finishes its work and exits normally.
#[test]
fn closed_stdout_is_not_a_panic() {
    let _machine = servo_e2e::shared();
    use std::process::{Command, Stdio};
    let mut child = Command::new(servo_e2e::servo_bin())
        .args(["params"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Close the read end before servo writes.
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert!(out.status.success(), "status {:?}: {err}", out.status);
}

/// The same story through the real commands with other hidden effects (the default is an
/// imbalance): backlash (judged on simulation), cogging (weak: 3e-4 N m, twice the Coulomb level
/// at the motor), stiction and a transport delay. Each is named, its main parameter recovered
/// within 15 %, the fit rises when it is added, and nothing significant is left.
#[test]
fn demo_finds_other_hidden_effects() {
    let _machine = servo_e2e::shared();
    for (hidden, name, key, truth) in [
        ("backlash:gap=0.03", "backlash", "gap", 0.03),
        (
            "cogging:amplitude=3e-4,harmonic=12",
            "cogging",
            "amplitude",
            3e-4,
        ),
        ("stribeck:tau_s=0.02,omega_s=0.5", "stribeck", "tau_s", 0.02),
        ("delay:delay=0.003", "delay", "delay", 0.003),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("demo");
        let (ok, stdout, stderr) =
            servo(&["demo", "--out", out.to_str().unwrap(), "--hidden", hidden]);
        assert!(ok, "[{hidden}] servo demo failed: {stderr}\n{stdout}");
        let diag = headline(&stdout, "diagnose");
        assert!(
            diag.starts_with(&format!("missing effect: {name}")),
            "[{hidden}] diagnose headline: {diag}"
        );
        let add = headline(&stdout, "add");
        let v = numbers(add);
        assert!(v[1] > v[0], "[{hidden}] fit did not rise: {add}");
        // The parameter as printed in the diagnose headline ("gap 0.0280 rad").
        let got = diag
            .split(&format!(", {key} "))
            .nth(1)
            .map(numbers)
            .and_then(|n| n.first().copied())
            .unwrap_or_else(|| panic!("[{hidden}] no {key} in: {diag}"));
        assert!(
            (got / truth - 1.0).abs() < 0.15,
            "[{hidden}] {key} {got} vs truth {truth}: {diag}"
        );
        let again = headline(&stdout, "re-diagnose");
        assert!(
            again.starts_with("nothing significant left"),
            "[{hidden}] re-diagnose headline: {again}"
        );
    }
}
