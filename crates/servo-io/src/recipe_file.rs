//! The recipes of the identification experiments (`servo identify --ramp`, handout 4.1 and 4.2)
//! and the load-speed profiles they become:
//!
//! * friction (4.1): a closed-loop speed staircase (`experiments/identify_friction.toml`, built
//!   in; a file may override it);
//! * inertia (4.2): constant acceleration/deceleration ramps (`experiments/identify_inertia.toml`,
//!   likewise).
//!
//! The recipes give motor speeds (as the handout's tables do); the profiles are at the load.

use crate::error::{self as anyhow, bail, Context};
use servo_core::control::SpeedProfile;
use std::path::Path;

/// Friction staircase recipe.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrictionRecipe {
    /// Constant motor speeds [rad/s].
    pub speeds_rad_s: Vec<f64>,
    /// Time at each speed [s].
    pub step_duration_s: f64,
    /// Positive then negative staircase.
    #[serde(default = "yes")]
    pub both_directions: bool,
    /// Rest before each direction [s].
    #[serde(default = "one")]
    pub rest_s: f64,
}

/// Inertia ramps recipe.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InertiaRecipe {
    /// Acceleration magnitude [rad/s^2].
    pub accel_rad_s2: f64,
    /// Peak motor speed [rad/s].
    pub peak_speed_rad_s: f64,
    /// Lowest motor speed of a cycle [rad/s].
    #[serde(default)]
    pub base_speed_rad_s: f64,
    /// Up/down cycles.
    pub cycles: u32,
    /// Rest before the first cycle [s].
    #[serde(default = "half")]
    pub rest_s: f64,
}

fn yes() -> bool {
    true
}
fn one() -> f64 {
    1.0
}
fn half() -> f64 {
    0.5
}

/// The built-in friction recipe (experiments/identify_friction.toml at build time).
pub const FRICTION_RECIPE: &str = include_str!("../../../experiments/identify_friction.toml");
/// The built-in inertia recipe (experiments/identify_inertia.toml at build time).
pub const INERTIA_RECIPE: &str = include_str!("../../../experiments/identify_inertia.toml");
/// How the built-in recipes are named in messages and log metadata (as a path: `built-in`).
pub const BUILT_IN: &str = "built-in";

fn load_toml<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> anyhow::Result<T> {
    let text = if path == Path::new(BUILT_IN) {
        match what {
            "friction" => FRICTION_RECIPE.to_string(),
            _ => INERTIA_RECIPE.to_string(),
        }
    } else {
        crate::text_file::read_text(path)
            .with_context(|| format!("reading {what} recipe {}", path.display()))?
    };
    toml::from_str(&text)
        .map_err(|e| crate::Error::Invalid(crate::text_file::toml_error(&e)))
        .with_context(|| format!("in {what} recipe {}", path.display()))
}

impl FrictionRecipe {
    /// Reads and checks a friction recipe (the path [`BUILT_IN`]: the built-in one).
    pub fn load(path: &Path) -> anyhow::Result<FrictionRecipe> {
        let r: FrictionRecipe = load_toml(path, "friction")?;
        if r.speeds_rad_s.is_empty() || r.speeds_rad_s.iter().any(|w| !(w.is_finite() && *w > 0.0))
        {
            bail!(
                "{}: speeds_rad_s must be a non-empty list of positive motor speeds [rad/s]",
                path.display()
            );
        }
        if !(r.step_duration_s >= 1.0 && r.step_duration_s.is_finite()) {
            bail!(
                "{}: step_duration_s must be >= 1 s (the estimator needs settled segments), got {}",
                path.display(),
                r.step_duration_s
            );
        }
        if !(r.rest_s >= 0.0 && r.rest_s.is_finite()) {
            bail!(
                "{}: rest_s must be >= 0 s, got {}",
                path.display(),
                r.rest_s
            );
        }
        Ok(r)
    }
    /// Length of the staircase [s].
    pub fn duration_s(&self) -> f64 {
        let one_dir = self.rest_s + self.step_duration_s * self.speeds_rad_s.len() as f64;
        one_dir * if self.both_directions { 2.0 } else { 1.0 }
    }
    /// The staircase as a load-speed profile for gear ratio `n` (the recipe's speeds are at
    /// the motor): a rest, then each speed for `step_duration_s`; then the same negative.
    pub fn profile(&self, n: f64) -> anyhow::Result<SpeedProfile> {
        let mut p = SpeedProfile::new();
        let signs: &[f64] = if self.both_directions {
            &[1.0, -1.0]
        } else {
            &[1.0]
        };
        for sign in signs {
            if self.rest_s > 0.0 {
                p.hold(self.rest_s, 0.0)?;
            }
            for w in &self.speeds_rad_s {
                p.hold(self.step_duration_s, sign * w / n)?;
            }
        }
        Ok(p)
    }
}

impl InertiaRecipe {
    /// Reads and checks an inertia recipe (the path [`BUILT_IN`]: the built-in one).
    pub fn load(path: &Path) -> anyhow::Result<InertiaRecipe> {
        let r: InertiaRecipe = load_toml(path, "inertia")?;
        if !(r.accel_rad_s2 > 0.0 && r.accel_rad_s2.is_finite()) {
            bail!(
                "{}: accel_rad_s2 must be > 0 rad/s^2, got {}",
                path.display(),
                r.accel_rad_s2
            );
        }
        if !(r.peak_speed_rad_s > r.base_speed_rad_s
            && r.base_speed_rad_s >= 0.0
            && r.peak_speed_rad_s.is_finite())
        {
            bail!(
                "{}: need 0 <= base_speed_rad_s < peak_speed_rad_s",
                path.display()
            );
        }
        if r.cycles < 2 {
            bail!("{}: cycles must be >= 2 (eq. 69 averages over pairs; one pair gives no uncertainty)", path.display());
        }
        Ok(r)
    }
    /// Length of the ramps [s] (rest, run-up to the base speed, cycles).
    pub fn duration_s(&self) -> f64 {
        let half = (self.peak_speed_rad_s - self.base_speed_rad_s) / self.accel_rad_s2;
        self.rest_s + self.base_speed_rad_s / self.accel_rad_s2 + 2.0 * half * self.cycles as f64
    }
    /// The ramps as a load-speed profile for gear ratio `n` (the recipe's speeds are at the
    /// motor): a rest, a run-up to the base speed at the same acceleration, then the cycles
    /// base -> peak -> base.
    pub fn profile(&self, n: f64) -> anyhow::Result<SpeedProfile> {
        let mut p = SpeedProfile::new();
        if self.rest_s > 0.0 {
            p.hold(self.rest_s, 0.0)?;
        }
        let (base, peak) = (self.base_speed_rad_s / n, self.peak_speed_rad_s / n);
        if self.base_speed_rad_s > 0.0 {
            p.ramp(self.base_speed_rad_s / self.accel_rad_s2, 0.0, base)?;
        }
        let half = (self.peak_speed_rad_s - self.base_speed_rad_s) / self.accel_rad_s2;
        for _ in 0..self.cycles {
            p.ramp(half, base, peak)?;
            p.ramp(half, peak, base)?;
        }
        Ok(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn staircase_profile_steps_through_the_speeds() {
        let r = FrictionRecipe {
            speeds_rad_s: vec![10.0, 20.0],
            step_duration_s: 2.0,
            both_directions: true,
            rest_s: 1.0,
        };
        // Motor speeds in the recipe, load speeds in the profile (N = 10).
        let p = r.profile(10.0).unwrap();
        assert_eq!(p.duration_s(), r.duration_s());
        assert_eq!(p.at(0.5), (0.0, 0.0));
        assert_eq!(p.at(1.5), (1.0, 0.0));
        assert_eq!(p.at(3.5), (2.0, 0.0));
        assert_eq!(p.at(5.5), (0.0, 0.0));
        assert_eq!(p.at(6.5), (-1.0, 0.0));
        assert_eq!(p.at(10.0), (0.0, 0.0));
    }

    #[test]
    fn ramps_profile_is_a_triangle() {
        let r = InertiaRecipe {
            accel_rad_s2: 100.0,
            peak_speed_rad_s: 100.0,
            base_speed_rad_s: 20.0,
            cycles: 2,
            rest_s: 0.5,
        };
        let p = r.profile(1.0).unwrap();
        assert!((p.duration_s() - r.duration_s()).abs() < 1e-12);
        assert_eq!(p.at(0.25), (0.0, 0.0));
        let close = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).abs() < 1e-9 && a.1 == b.1;
        assert!(close(p.at(0.6), (10.0, 100.0))); // run-up to the base speed
        assert!(close(p.at(1.0), (50.0, 100.0)));
        assert!(close(p.at(1.8), (70.0, -100.0)));
        assert!(close(p.at(2.5), (40.0, 100.0)));
        assert_eq!(p.at(4.0), (0.0, 0.0));
    }
}
