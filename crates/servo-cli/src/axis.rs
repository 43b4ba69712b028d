//! A linear axis in the reports: the model's [`Transmission`] and gear ratio, turning the core's
//! equivalent rotation (J_eq, B_eq motor side, tau_sf and load-side effect torques) into the
//! mass [kg], viscous [N s/m], forces [N] and lengths [m] a user of a screw or belt axis reads
//! (the conversions are [`servo_core::transmission`]'s; this file only formats).

use crate::model_file::ModelFile;
use servo_core::effects::Effect;
use servo_core::transmission::{Transmission, TransmissionKind};

/// A linear axis: its transmission and the gear ratio N between motor and screw/pulley.
#[derive(Debug, Clone, Copy)]
pub struct Axis {
    pub transmission: Transmission,
    pub n: f64,
}

impl Axis {
    /// The axis of a model file; `None` for a rotary gear.
    pub fn of(model: &ModelFile) -> Option<Axis> {
        model.transmission.is_linear().then_some(Axis {
            transmission: model.transmission,
            n: model.params.n,
        })
    }

    /// Mass per motor-side inertia [kg per kg m^2] (also [N s/m] per [N m s/rad]).
    pub fn mass_per_j(&self) -> f64 {
        self.transmission.mass_kg(1.0, self.n).unwrap_or(f64::NAN)
    }

    /// Force per load-side torque [N per N m].
    pub fn force_per_tau(&self) -> f64 {
        self.transmission.force_n(1.0).unwrap_or(f64::NAN)
    }

    /// One line: `screw, lead 10 mm, N = 1, encoder on the motor`.
    pub fn describe(&self) -> String {
        let what = match self.transmission.kind {
            TransmissionKind::Screw { lead_m } => format!("screw, lead {} mm", lead_m * 1e3),
            TransmissionKind::Belt { radius_m } => {
                format!("belt/rack, radius {} mm", radius_m * 1e3)
            }
            TransmissionKind::Gear => "gear".to_string(),
        };
        format!(
            "linear axis: {what}, N = {}, encoder at the {} side",
            self.n,
            self.transmission.encoder.name()
        )
    }

    /// The `transmission` object of the JSON reports.
    pub fn json(&self) -> serde_json::Value {
        let mut v = serde_json::json!({
            "kind": self.transmission.kind_name(),
            "n": self.n,
            "encoder": self.transmission.encoder.name(),
            "metres_per_rad": self.transmission.metres_per_rad(),
        });
        match self.transmission.kind {
            TransmissionKind::Screw { lead_m } => v["lead_m"] = lead_m.into(),
            TransmissionKind::Belt { radius_m } => v["radius_m"] = radius_m.into(),
            TransmissionKind::Gear => {}
        }
        v
    }

    /// The base model in linear units: `(m_eq [kg], b_eq [N s/m], F_c [N])`.
    pub fn base(&self, j_eq: f64, b_eq: f64, tau_sf: f64) -> (f64, f64, f64) {
        (
            j_eq * self.mass_per_j(),
            b_eq * self.mass_per_j(),
            tau_sf * self.force_per_tau(),
        )
    }

    /// The base model as text lines (`m_eq = 5.02 kg ...`).
    pub fn base_text(&self, j_eq: f64, b_eq: f64, tau_sf: f64) -> String {
        let (m, b, f) = self.base(j_eq, b_eq, tau_sf);
        format!("  m_eq = {m:.4} kg, b_eq = {b:.4} N s/m, F_c = {f:.4} N at the load\n")
    }

    /// The base model's JSON keys (`m_eq_kg`, `b_eq_n_s_m`, `f_c_n`).
    pub fn base_json(&self, j_eq: f64, b_eq: f64, tau_sf: f64) -> serde_json::Value {
        let (m, b, f) = self.base(j_eq, b_eq, tau_sf);
        serde_json::json!({"m_eq_kg": m, "b_eq_n_s_m": b, "f_c_n": f})
    }

    /// An effect's parameters in linear units where they are load-side forces, stiffnesses,
    /// dampings, lengths or speeds, others as they are: `(key with unit suffix, value, unit)`.
    pub fn effect_params(&self, e: &Effect) -> Vec<(String, f64, String)> {
        let acts = e.kind.acts_on();
        e.iter()
            .map(
                |(p, v)| match self.transmission.linear_param(acts, p.key, p.unit, v) {
                    Some(l) => (
                        Transmission::linear_key(p.key, l.unit).as_str().to_string(),
                        l.value,
                        l.unit.to_string(),
                    ),
                    None => (p.key.to_string(), v, p.unit.to_string()),
                },
            )
            .collect()
    }

    /// [`Axis::effect_params`] as `key = value unit, ...`.
    pub fn effect_text(&self, e: &Effect) -> String {
        self.effect_params(e)
            .iter()
            .map(|(k, v, u)| format!("{k} = {} {u}", crate::cmd::design::sig6(*v)))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// [`Axis::effect_params`] as a JSON object.
    pub fn effect_json(&self, e: &Effect) -> serde_json::Value {
        let m: serde_json::Map<String, serde_json::Value> = self
            .effect_params(e)
            .into_iter()
            .map(|(k, v, _)| (k, v.into()))
            .collect();
        serde_json::Value::Object(m)
    }
}
