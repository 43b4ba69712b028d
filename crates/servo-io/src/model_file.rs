//! The model file (TOML): plant parameters, active effects, simulator sensors and provenance.
//!
//! One format serves `--params`, `--plant` (the simulator's truth), `--model` (compare/diagnose)
//! and the output of `identify` and `compare --save`:
//!
//! ```toml
//! [params]            # every Table 2 key is required; j_eq, b_eq, tau_sf are optional overrides
//! r_a = 2.6           # ohm
//! ...
//! [effects.<name>]    # registered effects, keys as in the registry (SI units)
//! gap = 0.04
//! [sensors]           # optional, simulator only
//! counts_per_rev = 4096
//! [provenance]        # optional, free-form: where identified values came from
//! ```

use crate::error::{self as anyhow, anyhow, bail, Context};
use servo_core::custom::CustomSlots;
use servo_core::effects::{Effect, EffectKind, Effects};
use servo_core::sim::SensorConfig;
use servo_core::{Plant, PlantParams};
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Debug, Clone, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    params: PlantParams,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    effects: BTreeMap<String, BTreeMap<String, f64>>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    custom: BTreeMap<String, crate::effects_file::RawCustom>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    sensors: Option<SensorConfig>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    provenance: Option<toml::Table>,
}

/// A parsed and validated model file. With serde it (de)serialises as the file's tables
/// (`[params]`, `[effects.<name>]`, ...), validated on the way in as [`ModelFile::parse`] does.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "Raw", into = "Raw")]
pub struct ModelFile {
    pub params: PlantParams,
    /// Effects listed in the file (in addition to the friction implied by the params).
    pub effects: Effects,
    /// User-defined effects (`[custom.NAME]`, see [`crate::effects_file`]), active in the model.
    pub custom: CustomSlots,
    pub sensors: Option<SensorConfig>,
    /// Free-form provenance (log, method, date, ...).
    pub provenance: Option<toml::Table>,
}

impl TryFrom<Raw> for ModelFile {
    type Error = crate::Error;
    fn try_from(raw: Raw) -> crate::Result<ModelFile> {
        ModelFile::from_raw(raw)
    }
}

impl From<ModelFile> for Raw {
    fn from(m: ModelFile) -> Raw {
        m.to_raw()
    }
}

impl Default for ModelFile {
    /// Table 2, no effects.
    fn default() -> Self {
        ModelFile {
            params: PlantParams::TABLE2,
            effects: Effects::NONE,
            custom: CustomSlots::NONE,
            sensors: None,
            provenance: None,
        }
    }
}

impl ModelFile {
    /// Reads and validates `path`; errors name the file, the key and what was expected.
    pub fn load(path: &Path) -> anyhow::Result<ModelFile> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading model file {}", path.display()))?;
        Self::parse(&text).with_context(|| format!("in model file {}", path.display()))
    }

    /// Parses and validates TOML text.
    pub fn parse(text: &str) -> anyhow::Result<ModelFile> {
        let raw: Raw = toml::from_str(text).map_err(|e| anyhow!("{}", e.to_string().trim_end()))?;
        Self::from_raw(raw)
    }

    /// Validates the deserialised file: parameters, effect names and keys, complete effects.
    fn from_raw(raw: Raw) -> anyhow::Result<ModelFile> {
        raw.params
            .validate()
            .map_err(|e| anyhow!("[params]: {e}"))?;
        // One value per quantity: the friction of [params] and the friction effects are the same
        // quantities (the effect would silently override the params).
        for (key, given, section) in [
            ("b_eq", raw.params.b_eq, EffectKind::Viscous),
            ("tau_sf", raw.params.tau_sf, EffectKind::Coulomb),
        ] {
            let other = raw
                .effects
                .get(section.name())
                .and_then(|kv| kv.get(key).map(|v| (section.name(), *v)));
            if let (Some(a), Some((name, b))) = (given, other) {
                bail!(
                    "{key} is given twice: [params] {key} = {a:e} and [effects.{name}] {key} = {b:e}; \
                     a model file holds each quantity once: keep one of the two"
                );
            }
        }
        let mut effects = Effects::NONE;
        for (name, kv) in &raw.effects {
            let kind = EffectKind::from_name(name).ok_or_else(|| {
                anyhow!(
                    "[effects.{name}]: unknown effect; the registry has {}",
                    servo_core::effects::RegisteredNames
                )
            })?;
            let mut e = Effect::unset(kind);
            for (k, v) in kv {
                e.set(k, *v)
                    .map_err(|err| anyhow!("[effects.{name}]: {err}"))?;
            }
            e.check_complete()
                .map_err(|err| anyhow!("[effects.{name}]: {err}"))?;
            effects.insert(e);
        }
        let mut custom = CustomSlots::NONE;
        for def in crate::effects_file::compile_all(&raw.custom)? {
            custom
                .insert(def.active())
                .map_err(|e| anyhow!("[custom.{}]: {e}", def.name()))?;
        }
        Ok(ModelFile {
            params: raw.params,
            effects,
            custom,
            sensors: raw.sensors,
            provenance: raw.provenance,
        })
    }

    /// The plant: friction from the params (B_eq, tau_sf), then the file's effects on top (an
    /// explicit `[effects.viscous]` or `[effects.coulomb]` replaces the params' value).
    pub fn plant(&self) -> anyhow::Result<Plant> {
        let mut plant = Plant::from_params(self.params).map_err(|e| anyhow!("[params]: {e}"))?;
        for e in self.effects.iter() {
            plant.effects.insert(*e);
        }
        plant.custom = self.custom;
        Ok(plant)
    }

    /// A model file describing `plant` (friction written as effects).
    pub fn from_plant(plant: &Plant) -> ModelFile {
        ModelFile {
            params: plant.params,
            effects: plant.effects,
            custom: plant.custom,
            sensors: None,
            provenance: None,
        }
    }

    /// Serialises to TOML (machine form).
    pub fn to_toml(&self) -> anyhow::Result<String> {
        Ok(toml::to_string(&self.to_raw())?)
    }

    /// The params as written: B_eq and tau_sf of the friction effects go to `[params]` (one
    /// place per quantity), and those effects are not written again as sections.
    fn written_params(&self) -> PlantParams {
        let mut p = self.params;
        if let Some(b) = self.effects.value(EffectKind::Viscous, "b_eq") {
            // A B_eq equal to the one implied by B_m and B_l stays implied.
            if p.b_eq.is_some() || b != p.b_eq() {
                p.b_eq = Some(b);
            }
        }
        if let Some(t) = self.effects.value(EffectKind::Coulomb, "tau_sf") {
            p.tau_sf = Some(t);
        }
        p
    }

    /// Is effect `kind` written as params (the friction effects)?
    fn in_params(kind: EffectKind) -> bool {
        matches!(kind, EffectKind::Viscous | EffectKind::Coulomb)
    }

    /// The serialisable form: effects as tables of catalogue keys.
    fn to_raw(&self) -> Raw {
        let mut effects = BTreeMap::new();
        for e in self.effects.iter().filter(|e| !Self::in_params(e.kind)) {
            let kv: BTreeMap<String, f64> = e.iter().map(|(p, v)| (p.key.to_string(), v)).collect();
            effects.insert(e.kind.name().to_string(), kv);
        }
        let custom = self
            .custom
            .iter()
            .map(|c| (c.name().to_string(), crate::effects_file::to_raw(c, None)))
            .collect();
        Raw {
            params: self.written_params(),
            effects,
            custom,
            sensors: self.sensors,
            provenance: self.provenance.clone(),
        }
    }

    /// Writes the file.
    pub fn save(&self, path: &Path) -> anyhow::Result<()> {
        let text = self.to_toml_commented();
        std::fs::write(path, text).with_context(|| format!("writing model file {}", path.display()))
    }

    /// TOML with units and meanings in comments (what `servo params` prints).
    pub fn to_toml_commented(&self) -> String {
        let written = self.written_params();
        let p = &written;
        let mut s = String::from(
            "# servo model file: DC gearmotor parameters (handout Table 2), SI units.\n\
             # Motor side / load side as in the handout: omega_l = omega_m / N.\n\n[params]\n",
        );
        let rows: [(&str, f64, &str); 13] = [
            ("r_a", p.r_a, "armature resistance R_a [ohm]"),
            ("l_a", p.l_a, "armature inductance L_a [H]"),
            ("k_e", p.k_e, "electric (BEMF) constant k_e [V s/rad]"),
            ("k_t", p.k_t, "torque constant k_t [N m/A]"),
            ("j_m", p.j_m, "rotor moment of inertia J_m [kg m^2]"),
            ("b_m", p.b_m, "rotor viscous friction B_m [N m s/rad]"),
            ("n", p.n, "gearbox ratio N [-]"),
            (
                "j_72",
                p.j_72,
                "inertia of one external 72-tooth gear J_72 [kg m^2] (3 fitted)",
            ),
            ("j_d", p.j_d, "inertia of the extra disc J_d [kg m^2]"),
            ("b_l", p.b_l, "load viscous friction B_l [N m s/rad]"),
            ("k_drv", p.k_drv, "voltage driver static gain k_drv [V/V]"),
            (
                "f_c_drv",
                p.f_c_drv,
                "voltage driver cut-off frequency f_c,drv [Hz]",
            ),
            ("r_s", p.r_s, "shunt resistance R_s [ohm]"),
        ];
        for (k, v, doc) in rows {
            s.push_str(&format!("{k} = {v:e}  # {doc}\n"));
        }
        let opt: [(&str, Option<f64>, &str); 3] = [
            ("j_eq", p.j_eq, "identified total inertia at motor side J_eq [kg m^2] (overrides J_m + J_l/N^2)"),
            ("b_eq", p.b_eq, "identified viscous friction at motor side B_eq [N m s/rad] (overrides B_m + B_l/N^2)"),
            ("tau_sf", p.tau_sf, "identified Coulomb friction at load side tau_sf [N m]"),
        ];
        for (k, v, doc) in opt {
            match v {
                Some(v) => s.push_str(&format!("{k} = {v:e}  # {doc}\n")),
                None => s.push_str(&format!("# {k} = ...  # {doc}\n")),
            }
        }
        for e in self.effects.iter().filter(|e| !Self::in_params(e.kind)) {
            s.push_str(&format!(
                "\n[effects.{}]  # {}\n",
                e.kind.name(),
                e.kind.description()
            ));
            for (spec, v) in e.iter() {
                s.push_str(&format!(
                    "{} = {:e}  # {} [{}]\n",
                    spec.key, v, spec.doc, spec.unit
                ));
            }
        }
        if !self.custom.is_empty() {
            s.push_str("\n# user-defined effects (docs/custom-effects.md)\n");
            let sections: Vec<(String, crate::effects_file::RawCustom)> = self
                .custom
                .iter()
                .map(|c| (c.name().to_string(), crate::effects_file::to_raw(c, None)))
                .collect();
            s.push_str(&crate::effects_file::to_toml(&sections));
        }
        if let Some(sn) = &self.sensors {
            s.push_str(&format!(
                "\n[sensors]  # simulator only\ncounts_per_rev = {}  # encoder counts per load revolution\n\
                 current_noise_a = {:e}  # current sensor noise std [A]\ncurrent_offset_a = {:e}  # current sensor offset [A]\nseed = {}  # noise seed\n",
                sn.counts_per_rev, sn.current_noise_a, sn.current_offset_a, sn.seed
            ));
        }
        if let Some(pv) = &self.provenance {
            s.push_str("\n[provenance]\n");
            s.push_str(&toml::to_string(pv).unwrap_or_default());
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_file_round_trips() {
        let text = ModelFile::default().to_toml_commented();
        let back = ModelFile::parse(&text).unwrap();
        assert_eq!(back, ModelFile::default());
    }

    #[test]
    fn serde_round_trip_validates() {
        let mut m = ModelFile::default();
        m.effects
            .insert(Effect::new(EffectKind::Delay, &[0.003]).unwrap());
        let json = serde_json::to_string(&m).unwrap();
        // (effects compare by their TOML: unused parameter slots hold NaN)
        let back: ModelFile = serde_json::from_str(&json).unwrap();
        assert_eq!(back.to_toml().unwrap(), m.to_toml().unwrap());
        let bad = json.replace("\"r_a\":2.6", "\"r_a\":-2.6");
        assert!(serde_json::from_str::<ModelFile>(&bad).is_err(), "{bad}");
    }

    #[test]
    fn keys_with_unit_suffixes_of_the_json_outputs_are_read() {
        let good = ModelFile::default().to_toml_commented();
        let suffixed = good
            .replace("r_a =", "r_a_ohm =")
            .replace("# b_eq = ...", "b_eq_n_m_s_rad = 4.6e-6");
        let m = ModelFile::parse(&suffixed).unwrap();
        assert_eq!(m.params.r_a, ModelFile::default().params.r_a);
        assert_eq!(m.params.b_eq, Some(4.6e-6));
        // both spellings of one key are refused, not silently resolved
        let both = good.replace("r_s =", "r_a_ohm = 2.6\nr_s =");
        assert!(ModelFile::parse(&both).is_err());
    }

    #[test]
    fn each_quantity_is_written_once_and_a_file_with_one_twice_is_refused() {
        let plant = Plant::from_params(PlantParams {
            b_eq: Some(1.1e-6),
            tau_sf: Some(8.0e-3),
            ..PlantParams::TABLE2
        })
        .unwrap();
        let mut m = ModelFile::from_plant(&plant);
        m.effects
            .insert(Effect::new(EffectKind::Coulomb, &[7.0e-3]).unwrap());
        for text in [m.to_toml_commented(), m.to_toml().unwrap()] {
            assert!(!text.contains("[effects.coulomb]") && !text.contains("[effects.viscous]"));
            let back = ModelFile::parse(&text).unwrap().plant().unwrap();
            // The effect's value is the one the plant used: it is the one written.
            assert_eq!(back.tau_sf(), 7.0e-3, "{text}");
            assert_eq!(back.b_eq(), 1.1e-6);
        }
        let good = m.to_toml_commented();
        for (section, key) in [("coulomb", "tau_sf"), ("viscous", "b_eq")] {
            let bad = format!("{good}\n[effects.{section}]\n{key} = 1e-3\n");
            let e = ModelFile::parse(&bad).unwrap_err().to_string();
            assert!(
                e.contains(&format!("[params] {key}"))
                    && e.contains(&format!("[effects.{section}] {key}")),
                "{e}"
            );
        }
        // One place only (an older file's effects without the params' key) is read.
        let only_effect =
            good.replace("tau_sf = 7e-3", "") + "\n[effects.coulomb]\ntau_sf = 5e-3\n";
        let back = ModelFile::parse(&only_effect).unwrap().plant().unwrap();
        assert_eq!(back.tau_sf(), 5e-3);
    }

    #[test]
    fn rejects_bad_files_naming_the_key() {
        let good = ModelFile::default().to_toml_commented();
        let unknown = good.replace("r_s =", "r_x =");
        let e = format!("{:#}", ModelFile::parse(&unknown).unwrap_err());
        assert!(e.contains("r_x"), "{e}");
        let negative = good.replace("j_m = 3.9e-7", "j_m = -3.9e-7");
        let e = format!("{:#}", ModelFile::parse(&negative).unwrap_err());
        assert!(e.contains("j_m"), "{e}");
        let missing: String = good
            .lines()
            .filter(|l| !l.starts_with("k_t"))
            .map(|l| format!("{l}\n"))
            .collect();
        let e = format!("{:#}", ModelFile::parse(&missing).unwrap_err());
        assert!(e.contains("k_t"), "{e}");
        let wrong_type = good.replace("n = 1.4e1", "n = \"fourteen\"");
        let e = format!("{:#}", ModelFile::parse(&wrong_type).unwrap_err());
        assert!(e.contains('n'), "{e}");
        let bad_effect = format!("{good}\n[effects.delay]\ndelayy = 0.1\n");
        let e = format!("{:#}", ModelFile::parse(&bad_effect).unwrap_err());
        assert!(e.contains("delayy") && e.contains("delay [s]"), "{e}");
    }
}
