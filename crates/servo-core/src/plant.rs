//! A gearmotor model: linear parameters plus active effects.

use crate::custom::CustomSlots;
use crate::effects::{Effect, EffectKind, Effects};
use crate::params::{ParamError, PlantParams};

/// The model of one gearmotor: Table-2-style linear parameters and the active effects.
///
/// Friction is defined by the effects alone (`viscous` and the dry-friction effects of the
/// registry); [`Plant::from_params`] turns the parameters' B_eq and tau_sf into those effects, so that the
/// simulator, the model fit and the diagnosis read friction from one place.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plant {
    /// Electrical and inertial parameters (R, L, k_e, k_t, J, N, driver).
    pub params: PlantParams,
    /// Active effects, including the base friction.
    pub effects: Effects,
    /// Active user-defined effects ([`crate::custom`]).
    pub custom: CustomSlots,
}

impl Plant {
    /// A plant from parameters: `viscous` with b_eq = params.b_eq(), and `coulomb` with
    /// params.tau_sf when that is set.
    pub fn from_params(params: PlantParams) -> Result<Plant, ParamError> {
        params.validate()?;
        let mut effects = Effects::NONE;
        // Both values were validated finite and non-negative, so `new` cannot fail.
        if let Ok(v) = Effect::new(EffectKind::Viscous, &[params.b_eq()]) {
            effects.insert(v);
        }
        if let Some(tau_sf) = params.tau_sf {
            if let Ok(c) = Effect::new(EffectKind::Coulomb, &[tau_sf]) {
                effects.insert(c);
            }
        }
        Ok(Plant {
            params,
            effects,
            custom: CustomSlots::NONE,
        })
    }

    /// The nominal Table 2 plant (viscous friction 0, no Coulomb friction).
    pub fn nominal() -> Plant {
        Plant {
            params: PlantParams::TABLE2,
            effects: Effects::NONE,
            custom: CustomSlots::NONE,
        }
    }

    /// The realistic lab plant of [`PlantParams::LAB`]: viscous and Coulomb friction at the
    /// levels measured on real SRV-02s.
    pub fn lab() -> Plant {
        // LAB is a valid constant (unit test `lab_plant_has_its_friction`); Table 2 otherwise.
        Plant::from_params(PlantParams::LAB).unwrap_or_else(|_| Plant::nominal())
    }

    /// Viscous friction at motor side B_eq [N m s/rad] from the `viscous` effect (0 if absent).
    pub fn b_eq(&self) -> f64 {
        self.effects
            .value(EffectKind::Viscous, "b_eq")
            .unwrap_or(0.0)
    }

    /// Coulomb friction at load side tau_sf [N m] from the `coulomb` effect (0 if absent).
    pub fn tau_sf(&self) -> f64 {
        self.effects
            .value(EffectKind::Coulomb, "tau_sf")
            .unwrap_or(0.0)
    }

    /// The parameters with B_eq and tau_sf taken from the effects (for linear analysis: design,
    /// reduced model, feedforward).
    pub fn linear_params(&self) -> PlantParams {
        PlantParams {
            b_eq: Some(self.b_eq()),
            tau_sf: Some(self.tau_sf()),
            ..self.params
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lab_plant_has_its_friction() {
        let p = Plant::lab();
        assert_eq!(p.b_eq(), 1.0e-6);
        assert_eq!(p.tau_sf(), 9.0e-3);
        assert_eq!(p.params.j_eq(), 7.0e-7);
        assert_ne!(p, Plant::nominal());
    }
}
