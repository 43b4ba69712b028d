//! Hostile inputs: every reader of untrusted bytes over a deterministic mutation corpus (seeded,
//! thousands of cases, about half a minute in release), plus the specific inputs of issue #14.
//!
//! Each reader must refuse bad input with an error: 0 panics, 0 aborts, 0 hangs, and no single
//! allocation beyond `64 x input + 64 MiB` (tracked by the global allocator below). To add a
//! reader, add one `#[test]` calling `fuzz(name, seeds, cases, |bytes| reader(bytes))`. For
//! longer runs use the `cargo fuzz` targets in `fuzz/` (see fuzz/README.md).

use servo_cli::fuzz::{check_reader, FuzzConfig, TrackingAlloc};
use servo_cli::gains_file::GainsFile;
use servo_cli::io::mcap_read::parse_mcap;
use servo_cli::io::{
    csv_read::{parse_csv, parse_csv_capped},
    LoopMsg, McapLog, McapLogOptions,
};
use servo_cli::model_file::ModelFile;
use servo_cli::reference_file::Experiment;
use std::collections::BTreeMap;
use std::fmt::Display;

#[global_allocator]
static ALLOC: TrackingAlloc = TrackingAlloc;

const SEED: u64 = 0x5e4f_0014;

fn fuzz<T, E: Display>(
    name: &str,
    seeds: &[Vec<u8>],
    cases: usize,
    reader: impl Fn(&[u8]) -> Result<T, E>,
) {
    let rep = check_reader(name, seeds, FuzzConfig::new(cases, SEED), reader);
    eprintln!("{rep}");
    for e in &rep.sample_errors {
        eprintln!("  e.g. {e}");
    }
    assert!(rep.failures.is_empty(), "{rep}");
    assert!(
        rep.refused > 0,
        "{rep}: the mutations never reached an error"
    );
}

/// Input that is not UTF-8 text; converts into both anyhow's error and servo-io's.
#[derive(Debug)]
struct NotText(std::str::Utf8Error);

impl std::fmt::Display for NotText {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "not UTF-8 text: {}", self.0)
    }
}

impl std::error::Error for NotText {}

impl From<NotText> for servo_cli::io::Error {
    fn from(e: NotText) -> Self {
        servo_cli::io::Error::Invalid(e.to_string())
    }
}

fn text(b: &[u8]) -> Result<&str, NotText> {
    std::str::from_utf8(b).map_err(NotText)
}

fn msg(k: usize) -> LoopMsg {
    let t = k as f64 * 1e-3;
    LoopMsg {
        time_s: t,
        ref_rad: 1.5,
        theta_l_rad: (t * 7.0).sin(),
        omega_l_rad_s: (t * 7.0).cos() * 7.0,
        err_rad: 1.5 - (t * 7.0).sin(),
        u_v: (k as f64 * 0.37).sin() * 10.0,
        ff_v: f64::NAN,
        p_v: 1.0,
        i_v: -0.25,
        d_v: 0.0,
        i_a_a: 0.01 * k as f64,
        saturated: k.is_multiple_of(7),
        ref_omega_l_rad_s: f64::NAN,
        i_ref_a: f64::NAN,
        duty: f64::NAN,
    }
}

/// Small servo MCAP logs: zstd and uncompressed chunks of 20 samples, finished and cut.
fn mcap_seeds() -> Vec<Vec<u8>> {
    let dir = tempfile::tempdir().unwrap();
    let mut out = Vec::new();
    use servo_cli::io::LogEncoding;
    for (i, (compress, encoding)) in [
        (true, LogEncoding::Json),
        (false, LogEncoding::Json),
        (true, LogEncoding::Protobuf),
    ]
    .into_iter()
    .enumerate()
    {
        let p = dir.path().join(format!("s{i}.mcap"));
        let mut meta = BTreeMap::new();
        meta.insert("gains_toml".into(), GAINS.to_string());
        meta.insert("duration_s".into(), "0.1".to_string());
        let mut log = McapLog::create(
            &p,
            &meta,
            McapLogOptions {
                flush_period_s: 0.02,
                compress,
                start_unix_ns: 1_000,
                encoding,
                fast_compression: encoding == LogEncoding::Protobuf,
                ..McapLogOptions::default()
            },
        )
        .unwrap();
        for k in 0..100 {
            log.write_loop(&msg(k)).unwrap();
        }
        log.finish().unwrap();
        let b = std::fs::read(&p).unwrap();
        out.push(b[..b.len() * 2 / 3].to_vec());
        out.push(b);
    }
    out
}

const GAINS: &str = "[pid]\nkp = 7.0476\nki = 86.121\nkd = 0.14418\ntl_s = 6.67e-3\nts_s = 1e-3\nkw = 30.0\nu_limit_v = 10\n[design]\nwc_rad_s = 30.0\n";

#[test]
fn fuzz_csv_reader() {
    let _machine = servo_e2e::shared();
    let own = "time_s,u_V,theta_l_rad,i_a_A,ref_rad\n0,1,0,0.1,1\n0.001,2,0.01,0.2,1\n0.002,2.5,0.02,0.25,1\n0.003,2,0.03,0.2,1\n";
    let foreign =
        "# lab export\nt_ms;pos_deg;I_mA;u_V\n0;180;100;1\n1;90;-50;2\n2;91;-40;2\n3;92;-30;2\n";
    let seeds = vec![own.as_bytes().to_vec(), foreign.as_bytes().to_vec()];
    fuzz("csv", &seeds, 6000, |b| {
        parse_csv(text(b)?, "fuzz.csv", None)
    });
    fuzz("csv --columns", &seeds, 5000, |b| {
        parse_csv(
            text(b)?,
            "fuzz.csv",
            Some("time=t_ms:ms,theta_l=pos_deg:deg,i_a=I_mA:mA,u=u_V"),
        )
    });
    // Lines capped at 48 bytes, so that mutated small inputs reach the cap: refused with a
    // message that quotes excerpts, never the whole input.
    fuzz("csv, lines capped", &seeds, 5000, |b| {
        let r = parse_csv_capped(text(b)?, "fuzz.csv", None, 48);
        if let Err(e) = &r {
            let m = format!("{e:#}");
            assert!(m.len() < 2000, "{} bytes of message: {m}", m.len());
        }
        r
    });
}

#[test]
fn fuzz_toml_files() {
    let _machine = servo_e2e::shared();
    let model = ModelFile::from_plant(&servo_core::Plant::nominal()).to_toml_commented();
    let mut with_effects = model.clone();
    with_effects.push_str("\n[effects.backlash]\ngap = 0.04\nstiffness = 5.0\ndamping = 0.01\nload_inertia_fraction = 0.5\n[effects.cogging]\namplitude = 0.002\nharmonic = 12\nphase = 0.3\n");
    fuzz(
        "model file",
        &[model.into_bytes(), with_effects.into_bytes()],
        3000,
        |b| ModelFile::parse(text(b)?).and_then(|m| m.plant()),
    );
    fuzz("gains file", &[GAINS.as_bytes().to_vec()], 5000, |b| {
        GainsFile::parse(text(b)?)
    });
    let mut exps = Vec::new();
    for f in ["steps.toml", "chirp.toml", "identify_friction.toml"] {
        let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("experiments")
            .join(f);
        exps.push(std::fs::read(p).unwrap());
    }
    fuzz("experiment file", &exps, 5000, |b| {
        Experiment::parse(text(b)?, "fuzz.toml")
    });
    let refs: Vec<Vec<u8>> = [
        "step:1.5",
        "sine:amp=90deg,freq=0.5",
        "square:1,0.2",
        "ramp:2",
    ]
    .iter()
    .map(|s| s.as_bytes().to_vec())
    .collect();
    fuzz("--ref", &refs, 5000, |b| {
        servo_core::control::Reference::parse(text(b)?).map_err(|e| anyhow::anyhow!("{e}"))
    });
}

#[test]
fn fuzz_mcap_reader() {
    let _machine = servo_e2e::shared();
    fuzz("mcap read", &mcap_seeds(), 10000, |b| {
        parse_mcap(b, "fuzz.mcap")
    });
}

#[test]
fn fuzz_mcap_recover() {
    let _machine = servo_e2e::shared();
    fuzz("log recover", &mcap_seeds(), 10000, |b| {
        servo_cli::cmd::log::recover_bytes(b, std::io::Cursor::new(Vec::new()))
    });
}

#[test]
fn fuzz_wire_decoder() {
    let _machine = servo_e2e::shared();
    use servo_core::protocol::{Decoder, Frame, Message};
    let msgs = [
        Message::Hello {
            protocol_version: 1,
        },
        Message::Start,
        Message::SetVoltage { seq: 7, u_v: 2.5 },
        Message::LoopReference {
            seq: 9,
            ref_rad: -1.0,
        },
        Message::Stop,
        Message::Stopped,
        Message::GainsAck,
    ];
    let mut stream = Vec::new();
    for m in &msgs {
        stream.extend_from_slice(Frame::new(m).as_bytes());
    }
    let singles: Vec<Vec<u8>> = msgs
        .iter()
        .map(|m| Frame::new(m).as_bytes().to_vec())
        .collect();
    let mut seeds = vec![stream];
    seeds.extend(singles);
    fuzz("wire decoder", &seeds, 20000, |b| {
        let mut d = Decoder::default();
        let (mut ok, mut bad) = (0usize, 0usize);
        d.feed(b, |r| match r {
            Ok(_) => ok += 1,
            Err(_) => bad += 1,
        });
        // A stream is "refused" when some frame in it was rejected.
        if bad > 0 {
            Err(format!("{bad} bad frames, {ok} good"))
        } else {
            Ok(ok)
        }
    });
}

/// The hostile inputs listed in issue #14, one by one: each gets a clear error.
#[test]
fn mcap_with_corrupted_lengths_is_refused_cleanly() {
    let _machine = servo_e2e::shared();
    let seeds = mcap_seeds();
    let good = &seeds[1];
    // A record length of u64::MAX right after the magic and at the first chunk.
    // The first chunk record, found by walking the records (opcode, u64 length, body).
    let mut chunk_at = 8;
    while good[chunk_at] != 0x06 {
        let len = u64::from_le_bytes(good[chunk_at + 1..chunk_at + 9].try_into().unwrap());
        chunk_at += 9 + len as usize;
    }
    for at in [8usize, chunk_at] {
        let mut b = good.clone();
        b[at + 1..at + 9].copy_from_slice(&u64::MAX.to_le_bytes());
        let e = format!("{:#}", parse_mcap(&b, "bad.mcap").unwrap_err());
        assert!(e.contains("bad.mcap"), "{e}");
        let r = servo_cli::cmd::log::recover_bytes(&b, std::io::Cursor::new(Vec::new())).unwrap();
        assert!(
            r.stopped_because
                .as_deref()
                .unwrap_or("")
                .contains("cut short"),
            "{r:?}"
        );
    }
    // The chunk's uncompressed_size (after two u64 times) set to 2^62.
    let mut b = good.clone();
    let us = chunk_at + 9 + 16;
    b[us..us + 8].copy_from_slice(&(1u64 << 62).to_le_bytes());
    let r = servo_cli::cmd::log::recover_bytes(&b, std::io::Cursor::new(Vec::new())).unwrap();
    assert!(r.stopped_because.is_some(), "{r:?}");
    assert!(
        parse_mcap(&b, "bad.mcap").is_err()
            || !parse_mcap(&b, "bad.mcap").unwrap().notes.is_empty()
    );
}

#[test]
fn absurd_plant_constants_are_refused_not_hung_on() {
    let _machine = servo_e2e::shared();
    let model = ModelFile::from_plant(&servo_core::Plant::nominal()).to_toml_commented();
    for key in ["k_t", "k_e", "f_c_drv"] {
        let bad: String = model
            .lines()
            .map(|l| {
                if l.trim_start().starts_with(&format!("{key} ")) {
                    format!("{key} = 1e308")
                } else {
                    l.to_string()
                }
            })
            .collect::<Vec<_>>()
            .join("\n");
        assert_ne!(bad, model, "{key} not in the model file");
        let e = format!("{:#}", ModelFile::parse(&bad).unwrap_err());
        assert!(e.contains(key) && e.contains("physically sensible"), "{e}");
        // The value and the range in scientific notation, not as 309-digit integers.
        assert!(e.contains("= 1e308 ") && e.len() < 400, "{e}");
    }
}

/// Small MAT-files (Level 5) written here, not the lab files: a Simulink Scope "structure with
/// time" with two signals (one a two-column matrix), a cell, an int16 vector, a char array and
/// a complex scalar; each uncompressed and with every variable zlib-compressed (-v7), plus a
/// compressed file whose first element is cut.
fn mat_seeds() -> Vec<Vec<u8>> {
    use servo_e2e::mat_writer::{doubles, element, mat_file, matrix, scope, text};
    let t: Vec<f64> = (0..40).map(|k| k as f64 * 1e-3).collect();
    let th: Vec<f64> = t.iter().map(|t| 90.0 * t).collect();
    let r = vec![30.0; t.len()];
    let u: Vec<f64> = t.iter().map(|t| 5.0 - t).collect();
    let scope_var = scope(
        "thl_u",
        &t,
        &[
            (vec![th, r], "theta_l [deg] / ref [deg]"),
            (vec![u], "u [V]"),
        ],
    );
    let cell = matrix(
        1,
        &[1, 2],
        "data",
        &[doubles("", 2, 2, &[1.0, 2.0, 3.0, 4.0]), text("", "note")],
    );
    let ints: Vec<u8> = (0..8i16)
        .flat_map(|x| (x * 300 - 900).to_le_bytes())
        .collect();
    let int16 = matrix(10, &[8, 1], "counts", &[element(3, &ints)]);
    let mut complex = matrix(6, &[1, 1], "z", &[element(9, &1.5f64.to_le_bytes())]);
    // The complex flag (0x0800) and the imaginary part.
    complex[16 + 1] |= 0x08;
    let imag = element(9, &(-0.5f64).to_le_bytes());
    complex.extend_from_slice(&imag);
    let n = (complex.len() - 8) as u32;
    complex[4..8].copy_from_slice(&n.to_le_bytes());
    let vars = vec![scope_var, cell, int16, complex, text("label", "servo fuzz")];
    let plain = mat_file(&vars, false);
    let packed = mat_file(&vars, true);
    let cut = packed[..packed.len() - 40].to_vec();
    vec![plain, packed, cut]
}

/// The MATLAB-path column map that imports [`mat_seeds`].
const MAT_MAP: &str = "time=thl_u.time,theta_l=thl_u.signals(1).values(:,1):deg,ref=thl_u.signals(1).values(:,end):deg,u=thl_u.signals(2).values";

#[test]
fn fuzz_mat_reader() {
    let _machine = servo_e2e::shared();
    use servo_cli::io::mat_log;
    use servo_cli::io::mat_read::parse_mat;
    let seeds = mat_seeds();
    for (i, s) in seeds.iter().take(2).enumerate() {
        let f = parse_mat(s).unwrap_or_else(|e| panic!("seed {i}: {e}"));
        let imp = mat_log::import(&f, "seed.mat", Some(MAT_MAP))
            .unwrap_or_else(|e| panic!("seed {i}: {e:#}"));
        assert_eq!(imp.record.len(), 40, "seed {i}");
        assert_eq!(f.variables.len(), 5, "seed {i}");
    }
    // Whatever parses is also listed (`servo inspect`), guessed and imported through the map.
    let read = |b: &[u8]| -> anyhow::Result<usize> {
        let f = parse_mat(b)?;
        let _ = mat_log::describe(&f);
        let _ = mat_log::guess(&f);
        let imp = mat_log::import(&f, "fuzz.mat", Some(MAT_MAP))?;
        Ok(imp.record.len())
    };
    // Allocation bound tighter than the other readers': 64 x the file + 1 MiB (the inflated data
    // of a small file are small; a zlib stream inflates at most ~1032 times).
    let cfg = FuzzConfig {
        alloc_base: 1 << 20,
        ..FuzzConfig::new(8000, SEED)
    };
    let rep = check_reader("mat", &seeds, cfg, read);
    eprintln!("{rep}");
    for e in &rep.sample_errors {
        eprintln!("  e.g. {e}");
    }
    assert!(rep.failures.is_empty(), "{rep}");
    assert!(rep.refused > 0 && rep.accepted > 0, "{rep}");
}

#[test]
fn fuzz_matlab_path_columns() {
    let _machine = servo_e2e::shared();
    use servo_cli::io::mat_path::MatPath;
    use servo_cli::io::ColumnMap;
    let paths: Vec<Vec<u8>> = [
        "thl_u.signals(1).values(:,1)",
        "thl_u.time",
        "data{2}(:,3)",
        "ia_best.signals.values(end,:)",
        "x(1,2,3)",
    ]
    .iter()
    .map(|s| s.as_bytes().to_vec())
    .collect();
    fuzz("matlab path", &paths, 5000, |b| {
        MatPath::parse(text(b)?).map_err(anyhow::Error::msg)
    });
    let maps = vec![MAT_MAP.as_bytes().to_vec()];
    fuzz("--columns with MATLAB paths", &maps, 5000, |b| {
        ColumnMap::parse(text(b)?)
    });
}

/// The expression language of user-defined effects (issue #11): the parser and the compiled
/// program never panic, whatever the text; a compiled program evaluates without panicking.
#[test]
fn fuzz_user_effect_expressions() {
    let _machine = servo_e2e::shared();
    use servo_core::custom::Program;
    let seeds: Vec<Vec<u8>> = [
        "k * (theta_l - theta0)",
        "-k^2 * sin(2 * theta_m + pi / 3) + atan2(omega_l, 1e-3) * abs(i_a)",
        "max(u, min(t, 2.5e-1)) / (1 + exp(-omega_m)) - sign(theta_l)^3",
        "((((k))))*theta0^-1.5e+2+sqrt(ln(log10(tanh(atan(cos(tan(u)))))))",
        "pow(theta_l, 3) - k * theta_l * abs(theta_l)",
    ]
    .iter()
    .map(|s| s.as_bytes().to_vec())
    .collect();
    let signals = [
        [0.3, 4.2, -1.0, -14.0, 0.5, 3.0, 1.25],
        [0.0; 7],
        [
            f64::MAX,
            -f64::MAX,
            f64::NAN,
            f64::INFINITY,
            -0.0,
            1e-300,
            -1e300,
        ],
    ];
    fuzz("user effect expression", &seeds, 6000, |bytes| {
        let text = String::from_utf8_lossy(bytes);
        let p = Program::compile(&text, &["k", "theta0"])?;
        let mut acc = 0.0;
        for s in &signals {
            acc += p.eval(s, &[0.02, 0.4]);
        }
        Ok::<f64, servo_core::custom::ExprError>(acc)
    });
}

/// Effects files (`--effects`, `[custom.NAME]` sections).
#[test]
fn fuzz_effects_files() {
    let _machine = servo_e2e::shared();
    let seeds = vec![br#"[custom.cable]
acts_on = "load_torque"
expr = "k * (theta_l - theta0)"
[custom.cable.params]
k = { value = 0.0, min = 0.0, unit = "N m/rad" }
theta0 = { value = 0.0, min = -1.5, max = 1.5, unit = "rad" }

[custom.ecc]
acts_on = "sensor"
expr = "theta_l + e * sin(theta_l)"
[custom.ecc.params]
e = { value = 0.0, min = -0.05, max = 0.05, unit = "rad" }
"#
    .to_vec()];
    fuzz("effects file", &seeds, 3000, |bytes| {
        let text = std::str::from_utf8(bytes).map_err(|e| e.to_string())?;
        servo_cli::effects_file::EffectsFile::parse(text).map_err(|e| format!("{e:#}"))
    });
}

/// Hostile names for the report writers' seeds: quotes breaking out of attributes, tags,
/// `javascript:` links, entities, CDATA ends, control characters, non-characters.
const HOSTILE_NAMES: &[&str] = &[
    "x\" tabindex=\"1\" autofocus onfocus=\"alert(1)\" y=\".csv",
    "<script>alert(1)</script>",
    "javascript:alert(1)",
    " JaVaScRiPt:alert(1)",
    "data:text/html,<svg onload=alert(1)>",
    "</svg><svg onload=alert(1)>",
    "' onmouseover='alert(1)",
    "a & b &amp; &lt; &#x3c; ]]> <!-- -->",
    "ctrl \u{0}\u{7}\u{b}\u{1b}[31m \u{7f}\u{85} \u{fffe}\u{ffff}",
    "θ_l [rad] ω_l ✓ \u{202e}gnp.exe",
    "https://example.org/a?b=1&c=\"2\"#x",
    "{} {{}} %s \\ \r\n\t",
];

/// The report and chart writers (`servo_cli::fuzz::check_report_writers`, the `report` fuzz
/// target's check) over mutated hostile names: no panic, no handler, no script, no broken
/// markup, and the charts parse as XML.
#[test]
fn fuzz_report_writers() {
    let _machine = servo_e2e::shared();
    let mut seeds: Vec<Vec<u8>> = Vec::new();
    for (k, _) in HOSTILE_NAMES.iter().enumerate() {
        let fields: Vec<&str> = (0..8)
            .map(|i| HOSTILE_NAMES[(k + i) % HOSTILE_NAMES.len()])
            .collect();
        let mut s = fields.join("\u{1f}").into_bytes();
        s.insert(0, k as u8); // the chart's flags (log x, scatter)
        seeds.push(s);
    }
    seeds.push(Vec::new());
    let rep = check_reader("report writers", &seeds, FuzzConfig::new(3000, SEED), |b| {
        let [svg, stacked, _page] = servo_cli::fuzz::check_report_writers(b);
        roxmltree::Document::parse(&svg).map_err(|e| format!("the chart is not XML: {e}"))?;
        roxmltree::Document::parse(&stacked)
            .map_err(|e| format!("the stacked charts are not XML: {e}"))?;
        Ok::<(), String>(())
    });
    eprintln!("{rep}");
    assert!(rep.failures.is_empty(), "{rep}");
    assert_eq!(rep.refused, 0, "an SVG that is not XML: {rep}");
}

/// The atomic writer every output goes through (`servo_io::output::check_atomic_writer`, the
/// `atomic_writer` fuzz target's check) over mutated cases: previous file or not, older backup
/// or not, committed or abandoned, through each of its three ways of writing. The target is
/// the old or the new bytes, a previous file is kept once under the first free `NAME.N`, an
/// older backup is untouched, no temporary file is left.
#[test]
fn fuzz_atomic_writer() {
    let _machine = servo_e2e::shared();
    let body = b"[pid]\nkp = 7.0\nki = 86.1\n# a hand-made comment\n".to_vec();
    // flags: bit 0 a previous file, bit 1 commit, bit 2 the same bytes, bit 3 an older
    // backup, bits 4.. the writer (write_file, AtomicFile, Replacement).
    let seeds: Vec<Vec<u8>> = (0u8..48)
        .map(|flags| {
            let mut s = vec![flags, (flags as usize * 7 % body.len()) as u8];
            s.extend_from_slice(&body);
            s
        })
        .collect();
    let rep = check_reader("atomic writer", &seeds, FuzzConfig::new(1500, SEED), |b| {
        if servo_cli::io::output::check_atomic_writer(b) {
            Ok(())
        } else {
            Err("no temporary folder for the case")
        }
    });
    eprintln!("{rep}");
    assert!(rep.failures.is_empty(), "{rep}");
    assert_eq!(rep.refused, 0, "cases not set up: {rep}");
}
