//! The effect catalogue: every physical mechanism servo knows, defined once.
//!
//! The simulator uses it as truth, `compare --add` fits it to data and `diagnose` searches it. Names
//! and parameter keys are fixed: users type them (`--plant-effect backlash:gap=0.04`, TOML
//! `[effects.backlash] gap = 0.04`). Units are SI; "motor side" and "load side" as in the handout.
//!
//! | effect | parameters |
//! |---|---|
//! | `viscous` | `b_eq` N m s/rad, motor side |
//! | `coulomb` | `tau_sf` N m, load side (eq. 8) |
//! | `stribeck` | `tau_s` breakaway torque N m, load side (> tau_sf); `omega_s` Stribeck speed rad/s, load side |
//! | `asymmetry` | `tau_sf_pos`, `tau_sf_neg` N m, load side: direction-dependent Coulomb friction |
//! | `backlash` | `gap` rad at the load; `stiffness` N m/rad and `damping` N m s/rad of the contact (load side); `load_inertia_fraction` of J_eq on the load side of the gap |
//! | `cogging` | `amplitude` N m at the motor, `harmonic` cycles per motor revolution, `phase` rad |
//! | `imbalance` | `amplitude` N m at the load, `phase` rad: torque periodic in load angle |
//! | `saturation` | `limit` V on the driver input u (symmetric) |
//! | `deadzone` | `width` V: dead band (half width) on the driver input u |
//! | `delay` | `delay` s: input transport delay beyond the one-sample zero-order hold |
//!
//! The physics of every effect (torque versus speed or angle, input nonlinearity u -> u_in) is
//! defined once in [`torque`], used by the simulator and as regressors by the fit and diagnosis.

pub mod torque;

use core::fmt;

/// One parameter of a catalogue effect.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamSpec {
    /// Key as typed by users (`gap`, `tau_sf`, ...).
    pub key: &'static str,
    /// SI unit of the value.
    pub unit: &'static str,
    /// What it is, in a few words.
    pub doc: &'static str,
    /// Value used when the user gives none and the fit does not estimate it; `None`: required.
    pub default: Option<f64>,
    /// Smallest physically meaningful value (inclusive).
    pub min: f64,
    /// True when the effect's torque or voltage is not linear in this parameter (it needs a
    /// search, not a regression).
    pub nonlinear: bool,
}

const fn spec(
    key: &'static str,
    unit: &'static str,
    doc: &'static str,
    default: Option<f64>,
    min: f64,
    nonlinear: bool,
) -> ParamSpec {
    ParamSpec {
        key,
        unit,
        doc,
        default,
        min,
        nonlinear,
    }
}

/// The kinds of effect in the catalogue.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum EffectKind {
    Viscous,
    Coulomb,
    Stribeck,
    Asymmetry,
    Backlash,
    Cogging,
    Imbalance,
    Saturation,
    Deadzone,
    Delay,
}

impl EffectKind {
    /// Every kind, in catalogue order.
    pub const ALL: [EffectKind; 10] = [
        EffectKind::Viscous,
        EffectKind::Coulomb,
        EffectKind::Stribeck,
        EffectKind::Asymmetry,
        EffectKind::Backlash,
        EffectKind::Cogging,
        EffectKind::Imbalance,
        EffectKind::Saturation,
        EffectKind::Deadzone,
        EffectKind::Delay,
    ];

    /// The name users type.
    pub const fn name(self) -> &'static str {
        match self {
            EffectKind::Viscous => "viscous",
            EffectKind::Coulomb => "coulomb",
            EffectKind::Stribeck => "stribeck",
            EffectKind::Asymmetry => "asymmetry",
            EffectKind::Backlash => "backlash",
            EffectKind::Cogging => "cogging",
            EffectKind::Imbalance => "imbalance",
            EffectKind::Saturation => "saturation",
            EffectKind::Deadzone => "deadzone",
            EffectKind::Delay => "delay",
        }
    }

    /// Looks a kind up by its name.
    pub fn from_name(name: &str) -> Option<EffectKind> {
        EffectKind::ALL.into_iter().find(|k| k.name() == name)
    }

    /// One-line physical description.
    pub const fn description(self) -> &'static str {
        match self {
            EffectKind::Viscous => "viscous friction B_eq omega_m at motor side (eq. 9)",
            EffectKind::Coulomb => "Coulomb friction tau_sf sign(omega_l) at load side (eq. 8)",
            EffectKind::Stribeck => {
                "stiction and Stribeck friction: stuck until the breakaway torque tau_s, decaying to tau_sf above omega_s"
            }
            EffectKind::Asymmetry => "direction-dependent Coulomb friction (tau_sf_pos, tau_sf_neg)",
            EffectKind::Backlash => "gear play: motor and load separate inside a gap, contact through a stiff spring",
            EffectKind::Cogging => "magnetic cogging torque periodic in motor angle",
            EffectKind::Imbalance => "gravity torque of an eccentric load, periodic in load angle",
            EffectKind::Saturation => "the driver input u is clipped to +/- limit",
            EffectKind::Deadzone => "the driver ignores |u| below a threshold (dead band)",
            EffectKind::Delay => "transport delay of the input beyond the zero-order hold",
        }
    }

    /// The equation where the effect lives: true for the torque balance (mechanical), false for the
    /// electrical/input side.
    pub const fn is_mechanical(self) -> bool {
        !matches!(
            self,
            EffectKind::Saturation | EffectKind::Deadzone | EffectKind::Delay
        )
    }

    /// The parameters of this kind, in order.
    pub const fn params(self) -> &'static [ParamSpec] {
        const VISCOUS: [ParamSpec; 1] = [spec(
            "b_eq",
            "N m s/rad",
            "viscous friction coefficient, motor side",
            None,
            0.0,
            false,
        )];
        const COULOMB: [ParamSpec; 1] = [spec(
            "tau_sf",
            "N m",
            "Coulomb friction torque, load side",
            None,
            0.0,
            false,
        )];
        const STRIBECK: [ParamSpec; 2] = [
            spec(
                "tau_s",
                "N m",
                "breakaway (static) friction torque, load side, > tau_sf",
                None,
                0.0,
                false,
            ),
            spec(
                "omega_s",
                "rad/s",
                "Stribeck speed, load side",
                Some(0.5),
                1e-6,
                true,
            ),
        ];
        const ASYMMETRY: [ParamSpec; 2] = [
            spec(
                "tau_sf_pos",
                "N m",
                "Coulomb friction for omega_l > 0, load side",
                None,
                0.0,
                false,
            ),
            spec(
                "tau_sf_neg",
                "N m",
                "Coulomb friction for omega_l < 0, load side (magnitude)",
                None,
                0.0,
                false,
            ),
        ];
        const BACKLASH: [ParamSpec; 4] = [
            spec("gap", "rad", "total play seen at the load", None, 0.0, true),
            spec(
                "stiffness",
                "N m/rad",
                "contact stiffness at the load",
                Some(20.0),
                1e-9,
                true,
            ),
            spec(
                "damping",
                "N m s/rad",
                "contact damping at the load",
                Some(0.02),
                0.0,
                true,
            ),
            spec(
                "load_inertia_fraction",
                "-",
                "share of J_eq on the load side of the gap (0..1)",
                Some(0.3),
                0.0,
                true,
            ),
        ];
        const COGGING: [ParamSpec; 3] = [
            spec(
                "amplitude",
                "N m",
                "cogging torque amplitude at the motor",
                None,
                0.0,
                false,
            ),
            spec(
                "harmonic",
                "1/rev",
                "cycles per motor revolution",
                None,
                1.0,
                true,
            ),
            spec(
                "phase",
                "rad",
                "phase in motor angle",
                Some(0.0),
                f64::NEG_INFINITY,
                false,
            ),
        ];
        const IMBALANCE: [ParamSpec; 2] = [
            spec(
                "amplitude",
                "N m",
                "imbalance torque amplitude at the load",
                None,
                0.0,
                false,
            ),
            spec(
                "phase",
                "rad",
                "phase in load angle",
                Some(0.0),
                f64::NEG_INFINITY,
                false,
            ),
        ];
        const SATURATION: [ParamSpec; 1] = [spec(
            "limit",
            "V",
            "symmetric limit on the driver input u",
            None,
            1e-9,
            true,
        )];
        const DEADZONE: [ParamSpec; 1] = [spec(
            "width",
            "V",
            "dead band half width on the driver input u",
            None,
            0.0,
            true,
        )];
        const DELAY: [ParamSpec; 1] = [spec(
            "delay",
            "s",
            "input transport delay beyond the zero-order hold",
            None,
            0.0,
            true,
        )];
        match self {
            EffectKind::Viscous => &VISCOUS,
            EffectKind::Coulomb => &COULOMB,
            EffectKind::Stribeck => &STRIBECK,
            EffectKind::Asymmetry => &ASYMMETRY,
            EffectKind::Backlash => &BACKLASH,
            EffectKind::Cogging => &COGGING,
            EffectKind::Imbalance => &IMBALANCE,
            EffectKind::Saturation => &SATURATION,
            EffectKind::Deadzone => &DEADZONE,
            EffectKind::Delay => &DELAY,
        }
    }

    /// The parameter spec for `key`.
    pub fn param(self, key: &str) -> Option<&'static ParamSpec> {
        self.params().iter().find(|p| p.key == key)
    }
}

impl fmt::Display for EffectKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Maximum number of parameters of any effect.
pub const MAX_PARAMS: usize = 4;

/// One effect with its parameter values (in the order of [`EffectKind::params`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Effect {
    pub kind: EffectKind,
    values: [f64; MAX_PARAMS],
}

/// Why an effect specification was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EffectError {
    #[error("unknown effect `{0}`; the catalogue has viscous, coulomb, stribeck, asymmetry, backlash, cogging, imbalance, saturation, deadzone, delay")]
    UnknownEffect(EffectName),
    #[error("effect `{effect}` has no parameter `{key}`; it takes {expected}")]
    UnknownKey {
        effect: &'static str,
        key: EffectName,
        expected: ParamList,
    },
    #[error("effect `{effect}`: `{key}` needs a number ({unit}), got `{value}`")]
    NotANumber {
        effect: &'static str,
        key: &'static str,
        unit: &'static str,
        value: EffectName,
    },
    #[error("effect `{effect}`: `{key}` = {value} is below its physical minimum {min} {unit}")]
    OutOfRange {
        effect: &'static str,
        key: &'static str,
        unit: &'static str,
        value: f64,
        min: f64,
    },
    #[error("effect `{effect}`: `{key}` ({unit}) has no default and was not given")]
    Missing {
        effect: &'static str,
        key: &'static str,
        unit: &'static str,
    },
    #[error("effect `{effect}`: expected `key=value` pairs separated by commas, got `{item}`")]
    Syntax {
        effect: &'static str,
        item: EffectName,
    },
}

/// A short string carried by an error without a heap (truncated to 48 bytes).
#[derive(Clone, PartialEq, Eq)]
pub struct EffectName {
    buf: [u8; 48],
    len: usize,
}

impl EffectName {
    pub fn new(s: &str) -> Self {
        let mut buf = [0u8; 48];
        let mut len = s.len().min(48);
        while !s.is_char_boundary(len) {
            len -= 1;
        }
        buf[..len].copy_from_slice(&s.as_bytes()[..len]);
        EffectName { buf, len }
    }
    pub fn as_str(&self) -> &str {
        core::str::from_utf8(&self.buf[..self.len]).unwrap_or("")
    }
}
impl fmt::Display for EffectName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}
impl fmt::Debug for EffectName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", self.as_str())
    }
}

/// Displays the parameter keys of an effect with units (for error messages).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamList(pub EffectKind);
impl fmt::Display for ParamList {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, p) in self.0.params().iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            write!(f, "{} [{}]", p.key, p.unit)?;
        }
        Ok(())
    }
}

impl Effect {
    /// An effect with every parameter at its default and required ones at NaN (unset).
    pub fn unset(kind: EffectKind) -> Effect {
        let mut values = [f64::NAN; MAX_PARAMS];
        for (v, p) in values.iter_mut().zip(kind.params()) {
            *v = p.default.unwrap_or(f64::NAN);
        }
        Effect { kind, values }
    }

    /// An effect from values in parameter order; checks count and physical range.
    pub fn new(kind: EffectKind, values: &[f64]) -> Result<Effect, EffectError> {
        let mut e = Effect::unset(kind);
        for (spec, v) in kind.params().iter().zip(values) {
            e.set(spec.key, *v)?;
        }
        e.check_complete()?;
        Ok(e)
    }

    /// Parses `name` or `name:key=value,key=value` (the `--plant-effect` / `--add` syntax).
    ///
    /// Keys not given keep their default; required keys without default stay unset (NaN), which
    /// [`Effect::check_complete`] reports and the model fit fills in.
    pub fn parse(spec: &str) -> Result<Effect, EffectError> {
        let (name, rest) = match spec.split_once(':') {
            Some((n, r)) => (n.trim(), Some(r)),
            None => (spec.trim(), None),
        };
        let kind =
            EffectKind::from_name(name).ok_or(EffectError::UnknownEffect(EffectName::new(name)))?;
        let mut e = Effect::unset(kind);
        if let Some(rest) = rest {
            for item in rest.split(',').map(str::trim).filter(|s| !s.is_empty()) {
                let (k, v) = item.split_once('=').ok_or(EffectError::Syntax {
                    effect: kind.name(),
                    item: EffectName::new(item),
                })?;
                let (k, v) = (k.trim(), v.trim());
                let p = kind.param(k).ok_or(EffectError::UnknownKey {
                    effect: kind.name(),
                    key: EffectName::new(k),
                    expected: ParamList(kind),
                })?;
                let x: f64 = v.parse().map_err(|_| EffectError::NotANumber {
                    effect: kind.name(),
                    key: p.key,
                    unit: p.unit,
                    value: EffectName::new(v),
                })?;
                e.set(p.key, x)?;
            }
        }
        Ok(e)
    }

    /// The value of `key` (NaN when unset), or `None` for a key the effect does not have.
    pub fn get(&self, key: &str) -> Option<f64> {
        let i = self.kind.params().iter().position(|p| p.key == key)?;
        Some(self.values[i])
    }

    /// Sets `key`, checking that it exists, is finite and respects its physical minimum.
    pub fn set(&mut self, key: &str, value: f64) -> Result<(), EffectError> {
        let kind = self.kind;
        let i = kind
            .params()
            .iter()
            .position(|p| p.key == key)
            .ok_or(EffectError::UnknownKey {
                effect: kind.name(),
                key: EffectName::new(key),
                expected: ParamList(kind),
            })?;
        let p = &kind.params()[i];
        if !value.is_finite() || value < p.min {
            return Err(EffectError::OutOfRange {
                effect: kind.name(),
                key: p.key,
                unit: p.unit,
                value,
                min: p.min,
            });
        }
        self.values[i] = value;
        Ok(())
    }

    /// Values in parameter order.
    pub fn values(&self) -> &[f64] {
        &self.values[..self.kind.params().len()]
    }

    /// Iterates (spec, value) pairs.
    pub fn iter(&self) -> impl Iterator<Item = (&'static ParamSpec, f64)> + '_ {
        self.kind.params().iter().zip(self.values.iter().copied())
    }

    /// Keys that are still unset (NaN).
    pub fn missing(&self) -> impl Iterator<Item = &'static ParamSpec> + '_ {
        self.iter().filter(|(_, v)| v.is_nan()).map(|(p, _)| p)
    }

    /// Error if any required parameter is unset.
    pub fn check_complete(&self) -> Result<(), EffectError> {
        match self.missing().next() {
            Some(p) => Err(EffectError::Missing {
                effect: self.kind.name(),
                key: p.key,
                unit: p.unit,
            }),
            None => Ok(()),
        }
    }
}

impl fmt::Display for Effect {
    /// Formats in the `name:key=value,...` syntax that [`Effect::parse`] reads.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.kind.name())?;
        for (i, (p, v)) in self.iter().enumerate() {
            write!(f, "{}{}={}", if i == 0 { ':' } else { ',' }, p.key, v)?;
        }
        Ok(())
    }
}

/// The set of active effects of a plant or model: at most one of each kind, no heap.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Effects {
    slots: [Option<Effect>; 10],
}

impl Effects {
    /// No effect active.
    pub const NONE: Effects = Effects { slots: [None; 10] };

    fn index(kind: EffectKind) -> usize {
        kind as usize
    }
    /// The effect of `kind`, if active.
    pub fn get(&self, kind: EffectKind) -> Option<&Effect> {
        self.slots[Self::index(kind)].as_ref()
    }
    /// Mutable access to the effect of `kind`, if active.
    pub fn get_mut(&mut self, kind: EffectKind) -> Option<&mut Effect> {
        self.slots[Self::index(kind)].as_mut()
    }
    /// Activates (or replaces) an effect.
    pub fn insert(&mut self, e: Effect) {
        self.slots[Self::index(e.kind)] = Some(e);
    }
    /// Deactivates an effect, returning it.
    pub fn remove(&mut self, kind: EffectKind) -> Option<Effect> {
        self.slots[Self::index(kind)].take()
    }
    /// Is `kind` active?
    pub fn contains(&self, kind: EffectKind) -> bool {
        self.get(kind).is_some()
    }
    /// Active effects in catalogue order.
    pub fn iter(&self) -> impl Iterator<Item = &Effect> {
        self.slots.iter().flatten()
    }
    /// Number of active effects.
    pub fn len(&self) -> usize {
        self.iter().count()
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Value of `kind`'s parameter `key`, if the effect is active.
    pub fn value(&self, kind: EffectKind, key: &str) -> Option<f64> {
        self.get(kind).and_then(|e| e.get(key))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_and_display_round_trip() {
        let e = Effect::parse("backlash:gap=0.04").unwrap();
        assert_eq!(e.kind, EffectKind::Backlash);
        assert_eq!(e.get("gap"), Some(0.04));
        assert_eq!(e.get("stiffness"), Some(20.0));
        let again = Effect::parse(&std::format!("{e}")).unwrap();
        assert_eq!(e, again);
    }

    #[test]
    fn parse_errors_name_the_problem() {
        assert!(matches!(
            Effect::parse("friction"),
            Err(EffectError::UnknownEffect(_))
        ));
        let err = Effect::parse("backlash:gapp=1").unwrap_err();
        assert!(std::format!("{err}").contains("gap [rad]"));
        assert!(matches!(
            Effect::parse("delay:delay=abc"),
            Err(EffectError::NotANumber { .. })
        ));
        assert!(matches!(
            Effect::parse("backlash:gap=-1"),
            Err(EffectError::OutOfRange { .. })
        ));
        assert!(matches!(
            Effect::parse("cogging:amplitude=1e-3")
                .unwrap()
                .check_complete(),
            Err(EffectError::Missing {
                key: "harmonic",
                ..
            })
        ));
    }

    #[test]
    fn effects_set_holds_one_of_each() {
        let mut s = Effects::NONE;
        s.insert(Effect::new(EffectKind::Coulomb, &[0.01]).unwrap());
        s.insert(Effect::new(EffectKind::Coulomb, &[0.02]).unwrap());
        assert_eq!(s.len(), 1);
        assert_eq!(s.value(EffectKind::Coulomb, "tau_sf"), Some(0.02));
    }
}
