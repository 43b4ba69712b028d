//! `servo identify`: the library's settings from the flags.

use super::*;

impl Identify {
    /// The simulated motor's file of `--ramp --plant FILE` on the simulator (None otherwise).
    pub(super) fn ramp_plant(&self) -> Option<&std::path::Path> {
        (self.ramp && self.ramp_args.backend == crate::cmd::run::BackendKind::Sim)
            .then_some(self.ramp_args.plant.plant.as_deref())
            .flatten()
    }

    /// The library's settings from the flags.
    pub(super) fn options(&self) -> IdentifyOptions {
        IdentifyOptions {
            method: self.method.map(|m| match m {
                Method::Friction => auto::Method::Friction,
                Method::Inertia => auto::Method::Inertia,
                Method::Combined => auto::Method::Combined,
                Method::Electrical => auto::Method::Electrical,
            }),
            inertia_method: match self.inertia_method {
                InertiaMethod::Phases => auto::InertiaMethod::Phases,
                InertiaMethod::Ls => auto::InertiaMethod::Ls,
            },
            friction: FrictionConfig {
                samples: self.samples,
                ..FrictionConfig::default()
            },
            phases: PhaseConfig {
                cutoff_hz: self.cutoff_hz,
                min_accel_rad_s2: self.min_accel,
                window_frac: self.phase_window,
                ..PhaseConfig::default()
            },
            combined: CombinedConfig {
                cutoff_hz: self.cutoff_hz,
                ..CombinedConfig::default()
            },
        }
    }
}

/// Parses `--phase-window FROM,TO` (fractions of a phase, 0 <= FROM < TO <= 1).
pub(super) fn parse_window(s: &str) -> Result<(f64, f64), String> {
    let err =
        || format!("expected FROM,TO with 0 <= FROM < TO <= 1 (fractions of a phase), got `{s}`");
    let (a, b) = s.split_once(',').ok_or_else(err)?;
    let a: f64 = a.trim().parse().map_err(|_| err())?;
    let b: f64 = b.trim().parse().map_err(|_| err())?;
    if (0.0..1.0).contains(&a) && a < b && b <= 1.0 {
        Ok((a, b))
    } else {
        Err(err())
    }
}
