//! `servo compare --add --save`: the gate before a model is written (the model with the effects
//! must not predict worse than the model it started from, unless `--force`), and what is said
//! about it in text and JSON.

use super::*;
use servo_core::compare::gate::{gate, refitted_base, Gate, Refitted, MAX_WORSENING};
use servo_core::compare::logs::AddEffect;
use servo_core::Plant;

/// What happened to `--save`.
pub(super) struct SaveOutcome {
    /// The path asked for.
    pub path: PathBuf,
    /// The gate's verdict (None without `--add`: the model as given is saved as is).
    pub gate: Option<Gate>,
    pub saved: bool,
    pub forced: bool,
}

impl SaveOutcome {
    /// The lines of the text report.
    pub fn lines(&self) -> Vec<String> {
        let p = self.path.display();
        let mut out = Vec::new();
        if let Some(g) = &self.gate {
            if let Some(why) = &g.held_out_missing {
                out.push(format!(
                    "held-out check: not made ({why}); judged on the replay"
                ));
            }
            out.push(g.sentence());
        }
        let worse = self.gate.as_ref().is_some_and(|g| g.worse().is_some());
        out.push(match (self.saved, worse) {
            (true, true) => format!("model written to {p} although it predicts worse (--force)"),
            (true, false) => format!("model written to {p}"),
            (false, _) => format!("model not saved to {p} (--force saves it anyway)"),
        });
        out
    }

    /// The `"save"` object of `--json`.
    pub fn json(&self) -> Value {
        let g = self.gate.as_ref();
        json!({
            "path": self.path.display().to_string(),
            "saved": self.saved,
            "forced": self.forced,
            "worse": g.is_some_and(|g| g.worse().is_some()),
            "reason": g.map(Gate::sentence),
            "held_out_missing": g.and_then(|g| g.held_out_missing.clone()),
            "measures": g.map(|g| g.measures.iter().map(|m| json!({
                "measure": m.name, "words": m.words, "before": m.before, "after": m.after,
                "unit": m.unit, "change_pct": finite(m.change_pct),
            })).collect::<Vec<_>>()).unwrap_or_default(),
            "bar": bar_json(&MAX_WORSENING),
        })
    }
}

/// A bar (named threshold) as JSON.
pub(super) fn bar_json(b: &servo_core::compare::gate::Bar) -> Value {
    json!({ "name": b.name, "value": b.value, "unit": b.unit, "rule": b.rule, "why": b.why })
}

/// Judges the ladder's final model against `start` and writes it to `path` when it does not
/// predict worse, or when `force`.
#[allow(clippy::too_many_arguments)]
pub(super) fn gate_and_save(
    cmd: &Compare,
    path: &Path,
    model_file: &ModelFile,
    start: &Plant,
    plant: &Plant,
    records: &[Record],
    effects: &[AddEffect],
    ladder: &[LadderStep],
) -> anyhow::Result<SaveOutcome> {
    let g = match (ladder.first(), ladder.last()) {
        (Some(a), Some(b)) if !effects.is_empty() => {
            let (k, fa) = a.cmp_fit[0];
            let fb = b.cmp_fit[0].1;
            let refit: Vec<bool> = ladder.iter().skip(1).map(|s| s.base_refitted).collect();
            Some(gate(
                records,
                start,
                effects,
                &refit,
                fa.rmse,
                fb.rmse,
                k.unit(),
            ))
        }
        _ => None,
    };
    // On a linear axis the errors the gate compares are said in m (or m/s), not in rad of the
    // screw; the ratios the verdict rests on do not change.
    let g = g.map(|mut g| {
        if let Some(m) = model_file.transmission.metres_per_rad() {
            for x in g.measures.iter_mut() {
                let unit = match x.unit {
                    "rad" => "m",
                    "rad/s" => "m/s",
                    _ => continue,
                };
                x.before *= m;
                x.after *= m;
                x.unit = unit;
            }
        }
        g
    });
    let worse = g.as_ref().is_some_and(|g| g.worse().is_some());
    let saved = !worse || cmd.force;
    if saved {
        let mut mf = ModelFile::from_plant(plant);
        mf.sensors = model_file.sensors;
        mf.transmission = model_file.transmission;
        mf.drive = model_file.drive;
        let mut prov = model_file.provenance.clone().unwrap_or_default();
        prov.insert(
            "compare_model".into(),
            toml::Value::String(cmd.model.display().to_string()),
        );
        prov.insert(
            "compare_logs".into(),
            toml::Value::Array(
                cmd.logs
                    .iter()
                    .map(|p| toml::Value::String(p.display().to_string()))
                    .collect(),
            ),
        );
        if !cmd.add.is_empty() {
            prov.insert(
                "compare_added".into(),
                toml::Value::Array(
                    cmd.add
                        .iter()
                        .map(|s| toml::Value::String(s.clone()))
                        .collect(),
                ),
            );
        }
        if let Some(g) = g.as_ref().filter(|_| worse) {
            prov.insert("compare_forced".into(), toml::Value::String(g.sentence()));
        }
        mf.provenance = Some(prov);
        // The 95 % intervals of the fitted effect parameters: `servo run --ff` refuses to
        // compensate an effect whose size holds zero.
        if let Some(last) = ladder.last() {
            for p in &last.params {
                if let (Some(kind), Some(se)) = (p.effect, p.std_err) {
                    let half = 1.96 * se;
                    mf.set_interval(
                        &format!("{}.{}", kind.name(), p.key),
                        p.value - half,
                        p.value + half,
                    );
                }
            }
        }
        mf.limits = model_file.limits.clone();
        mf.save_over(path, &ModelFile::FRICTION_KINDS)?;
    }
    Ok(SaveOutcome {
        path: path.to_path_buf(),
        gate: g,
        saved,
        forced: cmd.force,
    })
}

/// The base parameters the ladder refitted besides the added effects, as one line (None when
/// nothing changed or nothing was added).
pub(super) fn refitted_line(start: &Plant, end: &Plant, ladder: &[LadderStep]) -> Option<String> {
    let r = refitted_base(start, end);
    if ladder.len() < 2 {
        return None;
    }
    if r.is_empty() || ladder.iter().skip(1).all(|s| !s.base_refitted) {
        return Some(String::from(
            "base parameters kept as given (refitting them with the effects predicted the logs worse)",
        ));
    }
    let parts: Vec<String> = r.iter().map(refitted_words).collect();
    Some(format!(
        "refitted with the effects (base parameters): {}",
        parts.join(", ")
    ))
}

fn refitted_words(r: &Refitted) -> String {
    let num = |v: f64| servo_core::math::sig(v, 5);
    format!(
        "{} {} -> {} {} ({})",
        r.key,
        num(r.before),
        num(r.after),
        r.unit,
        servo_core::math::change(r.before, r.after)
    )
}

/// The refitted base parameters as JSON rows.
pub(super) fn refitted_json(start: &Plant, end: &Plant) -> Value {
    Value::Array(
        refitted_base(start, end)
            .iter()
            .map(|r| json!({ "key": r.key, "unit": r.unit, "before": r.before, "after": r.after }))
            .collect(),
    )
}
