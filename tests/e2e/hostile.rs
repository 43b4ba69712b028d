//! Hostile names in reports and plots: a file, folder or column name, model metadata or a chart
//! label with quotes, angle brackets, ampersands, `javascript:` URLs, control and bidirectional
//! characters must come out of every HTML report and SVG servo writes as text: no event-handler
//! attribute, no script element, no broken markup; and a browser loading a report runs nothing.
//!
//! * a property test: random strings into every text of the chart renderer, the markup builder
//!   and the trend report (in process);
//! * the CLI: every command that writes HTML or SVG on logs, folders and columns with hostile
//!   names, each output checked by `servo_io::markup::problems`, each SVG (standalone or inline)
//!   parsed as XML, each report loaded in headless Chromium.

use servo_cli::fuzz::Rng;
use servo_core::sim::excitation::{simulate_open_loop, RandomSteps, ZeroRamps};
use servo_core::sim::SensorConfig;
use servo_core::{Plant, PlantParams};
use servo_e2e::servo;
use servo_io::markup;
use servo_io::markup::{problems, Attr, Markup, Url};
use std::path::{Path, PathBuf};

/// What a hostile name's handlers would write, were they run.
const MARKER: &str = "PWNED";

/// A file name (no `/`, no NUL) that breaks out of a double-quoted attribute, opens tags with
/// handlers, carries a `javascript:` URL, entities, control and bidirectional characters.
fn hostile_name(stem_suffix: &str) -> String {
    format!(
        "x\" tabindex=\"1\" autofocus onfocus=\"document.title='{MARKER}';console.log('{MARKER}')\" y=\"\
         <img src=x onerror=\"document.title='{MARKER}'\"><svg onload=console.log('{MARKER}')>\
         &amp;&lt;javascript:alert('{MARKER}') '\u{1}\u{1b}[31m\u{7f}\u{202e}é漢{stem_suffix}"
    )
}

/// Pieces random strings are made of.
const PIECES: [&str; 34] = [
    "\"",
    "'",
    "<",
    ">",
    "&",
    "&amp;",
    "&#",
    "javascript:",
    "JavaScript:alert(1)",
    " onload=",
    "onerror=alert(1)",
    "<script>",
    "</script>",
    "<img src=x onerror=alert(1)>",
    "</svg>",
    "<!--",
    "-->",
    "]]>",
    "<![CDATA[",
    "{}",
    "=",
    "/",
    "\\",
    "`",
    " ",
    "\n",
    "\t",
    "\r",
    "é",
    "漢字",
    "😀",
    "\u{202e}",
    "\u{FFFE}",
    "x",
];

fn random_string(rng: &mut Rng) -> String {
    let n = rng.next_u64() % 12;
    let mut s = String::new();
    for _ in 0..n {
        match rng.next_u64() % 4 {
            0 => {
                // a control character (C0, DEL or C1)
                let c = [0u32, 1, 8, 0x0b, 0x0c, 0x1b, 0x1f, 0x7f, 0x85, 0x9f]
                    [(rng.next_u64() % 10) as usize];
                s.push(char::from_u32(c).unwrap());
            }
            _ => s.push_str(PIECES[(rng.next_u64() % PIECES.len() as u64) as usize]),
        }
    }
    s
}

/// Every problem of an HTML report or SVG document: the tokenizer's, and each SVG element
/// (inline or the document) parsed as XML.
fn all_problems(doc: &str) -> Vec<String> {
    let mut out = problems(doc);
    // each innermost <svg> element (a report's chart, a stacked chart) parsed as XML on its own;
    // the elements holding others are parsed whole below when they are the document
    for (k, (at, _)) in doc.match_indices("<svg").enumerate() {
        let Some(end) = doc[at..].find("</svg>") else {
            out.push(format!("svg {k} does not end"));
            continue;
        };
        let el = &doc[at..at + end + "</svg>".len()];
        if el[4..].contains("<svg") {
            continue;
        }
        if let Err(e) = roxmltree::Document::parse(el) {
            out.push(format!("svg {k} is not XML: {e}"));
        }
    }
    if doc.trim_start().starts_with("<?xml") || doc.trim_start().starts_with("<svg") {
        if let Err(e) = roxmltree::Document::parse(doc) {
            out.push(format!("the SVG document is not XML: {e}"));
        }
    }
    out
}

#[test]
fn random_strings_in_every_chart_text_leave_well_formed_svg_and_their_text() {
    let _machine = servo_e2e::shared();
    let mut rng = Rng::new(0x4057_11e5);
    let x: Vec<f64> = (0..50).map(|k| k as f64 * 0.01).collect();
    let y: Vec<f64> = x.iter().map(|t| (3.0 * t).sin()).collect();
    for case in 0..300 {
        let texts: Vec<String> = (0..5).map(|_| random_string(&mut rng)).collect();
        let chart = servo_cli::plot::Chart {
            title: &texts[0],
            x_label: &texts[1],
            y_label: &texts[2],
            log_x: case % 3 == 0,
            scatter: case % 5 == 0,
            ..Default::default()
        };
        let series = [
            servo_cli::plot::Series {
                label: &texts[3],
                x: &x[1..],
                y: &y[1..],
            },
            servo_cli::plot::Series {
                label: &texts[4],
                x: &x[1..],
                y: &x[1..],
            },
        ];
        let svg = servo_cli::plot::line_chart_svg(&chart, &series).unwrap();
        let p = all_problems(&svg);
        assert!(p.is_empty(), "case {case} {texts:?}: {p:?}");
        // and the texts are there, as text (only the characters XML forbids replaced)
        let doc = roxmltree::Document::parse(&svg).unwrap();
        let shown: Vec<String> = doc
            .descendants()
            .filter(|n| n.has_tag_name("text"))
            .map(|n| n.text().unwrap_or("").trim().to_string())
            .collect();
        for t in [&texts[0], &texts[3], &texts[4]] {
            let want = markup::svg_text(t).trim().to_string();
            // plotters draws a label with a line break as one text; an empty label not at all
            if want.is_empty() || want.contains(['\n', '\r']) {
                continue;
            }
            assert!(
                shown.iter().any(|s| s == &want),
                "case {case}: {want:?} not among the chart's texts {shown:?}"
            );
        }
        // a stack of charts (compare, frf) stays one well-formed document
        let stacked = servo_cli::cmd::compare::stack_svg(&[svg.clone(), svg]);
        let p = all_problems(&stacked);
        assert!(p.is_empty(), "case {case} stacked: {p:?}");
    }
}

#[test]
fn random_strings_in_every_markup_context_round_trip_as_values() {
    let _machine = servo_e2e::shared();
    let mut rng = Rng::new(0x0e5c_a9e5);
    for case in 0..2000 {
        let (a, b, c, d) = (
            random_string(&mut rng),
            random_string(&mut rng),
            random_string(&mut rng),
            random_string(&mut rng),
        );
        let mut h = Markup::new();
        markup!(
            h,
            "<div data-a=\"{}\" title='{}'><a href=\"{}\">{}</a></div>",
            a,
            Attr(&b),
            Url(&c),
            d
        );
        let p = problems(h.as_str());
        assert!(p.is_empty(), "case {case}: {p:?} in {}", h.as_str());
        let doc = roxmltree::Document::parse(h.as_str()).unwrap();
        let div = doc.root_element();
        let clean =
            |s: &str| markup::svg_text(s).replace(['\u{202e}', '\u{85}', '\u{9f}'], "\u{FFFD}");
        // an attribute value comes back whole (XML normalises the white space of a plain one)
        assert_eq!(
            div.attribute("title"),
            Some(clean(&b).as_str()),
            "case {case}"
        );
        // (line ends first made \n, then each white-space character a space)
        let plain = clean(&a)
            .replace("\r\n", "\n")
            .replace(['\t', '\n', '\r'], " ");
        assert_eq!(div.attribute("data-a"), Some(plain.as_str()), "case {case}");
        let link = div.first_element_child().unwrap();
        let href = link.attribute("href").unwrap();
        assert!(href == "#" || markup::safe_url(href).is_some(), "{href:?}");
        assert_eq!(
            link.text()
                .unwrap_or("")
                .replace("\r\n", "\n")
                .replace('\r', "\n"),
            clean(&d).replace("\r\n", "\n").replace('\r', "\n"),
            "case {case}"
        );
    }
}

// ---- the CLI -------------------------------------------------------------------------------

/// A made-up gearmotor (not Table 2's).
fn motor() -> PlantParams {
    PlantParams {
        k_t: 9.0e-3,
        k_e: 9.0e-3,
        r_a: 3.1,
        n: 16.0,
        j_eq: Some(8.0e-7),
        b_eq: Some(1.2e-6),
        tau_sf: Some(0.011),
        ..PlantParams::TABLE2
    }
}

/// 6 s of random voltage steps with ramps through zero on [`motor`], as servo CSV.
fn write_open_loop_log(path: &Path, seed: u64) {
    let plant = Plant::from_params(motor()).unwrap();
    let u = RandomSteps {
        ramps: Some(ZeroRamps {
            probability: 0.3,
            min_v: 3.0,
            span_v: 3.0,
        }),
        ..RandomSteps::new(seed)
    }
    .voltages(6000, 1e-3);
    let rec = simulate_open_loop(
        &plant,
        SensorConfig {
            seed,
            ..SensorConfig::default()
        },
        1e-3,
        &u,
        "hostile",
    )
    .unwrap();
    servo_cli::io::write_csv(path, &rec).unwrap();
}

/// The model file of [`motor`], with hostile metadata in its provenance table.
fn write_model(path: &Path) {
    let mut m = servo_cli::model_file::ModelFile {
        params: motor(),
        ..Default::default()
    };
    let mut prov = toml::Table::new();
    prov.insert("source".into(), toml::Value::String(hostile_name("")));
    prov.insert(
        "note".into(),
        toml::Value::String("<script>alert(1)</script> javascript:alert(1) & \"q\"".into()),
    );
    m.provenance = Some(prov);
    m.save(path).unwrap();
}

fn run_ok(args: &[&str]) -> String {
    let (ok, out, err) = servo(args);
    assert!(ok, "servo {args:?} failed:\n{err}\n{out}");
    out
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Whether `SERVO_REQUIRE_CHROMIUM=1` (CI) makes a missing Chromium a failure.
fn chromium() -> Option<PathBuf> {
    for c in ["chromium", "chromium-browser", "google-chrome"] {
        if let Ok(out) = std::process::Command::new("which").arg(c).output() {
            let p = String::from_utf8_lossy(&out.stdout).trim().to_string();
            if out.status.success() && !p.is_empty() {
                return Some(PathBuf::from(p));
            }
        }
    }
    assert!(
        std::env::var("SERVO_REQUIRE_CHROMIUM").as_deref() != Ok("1"),
        "SERVO_REQUIRE_CHROMIUM=1 but no chromium on PATH (apt-get install chromium)"
    );
    eprintln!("SKIP: no chromium on PATH: the reports are not loaded in a browser");
    None
}

/// Loads `html` in headless Chromium (its handlers given time to run) and checks that nothing
/// ran: the title is `title`, no console message, no handler attribute in the DOM.
fn no_script_runs(html: &Path, title: &str, profile: &Path) {
    let Some(bin) = chromium() else { return };
    // a copy under a plain name: the file URL of a hostile name is not what is tested
    let plain = profile.with_extension("html");
    std::fs::copy(html, &plain).unwrap();
    let url = format!("file://{}", plain.canonicalize().unwrap().display());
    let out = std::process::Command::new(&bin)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-dev-shm-usage",
            "--enable-logging=stderr",
            "--v=0",
            "--virtual-time-budget=3000",
            &format!("--user-data-dir={}", profile.display()),
            "--dump-dom",
            &url,
        ])
        .output()
        .unwrap();
    let dom = String::from_utf8_lossy(&out.stdout);
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "chromium failed on {}: {log}",
        html.display()
    );
    let shown_title = dom
        .split_once("<title>")
        .and_then(|(_, r)| r.split_once("</title>"))
        .map(|(t, _)| t.to_string());
    assert_eq!(shown_title.as_deref(), Some(title), "{}", html.display());
    for l in log.lines().filter(|l| l.contains("CONSOLE")) {
        assert!(
            !l.contains(MARKER),
            "a script ran in {}: {l}",
            html.display()
        );
    }
    // the DOM the browser built holds the hostile name as text only
    let handlers: Vec<String> = problems(&dom)
        .into_iter()
        .filter(|p| p.contains("event handler") || p.contains("<script>"))
        .collect();
    assert!(handlers.is_empty(), "{}: {handlers:?}", html.display());
    assert!(
        dom.contains("autofocus onfocus"),
        "the name is not shown as text"
    );
}

fn check_output(path: &Path, what: &str) -> String {
    let doc = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{what}: no output {}: {e}", path.display()));
    let p = all_problems(&doc);
    assert!(p.is_empty(), "{what} ({}): {p:?}", path.display());
    doc
}

#[test]
fn hostile_names_through_every_command_that_writes_html_or_svg() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let model = dir.join(hostile_name(".toml"));
    write_model(&model);
    // an open-loop log with a hostile name
    let log = dir.join(hostile_name(".csv"));
    write_open_loop_log(&log, 7);
    // the same log under hostile column names, read through a column map
    let cols = dir.join(hostile_name("_columns.csv"));
    let text = std::fs::read_to_string(&log).unwrap();
    let (header, body) = text.split_once('\n').unwrap();
    let rename = |c: &str| format!("\"{c} <svg onload=alert(1)>\"\"&amp;'\u{1b}\"");
    let names: Vec<String> = header.split(',').map(|c| rename(c.trim())).collect();
    std::fs::write(&cols, format!("{}\n{body}", names.join(","))).unwrap();
    let unquoted = |c: &str| format!("{c} <svg onload=alert(1)>\"&amp;'\u{1b}");
    let map: Vec<String> = header
        .split(',')
        .map(str::trim)
        .filter_map(|c| {
            let (sig, unit) = c.rsplit_once('_')?;
            let sig = if sig == "omega_l_rad" {
                return None;
            } else {
                sig
            };
            let unit = match unit {
                "s" | "V" | "rad" | "A" => unit,
                _ => return None,
            };
            Some(format!("{sig}={}:{unit}", unquoted(c)))
        })
        .collect();
    let map = map.join(",");

    // servo diagnose --report (file name, column names, the model's metadata)
    let report = dir.join(hostile_name("_report.html"));
    run_ok(&[
        "diagnose",
        s(&cols),
        "--columns",
        &map,
        "--model",
        s(&model),
        "--report",
        s(&report),
    ]);
    let html = check_output(&report, "diagnose --report");
    assert!(
        html.contains(markup::CSP_META),
        "no CSP in the diagnose report"
    );
    assert!(
        html.contains("data-log=\"x&quot; tabindex=&quot;1&quot;"),
        "the log's name is not in its panel, escaped"
    );
    no_script_runs(
        &report,
        "servo diagnose report",
        &dir.join("chrome-diagnose"),
    );

    // servo trend --report: a hostile actuator folder, hostile log names with dates in them
    let fleet = dir.join("fleet");
    let arm = fleet.join(hostile_name("-arm"));
    std::fs::create_dir_all(&arm).unwrap();
    for (k, date) in ["20260105", "20260112", "20260119", "20260126"]
        .iter()
        .enumerate()
    {
        write_open_loop_log(
            &arm.join(format!("{}{date}.csv", hostile_name("_"))),
            20 + k as u64,
        );
    }
    let trend = dir.join(hostile_name("_trend.html"));
    run_ok(&[
        "trend",
        s(&fleet),
        "--model",
        s(&model),
        "--time-from",
        "name:%Y%m%d",
        "--cache",
        s(&dir.join("cache")),
        "--report",
        s(&trend),
    ]);
    let html = check_output(&trend, "trend --report");
    assert!(
        html.contains(markup::CSP_META),
        "no CSP in the trend report"
    );
    assert!(
        html.contains("autofocus onfocus=&quot;"),
        "the actuator is not named, escaped"
    );
    no_script_runs(&trend, "servo trend", &dir.join("chrome-trend"));

    // servo compare --plot (the log's name is in the chart titles)
    let plot = dir.join(hostile_name("_compare.svg"));
    run_ok(&["compare", s(&log), "--model", s(&model), "--plot", s(&plot)]);
    let svg = check_output(&plot, "compare --plot");
    assert!(
        svg.contains("autofocus onfocus=&quot;"),
        "the log is not named in the titles"
    );

    // servo identify --plot: the friction staircase and inertia ramps run into a hostile folder,
    // then identified from copies with hostile names
    let runs = dir.join(hostile_name("-runs"));
    run_ok(&[
        "identify",
        "--ramp",
        "--plant",
        s(&model),
        "--log-dir",
        s(&runs),
        "-o",
        s(&dir.join(hostile_name("_ramp.toml"))),
    ]);
    let (friction, inertia) = (
        dir.join(hostile_name("_f.mcap")),
        dir.join(hostile_name("_i.mcap")),
    );
    std::fs::copy(runs.join("identify_friction.mcap"), &friction).unwrap();
    std::fs::copy(runs.join("identify_inertia.mcap"), &inertia).unwrap();
    let plot = dir.join(hostile_name("_identify.svg"));
    run_ok(&[
        "identify",
        s(&friction),
        s(&inertia),
        "--params",
        s(&model),
        "-o",
        s(&dir.join(hostile_name("_identified.toml"))),
        "--plot",
        s(&plot),
    ]);
    check_output(&plot, "identify --plot");

    // servo design --plot
    let plot = dir.join(hostile_name("_bode.svg"));
    let gains = dir.join(hostile_name("_gains.toml"));
    let step = dir.join(hostile_name("_step.svg"));
    run_ok(&[
        "design",
        "--params",
        s(&model),
        "--wc",
        "30",
        "--pm",
        "60",
        "-o",
        s(&gains),
        "--plot",
        s(&plot),
        "--step-plot",
        s(&step),
    ]);
    check_output(&plot, "design --plot");
    check_output(&step, "design --step-plot");

    // servo run --plot (and its _u.svg) with a multisine logged under a hostile name, then
    // servo frf --plot on it
    let run_log = dir.join(hostile_name("_run.mcap"));
    let plot = dir.join(hostile_name("_run.svg"));
    let multisine = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("experiments/multisine.toml");
    run_ok(&[
        "run",
        "--plant",
        s(&model),
        "--gains",
        s(&gains),
        "--experiment",
        s(&multisine),
        "--duration",
        "20",
        "--log",
        s(&run_log),
        "--plot",
        s(&plot),
    ]);
    check_output(&plot, "run --plot");
    check_output(&dir.join(hostile_name("_run_u.svg")), "run --plot (u)");
    let plot = dir.join(hostile_name("_frf.svg"));
    run_ok(&[
        "frf",
        s(&run_log),
        "--gains",
        s(&gains),
        "--segment-s",
        "5",
        "--plot",
        s(&plot),
    ]);
    check_output(&plot, "frf --plot");
}

#[test]
fn random_strings_in_every_field_of_the_trend_report() {
    let _machine = servo_e2e::shared();
    let tmp = tempfile::tempdir().unwrap();
    let arm = tmp.path().join("fleet").join("arm");
    std::fs::create_dir_all(&arm).unwrap();
    for (k, date) in ["20260105", "20260112", "20260119"].iter().enumerate() {
        write_open_loop_log(&arm.join(format!("{date}.csv")), 40 + k as u64);
    }
    let model = tmp.path().join("m.toml");
    write_model(&model);
    let cfg = servo_cli::trend::TrendConfig {
        inputs: vec![tmp.path().join("fleet")],
        model: model.clone(),
        columns: None,
        group_by: servo_cli::trend::GroupBy::Dir,
        time_from: servo_cli::trend::when::TimeFrom::Name("%Y%m%d".into()),
        limits: Default::default(),
        cache_dir: Some(tmp.path().join("cache")),
        workers: 1,
        options: Default::default(),
        progress: false,
    };
    let mut r = servo_cli::trend::run(&cfg).unwrap();
    assert!(!r.actuators.is_empty() && !r.actuators[0].params.is_empty());
    let mut rng = Rng::new(0x7e4d);
    for case in 0..60 {
        let mut g = || random_string(&mut rng);
        r.model = PathBuf::from(g());
        r.failed = vec![servo_cli::trend::Failed {
            path: PathBuf::from(g()),
            error: g(),
        }];
        for a in &mut r.actuators {
            a.name = g();
            a.grouped_by = g();
            for l in &mut a.logs {
                l.path = PathBuf::from(g());
                l.time_from = g();
            }
            for p in &mut a.params {
                p.parameter = g();
                p.unit = g();
            }
        }
        let html = servo_cli::trend::report::html(&r).unwrap();
        let p = all_problems(&html);
        assert!(p.is_empty(), "case {case}: {p:?}");
        assert!(html.contains(markup::CSP_META));
    }
}
