//! `--ff` with effects (issue #29): which linear feedforward terms and which of a model's
//! identified effects a run compensates, checked against the model before anything runs.
//!
//! `--ff` is a comma list of
//! * the linear terms of the handout's feedforward: `inertia` (J_eq and back-EMF), `friction`
//!   (B_eq and tau_sf), `viscous`, `coulomb`, `back_emf`;
//! * effect names of the registry (every catalogue effect but the linear ones): compensate
//!   that effect of the model file, as its effect file declares ([`servo_core::effects::Compensation`]);
//! * `all`: every linear term and every effect of the model that declares a compensation;
//! * `none`.
//!
//! An effect named but absent from the model, or one that declares no compensation (a gear
//! play), is refused with the reason; so is an effect whose fitted interval (the model file's
//! `[provenance.intervals]`, written by `compare --add --save`) holds zero for a parameter that
//! sizes it: its sign or size is doubtful, and compensating it could double the error.

use crate::error::{self as anyhow, bail};
use crate::model_file::ModelFile;
use servo_core::control::{EffectSelect, FeedforwardConfig, LoopCompensation};
use servo_core::effects::{AngleFrom, Compensation, EffectKind};
use servo_core::Plant;

/// What a run compensates, checked against the model.
#[derive(Debug, Clone, PartialEq)]
pub struct CompensationChoice {
    /// The linear feedforward terms.
    pub linear: FeedforwardConfig,
    /// The effects selected.
    pub select: EffectSelect,
    /// Each compensated effect and how, in registry order.
    pub compensated: Vec<(&'static str, String)>,
    /// Each effect of the model left out and why (with `all`: the effects that declare no
    /// compensation).
    pub left_out: Vec<(&'static str, String)>,
    /// The ramp-in time of the effects' compensation [s].
    pub ramp_s: f64,
    /// The user-defined effects compensated (names of the model's `[custom.*]` effects).
    pub custom: Vec<&'static str>,
}

/// How a compensation works, in words.
pub fn how(c: Compensation, e: &servo_core::effects::Effect) -> Option<String> {
    Some(match c {
        Compensation::Linear => return None,
        Compensation::Torque {
            angle: AngleFrom::Measured,
        } => "its torque at the measured angle".into(),
        Compensation::Torque {
            angle: AngleFrom::Reference,
        } => "its torque on the reference".into(),
        Compensation::DryFriction => {
            "the friction curve: its level at the measured speed, the reference speed's sign".into()
        }
        Compensation::InputInverse => "the inverse of its input map on the whole command".into(),
        Compensation::Limit => "the controller's limit narrowed to its bound".into(),
        Compensation::Lead => format!(
            "the feedforward read {} s ahead",
            servo_core::math::sig(e.kind.model().input_delay_s(e.values()), 3)
        ),
        Compensation::Not(why) => format!("not compensated: {why}"),
    })
}

impl CompensationChoice {
    /// Parses `--ff` `text` against the effects of `model` (`plant`: its plant), ramped in over
    /// `ramp_s` [s].
    pub fn parse(
        text: &str,
        model: &ModelFile,
        plant: &Plant,
        ramp_s: f64,
    ) -> anyhow::Result<CompensationChoice> {
        if !(ramp_s.is_finite() && ramp_s >= 0.0) {
            bail!("--ff-ramp: expected a time >= 0 s, got {ramp_s}");
        }
        let mut linear = FeedforwardConfig::OFF;
        linear.sign = FeedforwardConfig::FULL.sign;
        let mut select = EffectSelect::None;
        let mut custom: Vec<&'static str> = Vec::new();
        let mut left_out = Vec::new();
        for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            match item {
                "all" => {
                    linear = FeedforwardConfig::FULL;
                    select = EffectSelect::All;
                    for e in plant.custom.iter() {
                        match custom_refusal(model, e) {
                            None if !custom.contains(&e.name()) => custom.push(e.name()),
                            None => {}
                            Some(why) => left_out.push((e.name(), why)),
                        }
                    }
                }
                "none" => {
                    linear = FeedforwardConfig::OFF;
                    linear.sign = FeedforwardConfig::FULL.sign;
                    select = EffectSelect::None;
                    custom.clear();
                }
                // A linear term (`inertia`, `friction`, ...), as `parse_ff` reads it, else an
                // effect of the model.
                other => {
                    if let Ok(c) = crate::controller::parse_ff(other) {
                        linear.inertia |= c.inertia;
                        linear.viscous |= c.viscous;
                        linear.coulomb |= c.coulomb;
                        linear.back_emf |= c.back_emf;
                        continue;
                    }
                    if let Some(e) = plant.custom.get(other) {
                        if let Some(why) = custom_refusal(model, e) {
                            bail!(
                                "--ff {other}: the user-defined {other} is not compensated: {why}"
                            );
                        }
                        if !custom.contains(&e.name()) {
                            custom.push(e.name());
                        }
                        continue;
                    }
                    let Some(kind) = EffectKind::from_name(other) else {
                        bail!(
                            "--ff: unknown term `{other}`; use inertia, friction, viscous, coulomb, \
                             back_emf, all, none or an effect of the model ({})",
                            effect_names(plant)
                        );
                    };
                    if plant.effects.get(kind).is_none() {
                        bail!(
                            "--ff {other}: the model has no {other} to compensate (its effects: {}); \
                             add it first (`servo compare LOG --model M --add {other} --save M2`)",
                            effect_names(plant)
                        );
                    }
                    if let Compensation::Not(why) = kind.model().compensation() {
                        bail!("--ff {other}: {other} is not compensated: {why}");
                    }
                    select = select.with(kind);
                }
            }
        }
        let mut compensated = Vec::new();
        for e in plant.effects.iter() {
            let c = e.kind.model().compensation();
            if c == Compensation::Linear {
                continue;
            }
            let name = e.kind.name();
            if !select.selects(e.kind) {
                if !select.is_none() {
                    left_out.push((name, "not selected".to_string()));
                }
                continue;
            }
            if let Compensation::Not(why) = c {
                left_out.push((name, why.to_string()));
                continue;
            }
            if let Some(doubt) = doubtful(model, e) {
                bail!(
                    "--ff: {name} is not compensated: {doubt}; its sign or size is doubtful \
                     (refit it on more data, or leave it out: --ff without {name})"
                );
            }
            if let Some(words) = how(c, e) {
                compensated.push((name, words));
            }
        }
        for e in plant.custom.iter().filter(|e| custom.contains(&e.name())) {
            let words = match e.def.acts_on() {
                servo_core::custom::ActsOn::Input => {
                    "the numerical inverse of its input map on the whole command"
                }
                _ => "its torque expression on the reference state",
            };
            compensated.push((e.name(), format!("user-defined: {words}")));
        }
        Ok(CompensationChoice {
            linear,
            select,
            compensated,
            left_out,
            ramp_s,
            custom,
        })
    }

    /// The compensation of `plant` this choice makes.
    pub fn build(&self, plant: &Plant) -> anyhow::Result<LoopCompensation> {
        let c = LoopCompensation::new(plant, self.linear, self.select, self.ramp_s)
            .map_err(|e| crate::error::anyhow!("--ff: {e}"))?;
        Ok(if self.custom.is_empty() {
            c
        } else {
            c.with_custom(plant, &|n| self.custom.contains(&n))
        })
    }

    /// The `--ff` form of what runs: the linear terms, then the effects (`none` for nothing),
    /// e.g. `inertia,back_emf,viscous,coulomb,<effect>`.
    pub fn label(&self) -> String {
        let mut v = Vec::new();
        let lin = crate::controller::ff_name(&self.linear);
        if lin != "none" {
            v.extend(lin.split(',').map(str::to_string));
        }
        // (a dry friction named both as a linear term and as the model's effect once)
        for (n, _) in &self.compensated {
            if !v.iter().any(|x| x == n) {
                v.push(n.to_string());
            }
        }
        if v.is_empty() {
            "none".into()
        } else {
            v.join(",")
        }
    }

    /// The compensated effects' names, comma-separated (empty for none).
    pub fn effect_names(&self) -> String {
        self.compensated
            .iter()
            .map(|(n, _)| *n)
            .collect::<Vec<_>>()
            .join(",")
    }

    /// One line per effect: how it is compensated, or why not.
    pub fn lines(&self) -> Vec<String> {
        let mut out: Vec<String> = self
            .compensated
            .iter()
            .map(|(n, w)| format!("compensated: {n} ({w})"))
            .collect();
        out.extend(
            self.left_out
                .iter()
                .map(|(n, w)| format!("not compensated: {n} ({w})")),
        );
        if self.ramp_s > 0.0 && !self.compensated.is_empty() {
            out.push(format!(
                "the effects' compensation ramps in over {} s",
                servo_core::math::sig(self.ramp_s, 3)
            ));
        }
        out
    }
}

/// The effects of `plant` by name, comma-separated (`none`).
fn effect_names(plant: &Plant) -> String {
    let v: Vec<&str> = plant
        .effects
        .iter()
        .filter(|e| e.kind.model().compensation() != Compensation::Linear)
        .map(|e| e.kind.name())
        .collect();
    if v.is_empty() {
        "none".into()
    } else {
        v.join(", ")
    }
}

/// Why the user-defined effect `e` is not compensated: a sensor map (it changes what is
/// measured, not the motion), or a parameter whose 95 % interval in the model file holds zero.
fn custom_refusal(model: &ModelFile, e: &servo_core::custom::CustomActive) -> Option<String> {
    if e.def.acts_on() == servo_core::custom::ActsOn::Sensor {
        return Some(
            "a sensor map changes what is measured, not the motion (correct the measurement instead)"
                .into(),
        );
    }
    for p in e.def.params() {
        let key = format!("{}.{}", e.name(), p.key);
        if let Some((lo, hi)) = model.interval(&key) {
            if lo < 0.0 && hi > 0.0 {
                return Some(format!(
                    "the 95 % interval of {key} [{} .. {}] {} holds zero: its sign or size is doubtful",
                    servo_core::math::sig(lo, 3),
                    servo_core::math::sig(hi, 3),
                    p.unit
                ));
            }
        }
    }
    None
}

/// Why `e` is doubtful: a parameter that sizes it (linear in the torque or voltage) whose
/// interval in the model file holds zero. An angle (a periodic torque's phase, in rad) places
/// the effect, it does not size it: its interval may hold zero.
fn doubtful(model: &ModelFile, e: &servo_core::effects::Effect) -> Option<String> {
    for spec in e
        .kind
        .params()
        .iter()
        .filter(|s| !s.nonlinear && s.unit != "rad")
    {
        let key = format!("{}.{}", e.kind.name(), spec.key);
        if let Some((lo, hi)) = model.interval(&key) {
            if lo < 0.0 && hi > 0.0 {
                return Some(format!(
                    "the 95 % interval of {key} [{} .. {}] {} holds zero",
                    servo_core::math::sig(lo, 3),
                    servo_core::math::sig(hi, 3),
                    spec.unit
                ));
            }
        }
    }
    None
}
