//! What a student sees (#30): the numbers, sentences, plots and reports of the demo and of the
//! workflow commands, checked the way a student reads them, and by rendering every SVG to PNG
//! (resvg) and the HTML report in headless Chromium.
//!
//! The PNGs are left in `target/<profile>/../tmp/student-png/` for a look by eye.

use servo_e2e::servo;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Largest size of any SVG servo writes [bytes].
const SVG_MAX_BYTES: u64 = 300 * 1024;

fn tmp(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn png_dir() -> PathBuf {
    static D: OnceLock<PathBuf> = OnceLock::new();
    D.get_or_init(|| tmp("student-png")).clone()
}

/// `servo demo`, once for the tests of this file: (its folder, its stdout).
fn demo() -> &'static (PathBuf, String) {
    static D: OnceLock<(PathBuf, String)> = OnceLock::new();
    D.get_or_init(|| {
        let out = tmp("student-demo").join("demo");
        let (ok, stdout, stderr) = servo(&["demo", "--out", out.to_str().unwrap(), "--verbose"]);
        assert!(ok, "servo demo failed: {stderr}\n{stdout}");
        (out, stdout)
    })
}

#[test]
fn demo_says_each_file_it_wrote_once() {
    let _machine = servo_e2e::shared();
    let (_, stdout) = demo();
    let wrote: Vec<&str> = stdout
        .lines()
        .filter_map(|l| l.trim_start().strip_prefix("wrote "))
        .collect();
    let ident: Vec<&&str> = wrote
        .iter()
        .filter(|w| w.ends_with("model_identified.toml"))
        .collect();
    assert_eq!(
        ident.len(),
        1,
        "model_identified.toml announced {ident:?}:\n{stdout}"
    );
    for w in &wrote {
        assert_eq!(
            wrote.iter().filter(|x| x == &w).count(),
            1,
            "`wrote {w}` printed more than once:\n{stdout}"
        );
    }
    // the run's summary: step metrics for the demo's steps
    assert!(stdout.contains("overshoot (max)"), "{stdout}");
}

#[test]
fn demo_says_plant_controller_clamps_and_changes_in_words() {
    let _machine = servo_e2e::shared();
    let (_, stdout) = demo();
    // the run stage says which plant and controller it simulated, in one line
    let run = stdout
        .split("== [2/")
        .nth(1)
        .and_then(|s| s.split("== [3/").next())
        .unwrap_or_else(|| panic!("no run stage:\n{stdout}"));
    let line = run
        .lines()
        .find(|l| l.starts_with("simulated plant:"))
        .unwrap_or_else(|| panic!("the run stage does not say its plant:\n{run}"));
    assert!(
        line.contains("controller: PID") && line.contains("Tustin"),
        "{line}"
    );
    assert!(!stdout.contains("()"), "an empty source in:\n{stdout}");
    // the identified B_eq came out negative (zero within its interval) here: said, not
    // silently written as 0, and not as an error
    let note = stdout
        .lines()
        .find(|l| l.contains("B_eq = -") && l.contains("zero within its 95 % interval"))
        .unwrap_or_else(|| panic!("a negative B_eq written as 0 without a word:\n{stdout}"));
    assert!(note.contains("written as 0"), "{note}");
    // the experiments the open-loop run does not hold are not failures
    assert!(
        stdout.contains("not part of this run: the friction staircase"),
        "{stdout}"
    );
    assert!(!stdout.contains("not identified"), "{stdout}");
    // no double negatives: a drop is "lowers", a rise "raises", never "by -"
    for l in stdout.lines() {
        assert!(
            !(l.contains("by -") || l.contains("lowers") && l.contains("by -")),
            "a double negative: {l}"
        );
    }
    assert!(
        stdout.contains("lowers the held-out simulation error by"),
        "{stdout}"
    );
    // the ranking's residual figure is named for what it is (RMS), as the HTML report names it
    assert!(stdout.contains("eq. RMS drop"), "{stdout}");
}

/// The text boxes of an SVG's texts (rendered with the system's fonts), in pixels.
fn text_boxes(tree: &resvg::usvg::Tree) -> Vec<(String, resvg::tiny_skia::Rect)> {
    fn walk(g: &resvg::usvg::Group, out: &mut Vec<(String, resvg::tiny_skia::Rect)>) {
        for n in g.children() {
            match n {
                resvg::usvg::Node::Group(g) => walk(g, out),
                resvg::usvg::Node::Text(t) => {
                    let s: String = t.chunks().iter().map(|c| c.text()).collect();
                    out.push((s, t.abs_bounding_box()));
                }
                _ => {}
            }
        }
    }
    let mut out = Vec::new();
    walk(tree.root(), &mut out);
    out
}

fn fontdb() -> std::sync::Arc<resvg::usvg::fontdb::Database> {
    static DB: OnceLock<std::sync::Arc<resvg::usvg::fontdb::Database>> = OnceLock::new();
    DB.get_or_init(|| {
        let mut db = resvg::usvg::fontdb::Database::new();
        db.load_system_fonts();
        // plotters writes `font-family="sans-serif"`: map it to a sans family this machine has
        let families: Vec<String> = db
            .faces()
            .flat_map(|f| f.families.iter().map(|(n, _)| n.clone()))
            .collect();
        if let Some(sans) = ["DejaVu Sans", "Liberation Sans", "Noto Sans", "Arial"]
            .iter()
            .find(|f| families.iter().any(|n| n == *f))
            .map(|f| f.to_string())
            .or_else(|| families.iter().find(|n| n.contains("Sans")).cloned())
        {
            db.set_sans_serif_family(sans);
        }
        std::sync::Arc::new(db)
    })
    .clone()
}

/// Renders `svg` to `png`; returns the problems a reader would see: texts overlapping, an axis
/// without a unit, a size over the bound.
fn render_and_check(svg_path: &Path, png: &Path) -> Vec<String> {
    let mut problems = Vec::new();
    let len = std::fs::metadata(svg_path).unwrap().len();
    if len > SVG_MAX_BYTES {
        problems.push(format!(
            "{} is {} KB (> 300 KB)",
            svg_path.display(),
            len / 1024
        ));
    }
    let text = std::fs::read_to_string(svg_path).unwrap();
    let opt = resvg::usvg::Options {
        fontdb: fontdb(),
        ..Default::default()
    };
    let tree = resvg::usvg::Tree::from_str(&text, &opt)
        .unwrap_or_else(|e| panic!("{}: not a valid SVG: {e}", svg_path.display()));
    let size = tree.size().to_int_size();
    let mut pixmap = resvg::tiny_skia::Pixmap::new(size.width(), size.height()).unwrap();
    pixmap.fill(resvg::tiny_skia::Color::WHITE);
    resvg::render(
        &tree,
        resvg::tiny_skia::Transform::default(),
        &mut pixmap.as_mut(),
    );
    pixmap.save_png(png).unwrap();
    let boxes = text_boxes(&tree);
    if !fontdb().is_empty() {
        assert!(
            !boxes.is_empty(),
            "{}: no text rendered",
            svg_path.display()
        );
    }
    for (i, (a, ra)) in boxes.iter().enumerate() {
        for (b, rb) in &boxes[i + 1..] {
            // a pixel of slack: glyph boxes of neighbouring labels may touch
            let ix = ra.right().min(rb.right()) - ra.left().max(rb.left());
            let iy = ra.bottom().min(rb.bottom()) - ra.top().max(rb.top());
            if ix > 1.0 && iy > 1.0 && !a.trim().is_empty() && !b.trim().is_empty() {
                problems.push(format!(
                    "{}: texts `{a}` and `{b}` overlap ({ra:?} / {rb:?})",
                    svg_path.display()
                ));
            }
        }
    }
    // every chart (nested <svg> of a stacked figure, or the file) names a unit on both axes
    let charts =
        text.matches("<svg").count().max(1) - usize::from(text.matches("<svg").count() > 1);
    let units = boxes
        .iter()
        .filter(|(s, _)| s.contains('[') && s.contains(']'))
        .count();
    if units < 2 * charts {
        problems.push(format!(
            "{}: {units} axis labels with a unit for {charts} chart(s)",
            svg_path.display()
        ));
    }
    // no negative zero among the tick labels ("-0e-6")
    for (t, _) in &boxes {
        if t.starts_with('-') && t.parse::<f64>() == Ok(0.0) {
            problems.push(format!("{}: tick label `{t}`", svg_path.display()));
        }
    }
    // the tick labels at small scales are not all alike ("0.0, 0.0, 0.0")
    let mut labels: Vec<&str> = boxes
        .iter()
        .map(|(s, _)| s.as_str())
        .filter(|s| s.parse::<f64>().is_ok())
        .collect();
    labels.sort_unstable();
    let all = labels.len();
    labels.dedup();
    if all > 6 && labels.len() * 3 < all {
        problems.push(format!(
            "{}: tick labels repeat: {} distinct of {all}",
            svg_path.display(),
            labels.len()
        ));
    }
    problems
}

fn svgs(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "svg"))
        .collect();
    v.sort();
    v
}

#[test]
fn every_svg_of_the_demo_renders_readably_and_small() {
    let _machine = servo_e2e::shared();
    let (dir, _) = demo();
    let files = svgs(dir);
    assert!(files.len() >= 4, "the demo wrote only {files:?}");
    let mut problems = Vec::new();
    for f in &files {
        let png = png_dir().join(format!(
            "demo_{}.png",
            f.file_stem().unwrap().to_string_lossy()
        ));
        problems.extend(render_and_check(f, &png));
        println!("{} -> {}", f.display(), png.display());
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// Whether `SERVO_REQUIRE_CHROMIUM=1` (CI) makes a missing Chromium a failure.
fn chromium() -> Option<PathBuf> {
    for c in ["chromium", "chromium-browser", "google-chrome"] {
        if let Ok(out) = std::process::Command::new("which").arg(c).output() {
            if out.status.success() {
                let p = String::from_utf8_lossy(&out.stdout).trim().to_string();
                if !p.is_empty() {
                    return Some(PathBuf::from(p));
                }
            }
        }
    }
    assert!(
        std::env::var("SERVO_REQUIRE_CHROMIUM").as_deref() != Ok("1"),
        "SERVO_REQUIRE_CHROMIUM=1 but no chromium on PATH (apt-get install chromium)"
    );
    eprintln!("SKIP: no chromium on PATH: the HTML report is not rendered");
    None
}

/// Renders `html` in headless Chromium: the PNG of the page and the DOM after layout.
fn render_html(html: &Path, png: &Path) -> Option<String> {
    let bin = chromium()?;
    // Chromium loads every core while it lays the page out: not beside a real-time test.
    let url = format!("file://{}", html.canonicalize().unwrap().display());
    let profile = tmp(&format!(
        "chromium-profile-{}",
        png.file_stem().unwrap().to_string_lossy()
    ));
    let common = [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--hide-scrollbars",
    ];
    let user = format!("--user-data-dir={}", profile.display());
    let shot = format!("--screenshot={}", png.display());
    let out = std::process::Command::new(&bin)
        .args(common)
        .args([
            user.as_str(),
            shot.as_str(),
            "--window-size=1100,2400",
            &url,
        ])
        .output()
        .unwrap();
    assert!(
        png.is_file(),
        "chromium wrote no screenshot: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let dom = std::process::Command::new(&bin)
        .args(common)
        .args([user.as_str(), "--dump-dom", &url])
        .output()
        .unwrap();
    assert!(
        dom.status.success(),
        "{}",
        String::from_utf8_lossy(&dom.stderr)
    );
    let img = resvg::tiny_skia::Pixmap::load_png(png).unwrap();
    let dark = img
        .pixels()
        .iter()
        .filter(|p| (p.red() as u32 + p.green() as u32 + p.blue() as u32) < 300)
        .count();
    assert!(dark > 1000, "the screenshot {} is blank", png.display());
    Some(String::from_utf8_lossy(&dom.stdout).into_owned())
}

#[test]
fn a_three_log_diagnosis_report_shows_three_panels_of_points() {
    let _machine = servo_e2e::shared();
    let (demo_dir, _) = demo();
    let dir = tmp("student-three-logs");
    // a third log: the hidden truth driven by another step sequence
    let third = dir.join("third.csv");
    let (ok, out, err) = servo(&[
        "run",
        "--plant",
        demo_dir.join("truth_hidden.toml").to_str().unwrap(),
        "--gains",
        demo_dir.join("gains.toml").to_str().unwrap(),
        "--ref",
        "square:amp=40deg,period=1.2",
        "--duration",
        "4",
        "--csv",
        third.to_str().unwrap(),
    ]);
    assert!(ok, "{err}\n{out}");
    let report = dir.join("report.html");
    let logs = [
        demo_dir.join("run.mcap"),
        demo_dir.join("identify_openloop.csv"),
        third.clone(),
    ];
    let mut args: Vec<String> = vec!["diagnose".into()];
    args.extend(logs.iter().map(|p| p.display().to_string()));
    args.extend([
        "--model".into(),
        demo_dir.join("model_identified.toml").display().to_string(),
        "--report".into(),
        report.display().to_string(),
    ]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let (ok, out, err) = servo(&args);
    assert!(ok, "{err}\n{out}");
    let html = std::fs::read_to_string(&report).unwrap();
    assert_eq!(
        html.matches("class=\"panel\"").count(),
        3,
        "one panel per log expected"
    );
    for l in &logs {
        let name = l.file_name().unwrap().to_string_lossy();
        assert!(
            html.contains(&format!("data-log=\"{name}\"")),
            "no panel for {name}"
        );
    }
    // the ranking's columns named as the text names them
    assert!(
        html.contains("<h2>Ranking</h2>") && html.contains("<th>held-out residual RMS drop</th>"),
        "ranking header"
    );
    // the compensation section (#29): the found effect's compensation, predicted on the model,
    // cuts the tracking error of the linear feedforward
    let (_, rows) = crate::util::compensation_section(&html, "student");
    assert_eq!(rows.len(), 3, "{rows:?}");
    assert_eq!(rows[0].0, "no compensation", "{rows:?}");
    assert!(
        rows[2].0.starts_with("+ ") && rows[2].1 < 0.3 * rows[1].1,
        "{rows:?}"
    );
    // the residual against speed is a scatter (points), the residual over time a line
    assert!(
        html.contains("<circle"),
        "no points in the residual-against-speed plot"
    );
    assert!(
        html.len() < 3 * 300 * 1024,
        "report of {} KB",
        html.len() / 1024
    );
    // no overlapping labels and units on every axis in each of the report's charts
    let mut problems = Vec::new();
    for (k, svg) in html.split("<svg").skip(1).enumerate() {
        let end = svg.find("</svg>").unwrap();
        let f = dir.join(format!("report_chart_{k}.svg"));
        std::fs::write(&f, format!("<svg{}</svg>", &svg[..end])).unwrap();
        problems.extend(render_and_check(
            &f,
            &png_dir().join(format!("report_chart_{k}.png")),
        ));
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    // and in a browser: three panels laid out
    if let Some(dom) = render_html(&report, &png_dir().join("diagnose_report.png")) {
        assert_eq!(dom.matches("class=\"panel\"").count(), 3, "{dom}");
    }
}

fn repo(p: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join(p)
        .display()
        .to_string()
}

/// The phase-margin interval `[lo, hi]` printed after `phase margin`, if any.
fn printed_interval(out: &str, what: &str) -> Option<(f64, f64)> {
    let at = out.find(&format!("{what} "))?;
    let rest = &out[at..];
    let line = rest.lines().next()?;
    let seg = line.split(';').next()?;
    let (a, b) = seg.split_once('[')?.1.split_once(']')?.0.split_once(',')?;
    Some((a.trim().parse().ok()?, b.trim().parse().ok()?))
}

#[test]
fn multisine_run_and_frf_say_what_was_measured() {
    let _machine = servo_e2e::shared();
    let dir = tmp("student-multisine");
    let g = dir.join("gains.toml");
    crate::util::write_pid_gains(&g);
    let log = dir.join("ms.mcap");
    let (ok, out, err) = servo(&[
        "run",
        "--experiment",
        &repo("experiments/multisine.toml"),
        "--gains",
        g.to_str().unwrap(),
        "--log",
        log.to_str().unwrap(),
    ]);
    assert!(ok, "{err}\n{out}");
    println!("{out}");
    // a multisine has no steps: tracking-error figures, no overshoot
    assert!(!out.contains("overshoot (max)"), "{out}");
    assert!(
        out.contains("no steps") && out.contains("tracking error RMS"),
        "{out}"
    );
    assert!(
        out.contains("simulated plant:") && out.contains("controller: PID"),
        "{out}"
    );

    let plot = dir.join("frf.svg");
    let (ok, out, err) = servo(&[
        "frf",
        log.to_str().unwrap(),
        "--gains",
        g.to_str().unwrap(),
        "--segment-s",
        "10",
        "--plot",
        plot.to_str().unwrap(),
    ]);
    assert!(ok, "{err}\n{out}");
    println!("{out}");
    // the output limit of the gains file
    assert!(!out.contains("no output limit"), "{out}");
    assert!(out.contains("output limit +-10 V"), "{out}");
    // a margin is measured with an interval narrower than the circle, or said not measured
    for what in ["phase margin", "gain margin"] {
        match printed_interval(&out, what) {
            Some((lo, hi)) => assert!(
                hi - lo < 360.0 && hi.abs() < 1000.0,
                "{what} interval [{lo}, {hi}]:\n{out}"
            ),
            None => assert!(
                out.contains(&format!("{what} not measured")),
                "{what}: neither measured nor said not measured:\n{out}"
            ),
        }
    }
    // coherence over the excited lines: a period-aligned multisine is coherent on them
    let (ok, js, err) = servo(&[
        "frf",
        log.to_str().unwrap(),
        "--gains",
        g.to_str().unwrap(),
        "--segment-s",
        "10",
        "--json",
    ]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&js).unwrap();
    let c = &v["coherence"];
    let frac = c["fraction_above_0_9"].as_f64().unwrap();
    let excited = c["excited_bins"].as_u64().unwrap();
    assert!(
        frac > 0.5,
        "coherence >= 0.9 on only {frac} of the lines: {c}"
    );
    assert!(
        (40..400).contains(&excited),
        "{excited} excited bins for 40 lines: {c}"
    );
    let gaps = c["no_information_rad_s"].as_array().unwrap().len();
    assert!(gaps < 10, "{gaps} no-information ranges listed: {c}");
    // the loop's Bode plot with its margins, and readable ticks
    let svg = std::fs::read_to_string(&plot).unwrap();
    assert!(
        svg.contains("loop L: phase") && svg.contains("crossover"),
        "no loop Bode plot"
    );
    // The bounds follow the estimate: no spike from a bin between the multisine's lines, where
    // the noise alone passes coherence 0.5 and the circle is around nothing. In the magnitude
    // panel no point of the upper bound (green) sits more than a quarter of the plot's height
    // above the estimate (blue) at the same x pixel (the old plot: spikes of 30 dB, half the
    // height).
    let panel = svg.split("<svg x=").nth(1).expect("a first panel");
    let points = |stroke: &str| -> Vec<(i64, i64)> {
        let mut v = Vec::new();
        for pl in panel.split("<polyline").skip(1) {
            let tag = pl.split("/>").next().unwrap_or("");
            if !tag.contains(&format!("stroke=\"{stroke}\"")) {
                continue;
            }
            let pts = tag
                .split("points=\"")
                .nth(1)
                .unwrap_or("")
                .split('"')
                .next()
                .unwrap_or("");
            for xy in pts.split_whitespace() {
                if let Some((x, y)) = xy.split_once(',') {
                    v.push((x.parse().unwrap(), y.parse().unwrap()));
                }
            }
        }
        v
    };
    let measured = points("#1F77B4");
    let upper = points("#2CA02C");
    assert!(
        measured.len() > 10 && upper.len() > 10,
        "no estimate or bound drawn"
    );
    let (top, bottom) = measured
        .iter()
        .chain(&upper)
        .fold((i64::MAX, i64::MIN), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let height = (bottom - top).max(1) as f64;
    let worst = upper
        .iter()
        .filter_map(|&(x, y)| {
            measured
                .iter()
                .filter(|m| m.0 == x)
                .map(|m| (m.1 - y) as f64 / height)
                .reduce(f64::min)
        })
        .fold(0.0f64, f64::max);
    assert!(
        worst < 0.25,
        "the upper bound spikes {:.0} % of the plot's height above the estimate",
        100.0 * worst
    );
    let problems = render_and_check(&plot, &png_dir().join("frf_multisine.png"));
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn a_long_run_plots_under_300_kb() {
    let _machine = servo_e2e::shared();
    let dir = tmp("student-long");
    let g = dir.join("gains.toml");
    crate::util::write_pid_gains(&g);
    let plot = dir.join("long.svg");
    let (ok, out, err) = servo(&[
        "run",
        "--ref",
        "sine:amp=0.5,freq=0.7",
        "--gains",
        g.to_str().unwrap(),
        "--duration",
        "300",
        "--plot",
        plot.to_str().unwrap(),
    ]);
    assert!(ok, "{err}\n{out}");
    let mut problems = Vec::new();
    for f in [plot.clone(), dir.join("long_u.svg")] {
        let png = png_dir().join(format!("{}.png", f.file_stem().unwrap().to_string_lossy()));
        problems.extend(render_and_check(&f, &png));
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn small_values_get_distinct_tick_labels() {
    let _machine = servo_e2e::shared();
    let dir = tmp("student-ticks");
    let t: Vec<f64> = (0..2000).map(|k| k as f64 * 1e-3).collect();
    let y: Vec<f64> = t.iter().map(|t| 3e-5 * (7.0 * t).sin()).collect();
    let svg = servo_cli::plot::line_chart_svg(
        &servo_cli::plot::Chart {
            title: "a torque residual of 30 uN m",
            x_label: "time [s]",
            y_label: "residual [N m]",
            ..Default::default()
        },
        &[servo_cli::plot::Series {
            label: "residual [N m]",
            x: &t,
            y: &y,
        }],
    )
    .unwrap();
    assert!(svg.contains("e-6"), "no engineering notation in the ticks");
    let f = dir.join("small.svg");
    std::fs::write(&f, svg).unwrap();
    let problems = render_and_check(&f, &png_dir().join("small_ticks.png"));
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
