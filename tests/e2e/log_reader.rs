//! Adding a log format is one file and one registry line (#32): a test-only format, a
//! whitespace-separated text log (`.ws`, first line `servo-ws 1`, then `time_s u_V theta_l_rad`
//! per line), read through servo-io's [`Registry`] next to the built-in formats.

use servo_cli::io::{Error, LogMeta, LogReader, Registry, Result, Signal};
use servo_core::record::Record;
use std::path::Path;

/// The whole format: this reader.
struct Whitespace;

impl LogReader for Whitespace {
    fn name(&self) -> &'static str {
        "whitespace text"
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["ws"]
    }
    fn read(
        &self,
        path: &Path,
        _columns: Option<&str>,
        _want: Option<&[Signal]>,
        _axis: &servo_core::Transmission,
    ) -> Result<(Record, LogMeta)> {
        let text = std::fs::read_to_string(path)?;
        let mut lines = text.lines();
        if lines.next() != Some("servo-ws 1") {
            return Err(Error::Incompatible {
                path: path.to_path_buf(),
                format: self.name(),
            });
        }
        let (mut t, mut u, mut theta) = (Vec::new(), Vec::new(), Vec::new());
        for line in lines.filter(|l| !l.trim().is_empty()) {
            let v: Vec<f64> = line
                .split_whitespace()
                .map(|x| x.parse().expect("a number"))
                .collect();
            t.push(v[0]);
            u.push(v[1]);
            theta.push(v[2]);
        }
        let rec = Record {
            source: path.display().to_string(),
            time_s: t,
            u_v: Some(u),
            theta_l_rad: Some(theta),
            ..Record::default()
        };
        Ok((rec, LogMeta::default()))
    }
    fn inspect(&self, path: &Path) -> Result<Vec<String>> {
        let (rec, _) = self.read(path, None, None, &servo_core::Transmission::GEAR)?;
        Ok(vec![format!(
            "{}: whitespace text, {} samples",
            path.display(),
            rec.len()
        )])
    }
}

static WHITESPACE: Whitespace = Whitespace;

fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).expect("writing a test log");
    p
}

#[test]
fn log_reader_registry_takes_a_format_from_outside_in_one_line() {
    let _machine = servo_e2e::shared();
    let dir = tempfile::tempdir().expect("tempdir");
    // Samples of a made-up run: u a ramp, theta_l its running sum.
    let mut text = String::from("servo-ws 1\n");
    let mut theta = 0.0;
    for k in 0..50 {
        let (t, u) = (k as f64 * 2e-3, 0.1 * k as f64);
        theta += 1e-3 * u;
        text.push_str(&format!("{t} {u} {theta}\n"));
    }
    let log = write(dir.path(), "run.ws", &text);

    // Without it, the built-in registry names the formats it knows, word for word as before.
    let err = Registry::built_in()
        .read(&log, None, None, &servo_core::Transmission::GEAR)
        .expect_err("no built-in reader takes .ws");
    assert_eq!(
        err.to_string(),
        format!(
            "{}: unknown log format `.ws`; expected a .mat, .mcap, .csv, .json or .wpilog file",
            log.display()
        )
    );

    // One line: the registry with the reader.
    let registry = Registry::built_in().with(&WHITESPACE);
    let (rec, meta) = registry
        .read(&log, None, None, &servo_core::Transmission::GEAR)
        .expect("the .ws log reads");
    assert_eq!(rec.len(), 50);
    let (u, th) = (rec.u_v.expect("u"), rec.theta_l_rad.expect("theta_l"));
    assert!((u[49] - 4.9).abs() < 1e-12, "{}", u[49]);
    assert!((th[49] - theta).abs() < 1e-12);
    assert!(meta.notes.is_empty());
    assert_eq!(
        registry.inspect(&log).expect("inspect"),
        [format!("{}: whitespace text, 50 samples", log.display())]
    );
    // The message now lists it too.
    let other = write(dir.path(), "run.xyz", "1 2 3\n");
    assert!(
        registry
            .read(&other, None, None, &servo_core::Transmission::GEAR)
            .expect_err(".xyz is nobody's")
            .to_string()
            .ends_with("expected a .mat, .mcap, .csv, .json, .wpilog or .ws file"),
        "{:?}",
        registry
            .read(&other, None, None, &servo_core::Transmission::GEAR)
            .err()
    );

    // "Not mine" is typed: a .ws file without the format's first line is passed on, and with no
    // other reader for .ws, the file is of no known format.
    let foreign = write(dir.path(), "foreign.ws", "t u theta\n0 0 0\n");
    assert!(matches!(
        WHITESPACE.read(&foreign, None, None, &servo_core::Transmission::GEAR),
        Err(Error::Incompatible { .. })
    ));
    assert!(matches!(
        registry.read(&foreign, None, None, &servo_core::Transmission::GEAR),
        Err(Error::UnknownFormat { .. })
    ));

    // The built-in formats read as before through the extended registry.
    let csv = write(
        dir.path(),
        "run.csv",
        "time_s,u_V,theta_l_rad\n0,0,0\n0.002,1,0.001\n0.004,2,0.003\n",
    );
    let (rec, _) = registry
        .read(&csv, None, None, &servo_core::Transmission::GEAR)
        .expect("the CSV reads");
    assert_eq!(rec.len(), 3);
    assert_eq!(
        registry.reader_for(&csv).expect("a reader").name(),
        "CSV",
        "the first reader that can read a file reads it"
    );
}
