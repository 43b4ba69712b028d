//! One log of a fleet: read it on the model's axis and fit the model to it, the base (J_eq,
//! B_eq, tau_sf and, with the current logged, the electrical constants) and every parameter of
//! the effects the model file declares (gaps, levels, ...), as `servo compare --add` fits an
//! effect ([`servo_core::fit::fit_model`]). Only the small estimates leave: the record is
//! dropped here.

use crate::model_file::ModelFile;
use servo_core::effects::EffectKind;
use servo_core::fit::{fit_model, EffectToFit, FitOptions};
use std::path::Path;

/// One fitted parameter of one log.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ParamValue {
    /// As in model files: `j_eq`, `b_eq`, `tau_sf`, `k_drv`, `r_eq`, `<effect>.<key>`.
    pub parameter: String,
    /// SI unit.
    pub unit: String,
    pub value: f64,
    /// Standard error of the fit (`None` when the fit gives none: a parameter sized by a search).
    pub std_err: Option<f64>,
}

/// What a log gives, independent of where it lies (cached by its content).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LogFit {
    pub estimates: Vec<ParamValue>,
    /// The log's own time [Unix s] and where it came from (`mcap`, `mat`, `column:NAME`).
    pub content_time: Option<(f64, String)>,
    /// The log's short metadata entries (MCAP key/values; a CSV's first-row values by column),
    /// for `--group-by`.
    pub meta: std::collections::BTreeMap<String, String>,
    /// Samples of the log.
    pub samples: usize,
}

/// The effects to fit: every declared effect but the base friction, each fittable parameter
/// fitted (the declared values are the start and keep what is not fittable).
pub fn effects_to_fit(model: &ModelFile) -> Vec<EffectToFit> {
    model
        .effects
        .iter()
        .filter(|e| !matches!(e.kind, EffectKind::Viscous | EffectKind::Coulomb))
        .map(|e| {
            let mut t = EffectToFit::all(e.kind);
            t.effect = *e;
            t
        })
        .collect()
}

/// The name of a fitted parameter as model files write it.
pub fn parameter_name(effect: Option<EffectKind>, key: &str) -> String {
    match effect {
        None | Some(EffectKind::Viscous) | Some(EffectKind::Coulomb) => key.to_string(),
        Some(k) => format!("{}.{key}", k.name()),
    }
}

/// Fits `model` to the log at `path` (`bytes` its content, already read for the hash).
pub fn fit_log(
    path: &Path,
    bytes: &[u8],
    model: &ModelFile,
    columns: Option<&str>,
    time_column: Option<&str>,
) -> anyhow::Result<LogFit> {
    let (record, meta) = crate::io::read_log_checked(path, columns, model)?;
    let plant = model.plant()?;
    let fit = fit_model(
        std::slice::from_ref(&record),
        &plant,
        &effects_to_fit(model),
        &FitOptions::default(),
    )
    .map_err(|e| anyhow::anyhow!("the model fit failed: {e}"))?;
    let estimates = fit
        .params
        .iter()
        .filter(|p| p.fitted && p.value.is_finite())
        .map(|p| ParamValue {
            parameter: parameter_name(p.effect, p.key),
            unit: p.unit.to_string(),
            value: p.value,
            std_err: p.std_err.filter(|s| s.is_finite() && *s > 0.0),
        })
        .collect();
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let content_time = match ext.as_str() {
        "mcap" => meta
            .get(super::when::MCAP_START_KEY)
            .and_then(|v| v.parse::<f64>().ok())
            .map(|ns| (ns * 1e-9, "mcap".to_string())),
        "mat" => super::when::mat_header_time(bytes).map(|t| (t, "mat".to_string())),
        _ => super::when::csv_column_time(bytes, time_column)
            .map(|(t, c)| (t, format!("column:{c}"))),
    };
    let mut short: std::collections::BTreeMap<String, String> = meta
        .entries
        .into_iter()
        .filter(|(_, v)| v.len() <= 200 && !v.contains('\n'))
        .collect();
    // A CSV's columns are its metadata for `--group-by NAME`: the first row's value of each
    // (an `actuator` or `unit_id` column), beside what the reader read (which takes precedence).
    if !matches!(ext.as_str(), "mcap" | "mat") {
        for (k, v) in super::when::csv_first_row(bytes) {
            short.entry(k).or_insert(v);
        }
    }
    Ok(LogFit {
        estimates,
        content_time,
        meta: short,
        samples: record.len(),
    })
}
