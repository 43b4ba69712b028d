//! `servo._servo`: the native part of the Python package (the Pythonic API is in
//! `python/servo/`). It runs servo's commands through [`servo_cli::api`] (the same code as
//! `servo ... --json`, so a result's `.to_dict()` is the CLI's JSON), reads and writes logs
//! through `servo_io`, and never lets a panic cross into Python.
//!
//! Long calls run on a worker thread with the GIL released while the calling thread polls for
//! signals every 50 ms: a Ctrl-C (KeyboardInterrupt) sets the diagnosis' cancel flag
//! ([`servo_core::diagnose::cancel`]) and is raised at once.

use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use serde_json::Value;
use servo_cli::api::{self, Failure, FailureKind};
use servo_core::record::Record;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::Duration;

/// How often the waiting thread looks for a KeyboardInterrupt.
const POLL: Duration = Duration::from_millis(50);
/// After a KeyboardInterrupt, how long to wait for the work to stop at its next check before
/// returning anyway (it then stops on its own, its result dropped).
const STOP_WAIT: Duration = Duration::from_secs(3);

/// Runs `work` on a worker thread, the GIL released, polling for signals; on a signal sets the
/// cancel flag and raises the signal's exception (KeyboardInterrupt).
fn run_polled<T: Send + 'static>(
    py: Python<'_>,
    work: impl FnOnce(Arc<AtomicBool>) -> T + Send + 'static,
) -> PyResult<T> {
    let flag = Arc::new(AtomicBool::new(false));
    let (tx, rx) = mpsc::channel();
    // detach() wants a Sync borrow: the receiver is only ever used from this thread.
    let rx = std::sync::Mutex::new(rx);
    let recv = |t: Duration| match rx.lock() {
        Ok(r) => r.recv_timeout(t),
        Err(_) => Err(mpsc::RecvTimeoutError::Disconnected),
    };
    let worker_flag = flag.clone();
    let handle = std::thread::Builder::new()
        .name("servo-work".into())
        .spawn(move || {
            let _ = tx.send(work(worker_flag));
        })
        .map_err(|e| PyRuntimeError::new_err(format!("cannot start a worker thread: {e}")))?;
    loop {
        match py.detach(|| recv(POLL)) {
            Ok(v) => {
                let _ = handle.join();
                return Ok(v);
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                return Err(PyRuntimeError::new_err(
                    "servo's worker thread ended without a result (a bug, please report it)",
                ));
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {
                if let Err(e) = py.check_signals() {
                    flag.store(true, Ordering::Relaxed);
                    if py.detach(|| recv(STOP_WAIT)).is_ok() {
                        let _ = handle.join();
                    }
                    return Err(e);
                }
            }
        }
    }
}

fn kind_name(k: FailureKind) -> &'static str {
    match k {
        FailureKind::Usage => "usage",
        FailureKind::Cancelled => "cancelled",
        FailureKind::Command => "command",
        FailureKind::Panic => "panic",
    }
}

/// `("ok", json_text)` or `(kind, message)`.
fn outcome(r: Result<Value, Failure>) -> (String, String) {
    match r {
        Ok(v) => match serde_json::to_string(&v) {
            Ok(s) => ("ok".into(), s),
            Err(e) => ("panic".into(), format!("cannot serialise the result: {e}")),
        },
        Err(f) => (kind_name(f.kind).into(), f.message),
    }
}

/// Runs `servo ARGS... --json` in-process: `("ok", json_text)` or `(kind, message)` with kind
/// one of `usage`, `command`, `cancelled`, `panic`. The GIL is released while it runs.
#[pyfunction]
fn run_json(py: Python<'_>, args: Vec<String>) -> PyResult<(String, String)> {
    run_polled(py, move |flag| outcome(api::run_json(&args, Some(flag))))
}

/// Runs `servo ARGS...` (a command without `--json`, e.g. `run`): `("ok", "")` or
/// `(kind, message)`.
#[pyfunction]
fn run(py: Python<'_>, args: Vec<String>) -> PyResult<(String, String)> {
    run_polled(py, move |_| match api::run(&args) {
        Ok(()) => ("ok".into(), String::new()),
        Err(f) => (kind_name(f.kind).into(), f.message),
    })
}

/// The model file of a built-in plant (`servo params --preset NAME`): `lab` or `table2`.
#[pyfunction]
fn params_toml(preset: &str) -> PyResult<String> {
    use clap::ValueEnum;
    let p = servo_cli::plant_args::PlantPreset::from_str(preset, true).map_err(|_| {
        pyo3::exceptions::PyValueError::new_err(format!(
            "unknown plant preset `{preset}`; expected `lab` or `table2`"
        ))
    })?;
    Ok(p.model_file().to_toml_commented())
}

/// A TOML document as JSON text (to read model and gains files without a TOML parser in
/// Python 3.9/3.10): `("ok", json)` or `("command", message)`.
#[pyfunction]
fn toml_to_json(text: &str) -> (String, String) {
    match toml::from_str::<toml::Value>(text) {
        Ok(v) => match serde_json::to_string(&v) {
            Ok(s) => ("ok".into(), s),
            Err(e) => ("command".into(), e.to_string()),
        },
        Err(e) => ("command".into(), e.to_string()),
    }
}

/// Many command lines on `workers` threads; one `(kind, payload)` per job, in order.
#[pyfunction]
fn run_many(
    py: Python<'_>,
    jobs: Vec<Vec<String>>,
    workers: usize,
) -> PyResult<Vec<(String, String)>> {
    run_polled(py, move |flag| {
        api::run_many(&jobs, workers, Some(flag))
            .into_iter()
            .map(outcome)
            .collect()
    })
}

fn guard<T>(f: impl FnOnce() -> anyhow_like::Result<T>) -> Result<T, String> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(e),
        Err(_) => Err("internal error (a bug in servo, please report it)".into()),
    }
}

/// The error text of a reader, as `servo` prints it.
mod anyhow_like {
    pub type Result<T> = std::result::Result<T, String>;
}

const SIGNALS: [&str; 11] = [
    "time_s",
    "u_v",
    "theta_l_rad",
    "theta_m_rad",
    "omega_l_rad_s",
    "omega_m_rad_s",
    "i_a_a",
    "ref_rad",
    "i_ref_a",
    "duty",
    "v_supply_v",
];

fn columns_of(r: Record) -> Vec<(&'static str, Vec<f64>)> {
    let mut out = vec![("time_s", r.time_s)];
    for (name, v) in [
        ("u_v", r.u_v),
        ("theta_l_rad", r.theta_l_rad),
        ("theta_m_rad", r.theta_m_rad),
        ("omega_l_rad_s", r.omega_l_rad_s),
        ("omega_m_rad_s", r.omega_m_rad_s),
        ("i_a_a", r.i_a_a),
        ("ref_rad", r.ref_rad),
        ("i_ref_a", r.i_ref_a),
        ("duty", r.duty),
        ("v_supply_v", r.v_supply_v),
    ] {
        if let Some(v) = v {
            out.push((name, v));
        }
    }
    out
}

/// What [`read_log`] returns: kind, signals (or the message), notes, metadata.
type ReadOutcome<'py> = (String, Bound<'py, PyAny>, Vec<String>, Bound<'py, PyDict>);

/// Reads a log (MCAP, CSV or MAT) as `servo` does: `("ok", {signal: array}, notes, metadata)`
/// or `(kind, message, [], {})`. Signal names carry their SI unit (`time_s`, `u_v`,
/// `theta_l_rad`, `i_a_a`, ...).
#[pyfunction]
#[pyo3(signature = (path, columns=None))]
fn read_log<'py>(
    py: Python<'py>,
    path: PathBuf,
    columns: Option<String>,
) -> PyResult<ReadOutcome<'py>> {
    let got = py.detach(|| {
        guard(|| {
            servo_io::read_log_with_meta(&path, columns.as_deref())
                .map_err(|e| format!("reading log {}: {e:#}", path.display()))
        })
    });
    let meta = PyDict::new(py);
    match got {
        Ok((rec, m)) => {
            let d = PyDict::new(py);
            for (name, v) in columns_of(rec) {
                d.set_item(name, PyArray1::from_vec(py, v))?;
            }
            for (k, v) in m.entries {
                meta.set_item(k, v)?;
            }
            Ok(("ok".into(), d.into_any(), m.notes, meta))
        }
        Err(msg) => Ok((
            "command".into(),
            msg.into_pyobject(py)?.into_any(),
            vec![],
            meta,
        )),
    }
}

/// Writes arrays (`time_s` and any of the other signal names) as servo's CSV, exactly
/// (shortest round-trip decimals): `None` or the error message.
#[pyfunction]
fn write_csv(
    py: Python<'_>,
    path: PathBuf,
    signals: Vec<(String, PyReadonlyArray1<'_, f64>)>,
) -> PyResult<Option<String>> {
    let mut rec = Record {
        source: path.display().to_string(),
        ..Record::default()
    };
    for (name, arr) in &signals {
        let v = arr
            .as_slice()
            .map(|s| s.to_vec())
            .unwrap_or_else(|_| arr.as_array().to_vec());
        match name.as_str() {
            "time_s" => rec.time_s = v,
            "u_v" => rec.u_v = Some(v),
            "theta_l_rad" => rec.theta_l_rad = Some(v),
            "theta_m_rad" => rec.theta_m_rad = Some(v),
            "omega_l_rad_s" => rec.omega_l_rad_s = Some(v),
            "omega_m_rad_s" => rec.omega_m_rad_s = Some(v),
            "i_a_a" => rec.i_a_a = Some(v),
            "ref_rad" => rec.ref_rad = Some(v),
            "i_ref_a" => rec.i_ref_a = Some(v),
            "duty" => rec.duty = Some(v),
            "v_supply_v" => rec.v_supply_v = Some(v),
            other => {
                return Ok(Some(format!(
                    "unknown signal `{other}`; expected one of {}",
                    SIGNALS.join(", ")
                )))
            }
        }
    }
    let r = py.detach(|| guard(|| servo_io::write_csv(&path, &rec).map_err(|e| format!("{e:#}"))));
    Ok(r.err())
}

/// The version of the servo crates this module was built from.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _servo(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // Python handles Ctrl-C (KeyboardInterrupt): servo's runs never install their own handler.
    servo_cli::live::leave_ctrlc_to_host();
    m.add_function(wrap_pyfunction!(run_json, m)?)?;
    m.add_function(wrap_pyfunction!(run_many, m)?)?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(params_toml, m)?)?;
    m.add_function(wrap_pyfunction!(toml_to_json, m)?)?;
    m.add_function(wrap_pyfunction!(read_log, m)?)?;
    m.add_function(wrap_pyfunction!(write_csv, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add("SIGNALS", SIGNALS.to_vec())?;
    Ok(())
}
