//! The README and the user guide (`docs/guide`, an mdBook) say what servo does: every `servo ...`
//! command of their ```sh blocks names a real subcommand and only flags that subcommand has,
//! the README's story runs as written (in a temporary folder, on the simulator) and tells what
//! its comments claim, and every link of the book and the README resolves.
//!
//! A ```sh,no-run block (mdBook renders it as `sh`) is skipped by the command checks: cargo
//! commands, shell templates. Chapters are read as mdBook reads them: `{{#include FILE}}`
//! replaced by FILE (relative to the chapter).

use servo_e2e::servo_bin;
use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::process::Command;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn guide_src() -> PathBuf {
    workspace().join("docs/guide/src")
}

/// A Markdown file as its reader sees it.
struct Doc {
    /// The file (links resolve from its folder).
    path: PathBuf,
    /// Its text, includes expanded.
    text: String,
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// `text` (of a chapter in `dir`) with every `{{#include FILE}}` replaced by FILE's text.
fn expand_includes(dir: &Path, text: &str, from: &Path) -> String {
    let mut out = String::new();
    let mut rest = text;
    while let Some(i) = rest.find("{{#include ") {
        out.push_str(&rest[..i]);
        let after = &rest[i + "{{#include ".len()..];
        let end = after
            .find("}}")
            .unwrap_or_else(|| panic!("{}: unclosed {{{{#include", from.display()));
        let file = dir.join(after[..end].trim());
        assert!(
            file.is_file(),
            "{}: {{{{#include {}}}}} names no file",
            from.display(),
            after[..end].trim()
        );
        out.push_str(&read(&file));
        rest = &after[end + 2..];
    }
    out.push_str(rest);
    out
}

/// The README and every chapter of the guide.
fn docs() -> Vec<Doc> {
    let mut v = vec![Doc {
        path: workspace().join("README.md"),
        text: read(&workspace().join("README.md")),
    }];
    let src = guide_src();
    let mut chapters: Vec<PathBuf> = std::fs::read_dir(&src)
        .unwrap_or_else(|e| panic!("{}: {e}", src.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    chapters.sort();
    for path in chapters {
        let text = expand_includes(&src, &read(&path), &path);
        v.push(Doc { path, text });
    }
    v
}

/// A fenced code block.
struct Block {
    /// The info string (`sh`, `sh,no-run`, `toml`, ...).
    info: String,
    /// Line number (1-based) of its opening fence.
    line: usize,
    lines: Vec<String>,
}

/// The fenced code blocks of `text` (``` or ~~~ fences of 3 or more, indented or not).
fn blocks(text: &str) -> Vec<Block> {
    let fence_of = |t: &str| -> Option<(char, usize)> {
        let c = t.chars().next().filter(|c| *c == '`' || *c == '~')?;
        let n = t.chars().take_while(|d| *d == c).count();
        (n >= 3).then_some((c, n))
    };
    let mut v = Vec::new();
    let mut open: Option<((char, usize), Block)> = None;
    for (i, l) in text.lines().enumerate() {
        let t = l.trim_start();
        match open.take() {
            None => {
                if let Some((c, n)) = fence_of(t) {
                    let info = t[n..].trim().to_string();
                    open = Some((
                        (c, n),
                        Block {
                            info,
                            line: i + 1,
                            lines: Vec::new(),
                        },
                    ));
                }
            }
            Some(((c, n), mut b)) => match fence_of(t) {
                Some((d, m)) if d == c && m >= n && t[m..].trim().is_empty() => v.push(b),
                _ => {
                    b.lines.push(l.to_string());
                    open = Some(((c, n), b));
                }
            },
        }
    }
    assert!(open.is_none(), "an unclosed code fence");
    v
}

/// Does the info string ask for shell commands that the checks read?
fn is_checked_sh(info: &str) -> bool {
    let mut words = info.split([',', ' ']).filter(|w| !w.is_empty());
    matches!(words.next(), Some("sh" | "bash" | "shell" | "console"))
        && !words.any(|w| w == "no-run")
}

/// One shell word or operator.
#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Word(String),
    Op(String),
}

/// Splits a shell line into words (quotes removed) and operators; a `#` starting a word starts
/// a comment.
fn shell_tokens(line: &str) -> Vec<Tok> {
    let mut v = Vec::new();
    let mut cur = String::new();
    let mut in_word = false;
    let mut chars = line.chars().peekable();
    let flush = |cur: &mut String, in_word: &mut bool, v: &mut Vec<Tok>| {
        if *in_word {
            v.push(Tok::Word(std::mem::take(cur)));
            *in_word = false;
        }
    };
    while let Some(c) = chars.next() {
        match c {
            '\'' | '"' => {
                in_word = true;
                for d in chars.by_ref() {
                    if d == c {
                        break;
                    }
                    cur.push(d);
                }
            }
            '#' if !in_word => break,
            c if c.is_whitespace() => flush(&mut cur, &mut in_word, &mut v),
            '&' | '|' | ';' | '>' | '<' | '(' | ')' => {
                flush(&mut cur, &mut in_word, &mut v);
                let mut op = c.to_string();
                if let Some(&d) = chars.peek() {
                    if d == c && (c == '&' || c == '|' || c == '>') {
                        op.push(d);
                        chars.next();
                    }
                }
                v.push(Tok::Op(op));
            }
            c => {
                in_word = true;
                cur.push(c);
            }
        }
    }
    flush(&mut cur, &mut in_word, &mut v);
    v
}

/// A `servo` command of a block: its arguments, and the file its stdout is redirected to.
#[derive(Debug, Clone, PartialEq)]
struct ServoCommand {
    args: Vec<String>,
    stdout_to: Option<String>,
}

/// The `servo ...` commands of a block's lines (continuation lines joined; comments dropped).
fn servo_commands(lines: &[String]) -> Vec<ServoCommand> {
    let mut joined = Vec::new();
    let mut cur = String::new();
    for l in lines {
        if let Some(head) = l.trim_end().strip_suffix('\\') {
            cur.push_str(head);
            cur.push(' ');
        } else {
            cur.push_str(l);
            joined.push(std::mem::take(&mut cur));
        }
    }
    joined.push(cur);
    let mut v = Vec::new();
    for line in joined {
        let toks = shell_tokens(&line);
        let mut i = 0;
        while i < toks.len() {
            if toks[i] == Tok::Word("servo".into()) {
                let mut cmd = ServoCommand {
                    args: Vec::new(),
                    stdout_to: None,
                };
                i += 1;
                while i < toks.len() {
                    match &toks[i] {
                        Tok::Word(w) => cmd.args.push(w.clone()),
                        Tok::Op(o) if o == ">" => {
                            if let Some(Tok::Word(f)) = toks.get(i + 1) {
                                cmd.stdout_to = Some(f.clone());
                                i += 1;
                            }
                        }
                        Tok::Op(_) => break,
                    }
                    i += 1;
                }
                v.push(cmd);
            }
            i += 1;
        }
    }
    v
}

/// What `servo <path> --help` lists: subcommands and flags.
#[derive(Default)]
struct Help {
    subcommands: BTreeSet<String>,
    flags: BTreeSet<String>,
}

fn help_of<'a>(path: &[String], cache: &'a mut HashMap<Vec<String>, Help>) -> &'a Help {
    cache.entry(path.to_vec()).or_insert_with(|| {
        let out = Command::new(servo_bin())
            .args(path)
            .arg("--help")
            .output()
            .expect("spawn servo");
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(
            out.status.success(),
            "servo {} --help failed:\n{text}{}",
            path.join(" "),
            String::from_utf8_lossy(&out.stderr)
        );
        let mut h = Help::default();
        let mut section = "";
        for l in text.lines() {
            if !l.starts_with(' ') && l.ends_with(':') {
                section = if l.starts_with("Commands") {
                    "commands"
                } else {
                    "other"
                };
                continue;
            }
            let t = l.trim_start();
            if section == "commands" && l.starts_with("  ") && !t.is_empty() {
                if let Some(name) = t.split_whitespace().next() {
                    h.subcommands.insert(name.to_string());
                }
            }
            if t.starts_with('-') && l.starts_with("  ") {
                for w in t.split_whitespace() {
                    let w = w.trim_end_matches(',');
                    if !w.starts_with('-') || w == "-" {
                        break;
                    }
                    h.flags.insert(w.to_string());
                }
            }
        }
        assert!(
            h.flags.contains("--help"),
            "servo {} --help lists no flags:\n{text}",
            path.join(" ")
        );
        h
    })
}

/// Checks one command: its subcommand exists, every flag it uses is one of that subcommand's.
fn check_command(cmd: &ServoCommand, cache: &mut HashMap<Vec<String>, Help>) -> Result<(), String> {
    let mut path: Vec<String> = Vec::new();
    let mut rest = cmd.args.as_slice();
    loop {
        let h = help_of(&path, cache);
        if h.subcommands.is_empty() {
            break;
        }
        match rest.first() {
            Some(w) if h.subcommands.contains(w) => {
                path.push(w.clone());
                rest = &rest[1..];
            }
            Some(w) if w.starts_with('-') && path.is_empty() && h.flags.contains(w.as_str()) => {
                return Ok(()); // servo --help, servo --version
            }
            other => {
                return Err(format!(
                    "`servo {}`: no subcommand {:?} (servo {} has {:?})",
                    cmd.args.join(" "),
                    other,
                    path.join(" "),
                    h.subcommands
                ))
            }
        }
    }
    let h = help_of(&path, cache);
    for a in rest {
        if !a.starts_with('-') || a == "-" || a.parse::<f64>().is_ok() {
            continue;
        }
        let flag = a.split('=').next().unwrap_or(a);
        if !h.flags.contains(flag) {
            return Err(format!(
                "`servo {}`: `servo {}` has no flag {flag} (it has {:?})",
                cmd.args.join(" "),
                path.join(" "),
                h.flags
            ));
        }
    }
    Ok(())
}

/// Every `servo` command of every checked ```sh block names a subcommand and flags that exist.
#[test]
fn every_documented_command_parses() {
    let _machine = servo_e2e::shared();
    let mut cache = HashMap::new();
    let mut errors = Vec::new();
    let mut n = 0;
    for d in docs() {
        for b in blocks(&d.text) {
            if !is_checked_sh(&b.info) {
                continue;
            }
            for cmd in servo_commands(&b.lines) {
                n += 1;
                if let Err(e) = check_command(&cmd, &mut cache) {
                    errors.push(format!(
                        "{} (block at line {}): {e}",
                        d.path.display(),
                        b.line
                    ));
                }
            }
        }
    }
    eprintln!("{n} documented servo commands checked");
    assert!(
        n >= 50,
        "only {n} servo commands found in the README and the guide"
    );
    assert!(errors.is_empty(), "{}", errors.join("\n"));
}

/// The checker itself: a wrong flag and a wrong subcommand are caught, quoting and
/// continuation lines are read as a shell reads them.
#[test]
fn the_command_checker_catches_wrong_commands() {
    let _machine = servo_e2e::shared();
    let mut cache = HashMap::new();
    let parse = |s: &str| servo_commands(&s.lines().map(String::from).collect::<Vec<_>>());
    let cmds = parse(
        "servo params > plant.toml   # a comment with --no-such-flag\n\
         servo compare a.mat --columns 'time=s.time,u=s.signals(1).values' \\\n  --model m.toml\n\
         (cd firmware && cargo build) && servo log recover b.mcap -o f.mcap &",
    );
    assert_eq!(cmds.len(), 3, "{cmds:?}");
    assert_eq!(cmds[0].stdout_to.as_deref(), Some("plant.toml"));
    assert_eq!(
        cmds[1].args,
        [
            "compare",
            "a.mat",
            "--columns",
            "time=s.time,u=s.signals(1).values",
            "--model",
            "m.toml"
        ]
    );
    assert_eq!(cmds[2].args, ["log", "recover", "b.mcap", "-o", "f.mcap"]);
    for c in &cmds {
        check_command(c, &mut cache).unwrap();
    }
    for bad in [
        "servo design --wc 30 --phase-margin 60",
        "servo identfy --ramp",
        "servo log recoverr b.mcap",
        "servo run --plant-effect=backlash --no-such-flag",
    ] {
        let c = &parse(bad)[0];
        assert!(
            check_command(c, &mut cache).is_err(),
            "{bad} passed the check"
        );
    }
    assert!(is_checked_sh("sh") && is_checked_sh("console"));
    assert!(!is_checked_sh("sh,no-run") && !is_checked_sh("sh no-run") && !is_checked_sh("toml"));
}

/// The `servo` commands of the first ```sh block after the heading `heading` of `doc`.
fn story_after(doc: &Doc, heading: &str) -> Vec<ServoCommand> {
    let at = doc
        .text
        .find(heading)
        .unwrap_or_else(|| panic!("{}: no heading {heading:?}", doc.path.display()));
    let b = blocks(&doc.text[at..])
        .into_iter()
        .find(|b| is_checked_sh(&b.info))
        .unwrap_or_else(|| panic!("{}: no sh block after {heading:?}", doc.path.display()));
    servo_commands(&b.lines)
}

/// The numbers of the `fit` columns of compare's error ladder.
fn ladder_fits(stdout: &str) -> Vec<f64> {
    let at = stdout
        .find("error ladder")
        .unwrap_or_else(|| panic!("no error ladder in:\n{stdout}"));
    stdout[at..]
        .lines()
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| {
            let after = &l[l.find(" fit ")? + 5..];
            after.split_whitespace().next()?.parse().ok()
        })
        .collect()
}

/// README's first block holds exactly the two commands CI and newcomers start with; the story
/// in ten commands is the guide's, and it runs as written, telling what its comments say:
/// the diagnosis names the hidden imbalance, adding it raises the fit, the second diagnosis
/// finds nothing left.
#[test]
fn the_readme_story_runs_as_written() {
    let _machine = servo_e2e::shared();
    let docs = docs();
    let readme = &docs[0];
    let first = &blocks(&readme.text)[0];
    let first: Vec<String> = first
        .lines
        .iter()
        .map(|l| l.split('#').next().unwrap_or("").trim().to_string())
        .collect();
    assert_eq!(
        first,
        [
            "cargo run --release -p servo-cli -- demo --out servo-demo",
            "cargo test --workspace --release"
        ],
        "README.md must start with the demo and the test command"
    );
    let lines = readme.text.lines().count();
    assert!(
        lines < 150,
        "README.md has {lines} lines: the depth belongs in the guide"
    );

    let story = story_after(readme, "## The story in ten commands");
    let guide = docs
        .iter()
        .find(|d| d.path.ends_with("getting-started.md"))
        .expect("getting-started.md");
    assert_eq!(
        story,
        story_after(guide, "## The story, one command at a time"),
        "the guide's story differs from the README's"
    );
    assert_eq!(
        story.len(),
        10,
        "the story in ten commands has {}",
        story.len()
    );

    let dir = tempfile::tempdir().unwrap();
    let mut outputs = Vec::new();
    for cmd in &story {
        let t = std::time::Instant::now();
        let out = Command::new(servo_bin())
            .args(&cmd.args)
            .current_dir(dir.path())
            .output()
            .expect("spawn servo");
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(
            out.status.success(),
            "servo {} failed:\n{stdout}\n{stderr}",
            cmd.args.join(" "),
        );
        says_only_what_is_so(&cmd.args, &stdout, &stderr);
        eprintln!(
            "servo {}: {:.1} s",
            cmd.args.join(" "),
            t.elapsed().as_secs_f64()
        );
        if let Some(f) = &cmd.stdout_to {
            std::fs::write(dir.path().join(f), &out.stdout).unwrap();
        }
        outputs.push((cmd.args.clone(), stdout));
    }
    for f in [
        "plant.toml",
        "gains.toml",
        "run.mcap",
        "model.toml",
        "cmp.svg",
        "report.html",
        "model2.toml",
        "run.csv",
    ] {
        let len = std::fs::metadata(dir.path().join(f))
            .unwrap_or_else(|e| panic!("the story left no {f}: {e}"))
            .len();
        assert!(len > 0, "the story's {f} is empty");
    }
    let of = |sub: &str, with: &str| -> Vec<&String> {
        outputs
            .iter()
            .filter(|(a, _)| a[0] == sub && a.iter().any(|x| x == with))
            .map(|(_, o)| o)
            .collect()
    };
    let hidden = story[2]
        .args
        .iter()
        .skip_while(|a| *a != "--plant-effect")
        .nth(1)
        .and_then(|e| e.split(':').next())
        .expect("the story's run hides an effect with --plant-effect")
        .to_string();
    let first_diagnosis = of("diagnose", "model.toml");
    assert_eq!(first_diagnosis.len(), 1);
    assert!(
        first_diagnosis[0].contains(&format!("missing {hidden}")),
        "the first diagnosis does not name the hidden {hidden}:\n{}",
        first_diagnosis[0]
    );
    let added = of("compare", "--add");
    assert_eq!(added.len(), 1);
    let fits = ladder_fits(added[0]);
    assert!(
        fits.len() == 2 && fits[1] > fits[0],
        "adding {hidden} does not raise the fit: {fits:?}\n{}",
        added[0]
    );
    let second = of("diagnose", "model2.toml");
    assert_eq!(second.len(), 1);
    assert!(
        second[0].contains("Status: complete"),
        "the second diagnosis is not complete:\n{}",
        second[0]
    );
}

/// A warning line: something the user should fix.
fn is_warning(line: &str) -> bool {
    let l = line.trim_start().to_ascii_lowercase();
    l.starts_with("warning") || l.contains(" warning:")
}

/// The default text of a documented command: no warning (the README's story and the guide's
/// commands do nothing wrong), and the answer first within its line budget: diagnose at most
/// 40 lines with the verdict in the first 10, design at most 30, identify at most 25.
fn says_only_what_is_so(args: &[String], stdout: &str, stderr: &str) {
    let cmd = format!("servo {}", args.join(" "));
    for l in stdout.lines().chain(stderr.lines()) {
        assert!(!is_warning(l), "{cmd} warns: {l}\n{stdout}\n{stderr}");
    }
    if args.iter().any(|a| a == "--json" || a == "--verbose") {
        return;
    }
    let lines: Vec<&str> = stdout.lines().collect();
    let budget = match args[0].as_str() {
        "diagnose" => {
            let at = lines.iter().position(|l| l.starts_with("Verdict: "));
            assert!(
                at.is_some_and(|i| i < 10),
                "{cmd}: the verdict is not within the first 10 lines:\n{stdout}"
            );
            40
        }
        "design" => 30,
        "identify" => 25,
        _ => return,
    };
    assert!(
        lines.len() <= budget,
        "{cmd} prints {} lines (at most {budget}):\n{stdout}",
        lines.len()
    );
}

#[test]
fn the_output_checker_sees_warnings_and_budgets() {
    let _machine = servo_e2e::shared();
    assert!(is_warning(
        "WARNING: these gains do not reproduce the logged u"
    ));
    assert!(is_warning(
        "  warning: the gains were designed for another plant"
    ));
    assert!(!is_warning(
        "note: kept the previous run.mcap as run.mcap.1"
    ));
    let args = |a: &[&str]| a.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    let long = "x\n".repeat(26);
    let caught = |f: &dyn Fn()| std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).is_err();
    assert!(caught(&|| says_only_what_is_so(
        &args(&["identify"]),
        &long,
        ""
    )));
    assert!(!caught(&|| says_only_what_is_so(
        &args(&["design"]),
        &long,
        ""
    )));
    let late = format!("{}Verdict: missing\n", "x\n".repeat(10));
    assert!(caught(&|| says_only_what_is_so(
        &args(&["diagnose"]),
        &late,
        ""
    )));
    assert!(caught(&|| says_only_what_is_so(
        &args(&["run"]),
        "",
        "WARNING: x"
    )));
}

/// The first number in `s` (a table cell such as `7.165e-7 (published ...)`).
fn first_number(s: &str) -> f64 {
    s.split(|c: char| !(c.is_ascii_digit() || c == '.' || c == 'e' || c == '-' || c == '+'))
        .filter_map(|t| t.parse::<f64>().ok())
        .next()
        .unwrap_or_else(|| panic!("no number in {s:?}"))
}

/// The cells of the table row of `doc` that starts with `| {first}`.
fn row<'a>(doc: &'a str, first: &str) -> Vec<&'a str> {
    let l = doc
        .lines()
        .find(|l| l.starts_with(&format!("| {first}")))
        .unwrap_or_else(|| panic!("the lab-data chapter has no row {first:?}"));
    l.trim_matches('|').split('|').map(str::trim).collect()
}

/// `a` equals `documented` at the precision it is printed with (its last digit), 2 % when the
/// documentation rounds coarser than that.
fn as_documented(a: f64, documented: f64, digits: usize, what: &str) {
    let tol = documented.abs() * 0.5 * 10f64.powi(1 - digits as i32);
    assert!(
        (a - documented).abs() <= tol * 1.0001,
        "{what}: servo gives {a}, the lab-data chapter documents {documented}"
    );
}

/// The lab-data chapter's commands run as written (its ```sh blocks, in order, with `servo` on
/// the path and `../shared/realdata` where it is) and give the numbers it documents: the
/// identified friction and inertia of padova2021-jacopisky, the fit of the frictionless nominal
/// model on the real Bode-PID steps and after `--add coulomb`, and the diagnosis' error ladder.
#[test]
fn the_lab_data_chapter_reproduces_its_numbers() {
    let _machine = servo_e2e::shared();
    let Some(real) = servo_e2e::realdata_dir() else {
        eprintln!("skipped: no ../shared/realdata (the lab data are not part of the repository)");
        return;
    };
    let docs = docs();
    let chapter = docs
        .iter()
        .find(|d| d.path.ends_with("lab-data.md"))
        .expect("lab-data.md");
    let dir = tempfile::tempdir().unwrap();
    let bin = dir.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    std::os::unix::fs::symlink(servo_bin(), bin.join("servo")).unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let mut outputs = String::new();
    for b in blocks(&chapter.text)
        .into_iter()
        .filter(|b| is_checked_sh(&b.info))
    {
        let script = b
            .lines
            .join("\n")
            .replace("../shared/realdata", &real.display().to_string());
        let out = Command::new("bash")
            .args(["-eu", "-c", &script])
            .env("PATH", &path)
            .current_dir(dir.path())
            .output()
            .expect("spawn bash");
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(
            out.status.success(),
            "lab-data.md line {}: the block failed:\n{script}\n{stdout}\n{}",
            b.line,
            String::from_utf8_lossy(&out.stderr)
        );
        outputs.push_str(&stdout);
    }
    let text = &chapter.text;
    // identify: the jacopisky row (B_eq, tau_sf, J_eq) from the model it wrote
    let model: toml::Table =
        toml::from_str(&std::fs::read_to_string(dir.path().join("jacopisky.toml")).unwrap())
            .unwrap();
    let cells = row(text, "padova2021-jacopisky");
    for (cell, key) in cells[1..4].iter().zip(["b_eq", "tau_sf", "j_eq"]) {
        let doc = first_number(cell);
        let got = model["params"][key].as_float().unwrap();
        let mantissa = cell.split_whitespace().next().unwrap();
        let digits = mantissa
            .split('e')
            .next()
            .unwrap()
            .replace(['.', '-'], "")
            .len();
        as_documented(got, doc, digits, &format!("identify {key}"));
    }
    // compare: the frictionless nominal model, then `--add coulomb`
    let ladders: Vec<Vec<f64>> = outputs
        .match_indices("error ladder")
        .map(|(i, _)| ladder_fits(&outputs[i..]))
        .collect();
    let nominal = first_number(row(text, "nominal datasheet (no friction)")[1]);
    let added = first_number(row(text, "`--add coulomb`")[1]);
    assert!(
        ladders.iter().any(|f| f.len() == 2
            && (f[0] - nominal).abs() < 0.006
            && (f[1] - added).abs() < 0.006),
        "compare: the chapter documents {nominal} % -> {added} %, servo gives the ladders {ladders:?}"
    );
}

/// The anchor mdBook (and GitHub) gives a heading.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter_map(|c| {
            if c.is_alphanumeric() || c == '_' || c == '-' {
                Some(c)
            } else if c.is_whitespace() {
                Some('-')
            } else {
                None
            }
        })
        .collect()
}

/// The anchors of a document's headings (outside code blocks).
fn anchors(text: &str) -> BTreeSet<String> {
    prose_lines(text)
        .filter_map(|l| {
            let t = l.trim_start_matches('#');
            (t.len() < l.len() && t.starts_with(' ')).then(|| slug(&t.replace('`', "")))
        })
        .collect()
}

/// The lines of `text` outside fenced code blocks.
fn prose_lines(text: &str) -> impl Iterator<Item = &str> {
    let mut fenced = false;
    text.lines().filter(move |l| {
        let t = l.trim_start();
        if t.starts_with("```") || t.starts_with("~~~") {
            fenced = !fenced;
            return false;
        }
        !fenced
    })
}

/// The link targets `[text](target)` of `text` outside code.
fn links(text: &str) -> Vec<String> {
    let mut v = Vec::new();
    for l in prose_lines(text) {
        // drop inline code spans
        let mut prose = String::new();
        for (i, part) in l.split('`').enumerate() {
            if i % 2 == 0 {
                prose.push_str(part);
            }
        }
        let mut rest = prose.as_str();
        while let Some(i) = rest.find("](") {
            let after = &rest[i + 2..];
            let end = after.find(')').unwrap_or(after.len());
            v.push(after[..end].trim().to_string());
            rest = &after[end.min(after.len())..];
        }
    }
    v
}

/// Every relative link of the README and the book names a file that exists (in the book: a
/// chapter of the book), and every `#anchor` a heading of its target. SUMMARY.md lists every
/// chapter, and every chapter it lists exists (draft entries `[Name]()` aside).
#[test]
fn every_link_resolves() {
    let _machine = servo_e2e::shared();
    let docs = docs();
    let src = guide_src();
    let chapters: HashMap<PathBuf, &Doc> = docs.iter().map(|d| (d.path.clone(), d)).collect();
    let mut errors = Vec::new();
    let mut n = 0;
    for d in &docs {
        let in_book = d.path.starts_with(&src);
        for target in links(&d.text) {
            if target.is_empty() && d.path.ends_with("SUMMARY.md") {
                continue; // a draft chapter
            }
            if target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            n += 1;
            let (file, anchor) = match target.split_once('#') {
                Some((f, a)) => (f, Some(a)),
                None => (target.as_str(), None),
            };
            let resolved = if file.is_empty() {
                d.path.clone()
            } else {
                d.path.parent().unwrap().join(file)
            };
            let resolved = std::fs::canonicalize(&resolved).unwrap_or(resolved);
            if !resolved.exists() {
                errors.push(format!("{}: link {target} names no file", d.path.display()));
                continue;
            }
            // mdBook copies the other files under src/ (images) into the book as they are
            let book_src = std::fs::canonicalize(
                std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/guide/src"),
            )
            .unwrap();
            let copied =
                resolved.starts_with(&book_src) && resolved.extension().is_some_and(|e| e != "md");
            if in_book && !chapters.contains_key(&resolved) && !copied {
                errors.push(format!(
                    "{}: link {target} leaves the book (mdBook does not copy it): name the path in code instead",
                    d.path.display()
                ));
                continue;
            }
            if let Some(a) = anchor {
                let text = match chapters.get(&resolved) {
                    Some(c) => c.text.clone(),
                    None => read(&resolved),
                };
                if !anchors(&text).contains(a) {
                    errors.push(format!(
                        "{}: link {target}: no heading with anchor #{a} in {}",
                        d.path.display(),
                        resolved.display()
                    ));
                }
            }
        }
    }
    // SUMMARY.md and the chapters on disk agree.
    let summary = read(&src.join("SUMMARY.md"));
    let listed: BTreeSet<String> = links(&summary)
        .into_iter()
        .filter(|t| !t.is_empty())
        .collect();
    for d in &docs {
        if d.path.starts_with(&src) && !d.path.ends_with("SUMMARY.md") {
            let name = d.path.file_name().unwrap().to_string_lossy().into_owned();
            if !listed.contains(&name) {
                errors.push(format!(
                    "{}: a chapter SUMMARY.md does not list",
                    d.path.display()
                ));
            }
        }
    }
    eprintln!("{n} links checked");
    assert!(n >= 40, "only {n} links found");
    assert!(errors.is_empty(), "{}", errors.join("\n"));
}

/// The link checker catches a missing file, a missing anchor and a link out of the book.
#[test]
fn the_link_checker_sees_links_and_anchors() {
    let _machine = servo_e2e::shared();
    let text = "# Top: the `x` part\n\nSee [a](b.md#c-d) and `[not](code.md)`.\n```sh\n[no](x.md)\n```\n## C, d\n";
    assert_eq!(links(text), ["b.md#c-d"]);
    assert!(
        anchors(text).contains("top-the-x-part"),
        "{:?}",
        anchors(text)
    );
    assert!(anchors(text).contains("c-d"));
    assert_eq!(
        slug("Benchmark: does the QEMU board sustain 1 kHz?"),
        "benchmark-does-the-qemu-board-sustain-1-khz"
    );
}
