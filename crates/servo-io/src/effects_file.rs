//! User-defined effects in TOML: the `[custom.NAME]` sections of a model file (active in the
//! model) or of an effects file (`--effects my_effects.toml`: definitions that `--add NAME` fits
//! and `diagnose` tries). See docs/custom-effects.md.
//!
//! ```toml
//! [custom.cable]
//! acts_on = "load_torque"            # load_torque [N m] | motor_torque [N m] | input [V] | sensor [rad]
//! expr = "k * (theta_l - theta0)"    # signals: theta_l theta_m omega_l omega_m i_a u t
//! description = "a cable pulling the arm back to theta0"   # optional
//! [custom.cable.params]
//! k = { value = 0.0, min = 0.0, unit = "N m/rad" }
//! theta0 = { value = 0.0, min = -1.0, max = 1.0, unit = "rad" }
//! ```

use crate::error::{self as anyhow, anyhow, Context};
use servo_core::custom::{ActsOn, CustomActive, CustomDef, ParamDecl, SIGNALS};
use std::collections::BTreeMap;
use std::path::Path;

/// One `[custom.NAME]` section as written.
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct RawCustom {
    pub acts_on: String,
    pub expr: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    #[serde(default)]
    pub params: BTreeMap<String, RawParam>,
}

/// One parameter: `{ value, min, max, unit }`.
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct RawParam {
    pub value: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub unit: String,
}

/// Compiles one section; errors name the section and what was expected.
pub fn compile(name: &str, raw: &RawCustom) -> anyhow::Result<&'static CustomDef> {
    let acts_on = ActsOn::from_name(raw.acts_on.trim()).ok_or_else(|| {
        anyhow!(
            "[custom.{name}] acts_on = {:?}: expected one of {}",
            raw.acts_on,
            ActsOn::ALL
                .iter()
                .map(|a| format!("\"{}\" [{}]", a.name(), a.unit()))
                .collect::<Vec<_>>()
                .join(", ")
        )
    })?;
    let decls: Vec<ParamDecl<'_>> = raw
        .params
        .iter()
        .map(|(k, p)| ParamDecl {
            key: k,
            unit: &p.unit,
            value: p.value,
            min: p.min,
            max: p.max,
        })
        .collect();
    CustomDef::new(name, acts_on, &raw.expr, &decls).map_err(|e| {
        anyhow!(
            "[custom.{name}]: {e}{}",
            if matches!(e, servo_core::custom::CustomError::Expr { .. }) {
                format!(
                    " (expr = {:?}; signals: {}; parameters: {})",
                    raw.expr,
                    SIGNALS.join(" "),
                    if raw.params.is_empty() {
                        String::from("none declared in [custom.NAME.params]")
                    } else {
                        raw.params.keys().cloned().collect::<Vec<_>>().join(" ")
                    }
                )
            } else {
                String::new()
            }
        )
    })
}

/// Compiles every section of a `custom` table.
pub fn compile_all(table: &BTreeMap<String, RawCustom>) -> anyhow::Result<Vec<&'static CustomDef>> {
    table.iter().map(|(n, r)| compile(n, r)).collect()
}

/// An effects file: `[custom.NAME]` sections only.
#[derive(Debug, Clone, Default, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    #[serde(default)]
    custom: BTreeMap<String, RawCustom>,
}

/// The user-defined effects of an effects file (`--effects`).
#[derive(Debug, Clone, Default)]
pub struct EffectsFile {
    pub defs: Vec<&'static CustomDef>,
}

impl EffectsFile {
    /// Reads and compiles `path`; errors name the file, the section and the column.
    pub fn load(path: &Path) -> anyhow::Result<EffectsFile> {
        let text = crate::text_file::read_text(path)
            .with_context(|| format!("reading effects file {}", path.display()))?;
        Self::parse(&text).with_context(|| format!("in effects file {}", path.display()))
    }

    /// Parses and compiles TOML text.
    pub fn parse(text: &str) -> anyhow::Result<EffectsFile> {
        let raw: RawFile =
            toml::from_str(text).map_err(|e| anyhow!("{}", crate::text_file::toml_error(&e)))?;
        if raw.custom.is_empty() {
            return Err(anyhow!(
                "no [custom.NAME] section: an effects file defines user effects (see docs/custom-effects.md)"
            ));
        }
        Ok(EffectsFile {
            defs: compile_all(&raw.custom)?,
        })
    }

    /// The definition called `name`.
    pub fn get(&self, name: &str) -> Option<&'static CustomDef> {
        self.defs.iter().copied().find(|d| d.name() == name)
    }

    /// Names, for messages.
    pub fn names(&self) -> String {
        self.defs
            .iter()
            .map(|d| d.name())
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Loads every effects file of `paths` into one library (a name defined twice is an error).
pub fn load_many(paths: &[std::path::PathBuf]) -> anyhow::Result<EffectsFile> {
    let mut lib = EffectsFile::default();
    for p in paths {
        let f = EffectsFile::load(p)?;
        for d in f.defs {
            if lib.get(d.name()).is_some() {
                anyhow::bail!(
                    "user effect `{}` is defined twice (again in {})",
                    d.name(),
                    p.display()
                );
            }
            lib.defs.push(d);
        }
    }
    Ok(lib)
}

/// The section describing `e` with its current values (NaN values written as the declared
/// value), for `--save` and `--save-effect`.
pub fn to_raw(e: &CustomActive, description: Option<String>) -> RawCustom {
    let params = e
        .def
        .params()
        .iter()
        .zip(e.values())
        .map(|(p, v)| {
            (
                p.key.to_string(),
                RawParam {
                    value: if v.is_finite() { *v } else { p.value },
                    min: p.min.is_finite().then_some(p.min),
                    max: p.max.is_finite().then_some(p.max),
                    unit: p.unit.to_string(),
                },
            )
        })
        .collect();
    RawCustom {
        acts_on: e.def.acts_on().name().to_string(),
        expr: e.def.expr().to_string(),
        description,
        params,
    }
}

/// TOML text of `[custom.NAME]` sections (with a comment per parameter).
pub fn to_toml(sections: &[(String, RawCustom)]) -> String {
    let mut s = String::new();
    for (name, r) in sections {
        s.push_str(&format!("[custom.{name}]\n"));
        if let Some(d) = &r.description {
            s.push_str(&format!("# {}\n", d.replace('\n', " ")));
        }
        s.push_str(&format!(
            "acts_on = {}\nexpr = {}\n",
            toml_str(&r.acts_on),
            toml_str(&r.expr)
        ));
        if let Some(d) = &r.description {
            s.push_str(&format!("description = {}\n", toml_str(d)));
        }
        s.push_str(&format!("[custom.{name}.params]\n"));
        for (k, p) in &r.params {
            let mut fields = vec![format!("value = {:e}", p.value)];
            if let Some(m) = p.min {
                fields.push(format!("min = {m:e}"));
            }
            if let Some(m) = p.max {
                fields.push(format!("max = {m:e}"));
            }
            if !p.unit.is_empty() {
                fields.push(format!("unit = {}", toml_str(&p.unit)));
            }
            s.push_str(&format!("{k} = {{ {} }}\n", fields.join(", ")));
        }
        s.push('\n');
    }
    s
}

fn toml_str(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[custom.cable]
acts_on = "load_torque"
expr = "k * (theta_l - theta0)"
[custom.cable.params]
k = { value = 0.0, min = 0.0, unit = "N m/rad" }
theta0 = { value = 0.0, min = -1.0, max = 1.0, unit = "rad" }
"#;

    #[test]
    fn loads_and_round_trips() {
        let f = EffectsFile::parse(GOOD).unwrap();
        let d = f.get("cable").unwrap();
        assert_eq!(d.acts_on(), ActsOn::LoadTorque);
        let text = to_toml(&[("cable".into(), to_raw(&d.active(), None))]);
        let back = EffectsFile::parse(&text).unwrap();
        assert!(std::ptr::eq(back.get("cable").unwrap(), d), "{text}");
    }

    #[test]
    fn errors_name_section_and_column() {
        let e = format!(
            "{:#}",
            EffectsFile::parse(&GOOD.replace("theta_l - theta0", "theta_x - theta0")).unwrap_err()
        );
        assert!(
            e.contains("[custom.cable]") && e.contains("theta_x") && e.contains("column 6"),
            "{e}"
        );
        let e = format!(
            "{:#}",
            EffectsFile::parse(&GOOD.replace("theta_l - theta0", "thet0")).unwrap_err()
        );
        assert!(e.contains("thet0") && e.contains("column 6"), "{e}");
        let e = format!(
            "{:#}",
            EffectsFile::parse(&GOOD.replace("(theta_l - theta0)", "(theta_l - theta0"))
                .unwrap_err()
        );
        assert!(e.contains("syntax error at column 22"), "{e}");
        let e = format!(
            "{:#}",
            EffectsFile::parse(&GOOD.replace("load_torque", "torque")).unwrap_err()
        );
        assert!(e.contains("acts_on") && e.contains("load_torque"), "{e}");
        let e = format!(
            "{:#}",
            EffectsFile::parse(&GOOD.replace("custom.cable", "custom.viscous")).unwrap_err()
        );
        assert!(e.contains("catalogue"), "{e}");
    }
}
