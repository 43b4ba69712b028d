//! `servo compare` on runs of one reference without and with compensation (issue #29): the
//! measured RMS tracking error of each run, and, per compensated effect, the model's ladder on
//! that run's reference and controller (servo_hw::run::compensation_check): what each
//! compensation is worth, one effect at a time, beside what the runs measured.

use super::LogData;
use crate::model_file::ModelFile;
use serde_json::{json, Value};
use servo_core::metrics::RunSummary;
use servo_core::Plant;
use servo_hw::run::compensation_check::{tracking_ladder, TrackingRun, TrackingRung};
use servo_io::compensation::CompensationChoice;
use servo_io::reference_file::Experiment;

/// One run's measured tracking error.
pub(super) struct RunError {
    pub name: String,
    /// The run's `--ff` (as its log records it).
    pub ff: String,
    pub err_rms_rad: f64,
}

/// The runs' errors and the model's ladder on the run that compensated the most effects.
pub(super) struct Tracking {
    pub runs: Vec<RunError>,
    /// The run the ladder was made on, and the ladder; or why none was made.
    pub ladder: Result<(String, Vec<TrackingRung>), String>,
}

/// The section, when at least two logs have a reference and one of them compensated effects
/// (`None` otherwise).
pub(super) fn tracking_ladders(
    logs: &[LogData],
    mf: &ModelFile,
    plant: &Plant,
) -> Option<Tracking> {
    let runs: Vec<(usize, RunError)> = logs
        .iter()
        .enumerate()
        .filter_map(|(i, l)| {
            l.record.ref_rad.as_ref()?;
            let s = RunSummary::compute(&l.record, &[], 0.05);
            Some((
                i,
                RunError {
                    name: l.name.clone(),
                    ff: l.feedforward.value.clone(),
                    err_rms_rad: s.err_rms_rad?,
                },
            ))
        })
        .collect();
    if runs.len() < 2 || !logs.iter().any(|l| !l.compensated.is_empty()) {
        return None;
    }
    let (best, _) = runs
        .iter()
        .max_by_key(|(i, _)| logs[*i].compensated.len())?;
    let log = &logs[*best];
    let ladder = ladder_on(log, mf, plant).map(|l| (log.name.clone(), l));
    Some(Tracking {
        runs: runs.into_iter().map(|(_, r)| r).collect(),
        ladder,
    })
}

/// The model's ladder on `log`'s reference and controller.
fn ladder_on(log: &LogData, mf: &ModelFile, plant: &Plant) -> Result<Vec<TrackingRung>, String> {
    let pid = log
        .controller
        .as_ref()
        .map(|c| c.config)
        .ok_or("the run's controller is unknown (no gains in its metadata or --gains)")?;
    let reference = log
        .reference
        .as_deref()
        .ok_or("the log does not record its reference")?;
    let duration_s = log.record.time_s.last().copied().unwrap_or(0.0) + pid.ts_s;
    // an experiment file's text, or a `--ref` (or an experiment file's path)
    let exp = if reference.contains("[[segment]]") {
        Experiment::parse(reference, "the log's reference")
    } else {
        Experiment::from_arg(reference, duration_s)
    }
    .map_err(|e| format!("the run's reference cannot be rebuilt: {e:#}"))?;
    let choice = CompensationChoice::parse(&log.feedforward.value, mf, plant, 0.0)
        .map_err(|e| format!("the run's --ff {}: {e:#}", log.feedforward.value))?;
    let effects: Vec<_> = plant
        .effects
        .iter()
        .map(|e| e.kind)
        .filter(|k| log.compensated.contains(k))
        .collect();
    let run = TrackingRun {
        truth: plant,
        sensors: mf.sensors.unwrap_or_default(),
        model: plant,
        pid,
        u_limit_v: log.u_limit.as_ref().map_or(10.0, |(u, _)| *u),
        program: servo_core::control::Program::Segments(exp.segments),
        duration_s,
        ramp_s: 0.0,
        drive: mf.drive,
    };
    tracking_ladder(&run, choice.linear, &effects, &choice.custom).map_err(|e| format!("{e}"))
}

/// The text lines.
pub(super) fn tracking_lines(t: &Option<Tracking>) -> Vec<String> {
    let Some(t) = t else {
        return Vec::new();
    };
    let mut out = vec![String::from(
        "tracking error of the runs (RMS of ref - theta_l, measured):",
    )];
    let first = t.runs.first().map_or(f64::NAN, |r| r.err_rms_rad);
    for r in &t.runs {
        out.push(format!(
            "  {:<32} --ff {:<44} {:.3e} rad ({:+.0} %)",
            r.name,
            r.ff,
            r.err_rms_rad,
            100.0 * (r.err_rms_rad / first - 1.0)
        ));
    }
    match &t.ladder {
        Ok((name, ladder)) => {
            out.push(format!(
                "per compensated effect, as the model predicts it on {name}'s reference and controller (servo run's loop on the model):"
            ));
            let base = ladder.first().map_or(f64::NAN, |r| r.err_rms_rad);
            for r in ladder {
                out.push(format!(
                    "  {:<44} {:.3e} rad ({:+.0} %)",
                    r.label(),
                    r.err_rms_rad,
                    100.0 * (r.err_rms_rad / base - 1.0)
                ));
            }
        }
        Err(why) => out.push(format!("per compensated effect: no ladder ({why})")),
    }
    out
}

/// The `"tracking"` object of `--json` (`None`: no section).
pub(super) fn tracking_json(t: &Option<Tracking>) -> Option<Value> {
    let t = t.as_ref()?;
    Some(json!({
        "runs": t.runs.iter().map(|r| json!({
            "log": r.name,
            "ff": r.ff,
            "err_rms_rad": r.err_rms_rad,
        })).collect::<Vec<_>>(),
        "ladder_log": t.ladder.as_ref().ok().map(|(n, _)| n.clone()),
        "ladder": t.ladder.as_ref().ok().map(|(_, l)| l.iter().map(|r| json!({
            "rung": r.label(),
            "effects": r.effects.iter().map(|k| k.name()).collect::<Vec<_>>(),
            "err_rms_rad": r.err_rms_rad,
            "err_max_rad": r.err_max_rad,
        })).collect::<Vec<_>>()),
        "no_ladder": t.ladder.as_ref().err(),
    }))
}
