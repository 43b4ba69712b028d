//! The user-defined part of `servo diagnose`: user effects from `--effects` as candidates, and
//! `--discover` (see `servo_core::fit::discover`).

use crate::effects_file::{self, EffectsFile};
use anyhow::{anyhow, Context};
use serde_json::{json, Value};
use servo_core::custom::CustomActive;
use servo_core::diagnose::user_effects::{self, judge_user_effects};
use servo_core::diagnose::{DiagnoseOptions, Diagnosis};
use servo_core::fit::discover::Judged;
use servo_core::record::Record;
use servo_core::Plant;
use std::fmt::Write as _;
use std::path::Path;

/// What `--save-effect` did: the file, whether the discovered effect was written to it, and
/// why not.
pub struct SavedEffect {
    pub path: std::path::PathBuf,
    pub written: bool,
    pub why: Option<String>,
}

impl SavedEffect {
    /// One line for the text report.
    pub fn text(&self) -> String {
        match &self.why {
            None => format!("discovered effect written to {}", self.path.display()),
            Some(why) => format!("--save-effect {}: not written: {why}", self.path.display()),
        }
    }

    /// The `saved_effect` object of the diagnosis JSON.
    pub fn json(&self) -> Value {
        json!({ "path": self.path.display().to_string(), "written": self.written, "why": self.why })
    }
}

/// The user effects judged and what the discovery found (servo_core::diagnose::user_effects),
/// with their JSON, text and TOML.
pub struct UserFindings(pub user_effects::UserFindings);

impl std::ops::Deref for UserFindings {
    type Target = user_effects::UserFindings;
    fn deref(&self) -> &Self::Target {
        &self.0
    }
}

/// Judges the user effects of `library` the model lacks and, with `discover_on`, searches a new
/// one called `name`.
pub fn run(
    records: &[Record],
    model: &Plant,
    opts: &DiagnoseOptions,
    library: &EffectsFile,
    last: &Diagnosis,
    discover_on: bool,
    name: &str,
) -> anyhow::Result<UserFindings> {
    let todo: Vec<CustomActive> = library
        .defs
        .iter()
        .filter(|d| model.custom.get(d.name()).is_none())
        .map(|d| {
            let mut a = d.active();
            for v in a.values.iter_mut() {
                *v = f64::NAN;
            }
            a
        })
        .collect();
    if discover_on
        && (name.is_empty() || library.get(name).is_some() || model.custom.get(name).is_some())
    {
        return Err(anyhow!(
            "--effect-name `{name}`: choose a name no user effect has"
        ));
    }
    let found = judge_user_effects(
        records,
        model,
        opts,
        &todo,
        last,
        discover_on.then_some(name),
    )?;
    Ok(UserFindings(found))
}

fn judged_json(j: &Judged) -> Value {
    json!({
        "effect": j.name,
        "significant": j.significant,
        "equation": j.equation.name(),
        "bic_gain": j.bic_gain,
        "error_drop_pct": 100.0 * j.eq_drop,
        "oe_drop_pct": j.oe_drop.map(|d| 100.0 * d),
        "params": j.params.iter().map(|(k, u, v)| json!({"key": k, "unit": u, "value": v})).collect::<Vec<_>>(),
        "checks": j.checks.iter().map(|(n, p, d)| json!({"check": n, "passed": p, "detail": d})).collect::<Vec<_>>(),
    })
}

impl UserFindings {
    /// The discovered effect as an effects-file section.
    pub fn proposal_toml(&self) -> Option<String> {
        let d = self.discovery.as_ref()?;
        let (a, _) = d.proposal.as_ref()?;
        Some(effects_file::to_toml(&[(
            a.name().to_string(),
            effects_file::to_raw(a, Some(d.words())),
        )]))
    }

    /// Writes the discovered effect to `path`, as a new file or as a section added to an
    /// effects file already there; never replaces an effect of that file nor anything else.
    /// Nothing written (and why) when nothing was discovered or the file cannot take it: the
    /// diagnosis is reported either way. An error only when writing fails.
    pub fn save_effect(&self, path: &Path) -> anyhow::Result<SavedEffect> {
        let not = |why: String| {
            Ok(SavedEffect {
                path: path.to_path_buf(),
                written: false,
                why: Some(why),
            })
        };
        let Some(text) = self.proposal_toml() else {
            return not(format!(
                "nothing discovered to write ({})",
                self.discovery_skipped
                    .clone()
                    .unwrap_or_else(|| String::from("no term passed the gates"))
            ));
        };
        let name = self
            .discovery
            .as_ref()
            .and_then(|d| d.proposal.as_ref())
            .map(|(a, _)| a.name())
            .unwrap_or_default();
        let text = match std::fs::read_to_string(path) {
            Ok(old) => match EffectsFile::parse(&old) {
                Ok(lib) if lib.get(name).is_some() => {
                    return not(format!(
                        "{} already defines `{name}`: choose another --effect-name",
                        path.display()
                    ))
                }
                Ok(_) => format!("{}\n{text}", old.trim_end()),
                Err(e) => {
                    return not(format!(
                        "{} exists and is not an effects file ({e:#}): nothing is replaced",
                        path.display()
                    ))
                }
            },
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => text,
            Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
        };
        // The previous library is the new file's beginning: replaced, nothing lost.
        crate::io::output::write_file_with(
            path,
            "effects file",
            text,
            crate::io::output::Previous::Replace,
        )?;
        Ok(SavedEffect {
            path: path.to_path_buf(),
            written: true,
            why: None,
        })
    }

    /// Adds `custom_candidates` and `discovery` to the diagnosis JSON.
    pub fn add_json(&self, v: &mut Value) {
        v["custom_candidates"] = Value::Array(self.candidates.iter().map(judged_json).collect());
        if let Some(why) = &self.discovery_skipped {
            v["discovery"] = json!({ "ran": false, "why": why });
        }
        if let Some(d) = &self.discovery {
            let fitted = |key: &str| {
                d.proposal
                    .as_ref()
                    .and_then(|(a, _)| a.get(key))
                    .unwrap_or(f64::NAN)
            };
            v["discovery"] = json!({
                "ran": true,
                "equation": d.equation.name(),
                "name": d.proposal.as_ref().map(|(a, _)| a.name()),
                "expr": d.proposal.as_ref().map(|(a, _)| a.def.expr()),
                "words": d.words(),
                "significant": d.proposal.as_ref().map(|(_, j)| j.significant),
                "judged": d.proposal.as_ref().map(|(_, j)| judged_json(j)),
                "terms": d.terms.iter().map(|f| json!({
                    "signal_term": f.term.expr, "key": f.term.key, "unit": f.term.unit,
                    "words": f.term.words, "value": fitted(f.term.key), "regression_value": f.value,
                    "t": f.t, "practical_pct": 100.0 * f.practical, "halves": [f.halves.0, f.halves.1],
                })).collect::<Vec<_>>(),
                "rejected": d.rejected.iter().map(|(t, why)| json!({"signal_term": t.expr, "why": why})).collect::<Vec<_>>(),
                "toml": self.proposal_toml(),
            });
        }
    }

    /// The text section (empty when there is nothing to say).
    pub fn text(&self) -> String {
        let mut s = String::new();
        if !self.candidates.is_empty() {
            let _ = writeln!(s, "\nuser-defined effects:");
            for j in &self.candidates {
                let params: Vec<String> = j
                    .params
                    .iter()
                    .map(|(k, u, v)| format!("{k} = {v:.4e} {u}"))
                    .collect();
                let _ = writeln!(
                    s,
                    "  {:<12} {} ({} residual -{:.1} % held out{}): {}",
                    j.name,
                    if j.significant {
                        "significant"
                    } else {
                        "not significant"
                    },
                    j.equation.name(),
                    100.0 * j.eq_drop,
                    j.oe_drop
                        .map(|d| format!(", simulation -{:.1} %", 100.0 * d))
                        .unwrap_or_default(),
                    params.join(", ")
                );
                for (n, _, d) in j.checks.iter().filter(|c| !c.1) {
                    let _ = writeln!(s, "      failed {n}: {d}");
                }
            }
        }
        if let Some(why) = &self.discovery_skipped {
            let _ = writeln!(s, "\ndiscovery not run: {why}");
        }
        if let Some(d) = &self.discovery {
            let _ = writeln!(s, "\ndiscovery ({}):", d.equation.name());
            match &d.proposal {
                Some((_, j)) => {
                    let _ = writeln!(
                        s,
                        "  proposed: {} ({})",
                        d.words(),
                        if j.significant {
                            "passes every guard"
                        } else {
                            "fails a guard: treat with care"
                        }
                    );
                    for (n, p, det) in &j.checks {
                        let _ =
                            writeln!(s, "    [{}] {n}: {det}", if *p { "ok" } else { "failed" });
                    }
                    if let Some(t) = self.proposal_toml() {
                        let _ = writeln!(s, "  as a user-defined effect:\n");
                        for l in t.lines() {
                            let _ = writeln!(s, "    {l}");
                        }
                    }
                }
                None => {
                    let _ = writeln!(s, "  no term of the library explains the residual");
                }
            }
            for (t, why) in &d.rejected {
                let _ = writeln!(s, "  rejected `{}`: {why}", t.expr);
            }
        }
        s
    }
}
