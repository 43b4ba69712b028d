//! User-defined effects: a mechanism the catalogue does not have, written by the user as an
//! expression of the plant's signals and of its own parameters (model file `[custom.NAME]`).
//!
//! ```toml
//! [custom.cable]                     # any name that is not a catalogue name
//! acts_on = "load_torque"            # load_torque | motor_torque | input | sensor
//! expr = "k * (theta_l - theta0)"    # signals: theta_l theta_m omega_l omega_m i_a u t
//! [custom.cable.params]
//! k = { value = 0.0, min = 0.0, unit = "N m/rad" }
//! theta0 = { value = 0.0, min = -1.0, max = 1.0, unit = "rad" }
//! ```
//!
//! Where it acts ([`ActsOn`]):
//! * `load_torque` [N m]: a resisting torque at the load, like friction or gravity on an unbalanced arm (subtracted
//!   from the motor torque through 1/N; positive opposes positive motion);
//! * `motor_torque` [N m]: a resisting torque at the motor shaft, like the detent torque of the magnets;
//! * `input` [V]: the expression *is* the driver input u_in, in terms of u (the input after the
//!   catalogue's dead zone and saturation, before the delay);
//! * `sensor` [rad]: the expression *is* the load angle as measured, in terms of the true
//!   theta_l (and the other signals).
//!
//! A definition is compiled once ([`CustomDef::new`]) and lives for the whole process (interned:
//! loading the same definition again returns the same one), so that a [`Plant`](crate::Plant)
//! stays `Copy` and holds its active user effects by reference ([`CustomSlots`]), as it holds its
//! catalogue effects. The simulator evaluates them at every sub-step, the fit estimates their
//! parameters ([`crate::fit::custom`]), the diagnosis tries them as candidates, and
//! [`crate::fit::discover`] proposes new ones from the residual.

// Errors carry their strings inline (no heap), like the catalogue's `EffectError`.
#![allow(clippy::result_large_err)]

pub mod expr;

#[cfg(feature = "alloc")]
pub use expr::{ExprError, Program};
pub use expr::{Op, SIGNALS, SIGNAL_UNITS};

use core::fmt;

/// Most user-defined effects active in one plant.
pub const MAX_CUSTOM: usize = 4;
/// Most parameters of one user-defined effect.
pub const MAX_CUSTOM_PARAMS: usize = 8;

/// Where a user-defined effect acts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ActsOn {
    /// A resisting torque at the load [N m].
    LoadTorque,
    /// A resisting torque at the motor [N m].
    MotorTorque,
    /// The driver input u_in [V] as a function of u.
    Input,
    /// The load angle as measured [rad] as a function of the true one.
    Sensor,
}

impl ActsOn {
    /// Every place, in the order of the model file's documentation.
    pub const ALL: [ActsOn; 4] = [
        ActsOn::LoadTorque,
        ActsOn::MotorTorque,
        ActsOn::Input,
        ActsOn::Sensor,
    ];
    /// The name in the model file.
    pub const fn name(self) -> &'static str {
        match self {
            ActsOn::LoadTorque => "load_torque",
            ActsOn::MotorTorque => "motor_torque",
            ActsOn::Input => "input",
            ActsOn::Sensor => "sensor",
        }
    }
    /// Unit of the expression's value.
    pub const fn unit(self) -> &'static str {
        match self {
            ActsOn::LoadTorque | ActsOn::MotorTorque => "N m",
            ActsOn::Input => "V",
            ActsOn::Sensor => "rad",
        }
    }
    /// Looks a place up by its model-file name.
    pub fn from_name(s: &str) -> Option<ActsOn> {
        ActsOn::ALL.into_iter().find(|a| a.name() == s)
    }
    /// True for the torque balance (load or motor torque).
    pub const fn is_torque(self) -> bool {
        matches!(self, ActsOn::LoadTorque | ActsOn::MotorTorque)
    }
}

impl fmt::Display for ActsOn {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One parameter of a user-defined effect.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CustomParam {
    pub key: &'static str,
    pub unit: &'static str,
    /// The value given in the file: the model's value, and the start of a search.
    pub value: f64,
    /// Bounds (inclusive) of the value, also the range of a search; -inf / +inf when not given.
    pub min: f64,
    pub max: f64,
}

/// A compiled user-defined effect.
#[derive(Debug, PartialEq)]
pub struct CustomDef {
    name: &'static str,
    acts_on: ActsOn,
    expr: &'static str,
    program: &'static [Op],
    params: &'static [CustomParam],
}

/// Why a user-defined effect was rejected.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum CustomError {
    /// The name is a catalogue effect's, empty, or not a plain identifier.
    BadName { name: NameBuf, why: &'static str },
    /// The expression does not compile.
    #[cfg(feature = "alloc")]
    Expr { name: NameBuf, error: ExprError },
    /// A parameter is declared badly (bounds, value outside them, too many, bad key).
    Param {
        name: NameBuf,
        key: NameBuf,
        why: NameBuf,
    },
    /// More than [`MAX_CUSTOM`] user effects in one plant.
    TooMany,
    /// A parameter key the effect does not have, or a value outside its bounds.
    Value {
        name: &'static str,
        key: NameBuf,
        why: NameBuf,
    },
}

/// A short owned string for errors (heap-free, truncated to 96 bytes).
pub type NameBuf = crate::effects::EffectName;

impl fmt::Display for CustomError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CustomError::BadName { name, why } => write!(f, "user effect `{name}`: {why}"),
            #[cfg(feature = "alloc")]
            CustomError::Expr { name, error } => {
                write!(f, "user effect `{name}`, expr: {error}")
            }
            CustomError::Param { name, key, why } => {
                write!(f, "user effect `{name}`, parameter `{key}`: {why}")
            }
            CustomError::TooMany => write!(
                f,
                "at most {MAX_CUSTOM} user-defined effects can be active in one model"
            ),
            CustomError::Value { name, key, why } => {
                write!(f, "user effect `{name}`, parameter `{key}`: {why}")
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for CustomError {}

/// A parameter as declared, before compilation.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamDecl<'a> {
    pub key: &'a str,
    pub unit: &'a str,
    pub value: f64,
    pub min: Option<f64>,
    pub max: Option<f64>,
}

#[cfg(feature = "alloc")]
fn is_ident(s: &str) -> bool {
    let mut c = s.chars();
    matches!(c.next(), Some(ch) if ch.is_ascii_alphabetic() || ch == '_')
        && c.all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
}

impl CustomDef {
    /// Checks and compiles a user-defined effect: the name is a plain identifier and not a
    /// catalogue name, every parameter has a finite value within its bounds, and the expression
    /// compiles with only the signals and these parameters. The definition is interned for the
    /// life of the process.
    #[cfg(feature = "alloc")]
    pub fn new(
        name: &str,
        acts_on: ActsOn,
        expr_src: &str,
        params: &[ParamDecl<'_>],
    ) -> Result<&'static CustomDef, CustomError> {
        use alloc::boxed::Box;
        use alloc::string::String;
        use alloc::vec::Vec;
        let nb = NameBuf::new(name);
        if !is_ident(name) || name.len() > 48 {
            return Err(CustomError::BadName {
                name: nb,
                why: "a name is a letter or `_` followed by letters, digits or `_` (at most 48)",
            });
        }
        if crate::effects::EffectKind::from_name(name).is_some() {
            return Err(CustomError::BadName {
                name: nb,
                why: "this is a catalogue effect's name; choose another name for a user effect",
            });
        }
        if SIGNALS.contains(&name) {
            return Err(CustomError::BadName {
                name: nb,
                why: "this is a signal's name",
            });
        }
        if params.len() > MAX_CUSTOM_PARAMS {
            return Err(CustomError::Param {
                name: nb,
                key: NameBuf::new(params[MAX_CUSTOM_PARAMS].key),
                why: NameBuf::new("at most 8 parameters per effect"),
            });
        }
        let mut specs = Vec::new();
        for (i, p) in params.iter().enumerate() {
            let bad = |why: &str| CustomError::Param {
                name: nb.clone(),
                key: NameBuf::new(p.key),
                why: NameBuf::new(why),
            };
            if !is_ident(p.key) || p.key.len() > 48 {
                return Err(bad(
                    "a key is a letter or `_` followed by letters, digits or `_`",
                ));
            }
            if SIGNALS.contains(&p.key) || p.key == "pi" {
                return Err(bad("this is a signal's name (or pi), not a parameter"));
            }
            if params[..i].iter().any(|q| q.key == p.key) {
                return Err(bad("declared twice"));
            }
            let min = p.min.unwrap_or(f64::NEG_INFINITY);
            let max = p.max.unwrap_or(f64::INFINITY);
            if min.is_nan() || max.is_nan() || min > max || min == f64::INFINITY {
                return Err(bad("min must be <= max"));
            }
            if !p.value.is_finite() {
                return Err(bad("value must be a finite number"));
            }
            if p.value < min || p.value > max {
                return Err(bad("value is outside [min, max]"));
            }
            specs.push(CustomParam {
                key: Box::leak(String::from(p.key).into_boxed_str()),
                unit: Box::leak(String::from(p.unit).into_boxed_str()),
                value: p.value,
                min,
                max,
            });
        }
        let keys: Vec<&str> = specs.iter().map(|p| p.key).collect();
        let program = Program::compile(expr_src, &keys).map_err(|error| CustomError::Expr {
            name: nb.clone(),
            error,
        })?;
        let def = CustomDef {
            name: "",
            acts_on,
            expr: "",
            program: &[],
            params: &[],
        };
        Ok(intern(def, name, expr_src, program.ops(), specs))
    }

    pub fn name(&self) -> &'static str {
        self.name
    }
    pub fn acts_on(&self) -> ActsOn {
        self.acts_on
    }
    /// The expression as written.
    pub fn expr(&self) -> &'static str {
        self.expr
    }
    pub fn params(&self) -> &'static [CustomParam] {
        self.params
    }
    /// The parameter `key`'s index.
    pub fn param_index(&self, key: &str) -> Option<usize> {
        self.params.iter().position(|p| p.key == key)
    }
    /// The compiled program.
    pub fn program(&self) -> &'static [Op] {
        self.program
    }
    /// Whether the expression reads the signal `name` (one of [`SIGNALS`]).
    pub fn reads(&self, name: &str) -> bool {
        SIGNALS
            .iter()
            .position(|s| *s == name)
            .is_some_and(|i| self.program.contains(&Op::Signal(i as u8)))
    }
    /// Whether the effect is a friction: a torque (load or motor side) that reads a speed and
    /// neither an angle nor the time, so that it is a curve of friction against speed (possibly
    /// growing with the current or the command as well) that the measured friction curve can
    /// judge.
    pub fn is_friction(&self) -> bool {
        self.acts_on.is_torque()
            && (self.reads("omega_l") || self.reads("omega_m"))
            && !["theta_l", "theta_m", "t"].iter().any(|s| self.reads(s))
    }
    /// Evaluates the expression at `signals` ([`SIGNALS`] order) with parameter values `values`.
    #[inline]
    pub fn eval(&self, signals: &[f64; 7], values: &[f64]) -> f64 {
        expr::eval_ops(self.program, signals, values)
    }
    /// The effect with the values given in its definition.
    pub fn active(&'static self) -> CustomActive {
        let mut values = [f64::NAN; MAX_CUSTOM_PARAMS];
        for (v, p) in values.iter_mut().zip(self.params) {
            *v = p.value;
        }
        CustomActive { def: self, values }
    }
}

/// Interns a definition: the same (name, place, expression, parameters) returns the same
/// `&'static`, so repeated loads do not grow memory.
#[cfg(feature = "alloc")]
fn intern(
    mut def: CustomDef,
    name: &str,
    expr_src: &str,
    ops: &[Op],
    specs: alloc::vec::Vec<CustomParam>,
) -> &'static CustomDef {
    use alloc::boxed::Box;
    use alloc::string::String;
    let same = |d: &CustomDef| {
        d.name == name
            && d.acts_on == def.acts_on
            && d.expr == expr_src
            && d.params.len() == specs.len()
            && d.params.iter().zip(&specs).all(|(a, b)| {
                a.key == b.key
                    && a.unit == b.unit
                    && a.value.to_bits() == b.value.to_bits()
                    && a.min.to_bits() == b.min.to_bits()
                    && a.max.to_bits() == b.max.to_bits()
            })
    };
    #[cfg(feature = "std")]
    {
        static TABLE: std::sync::Mutex<alloc::vec::Vec<&'static CustomDef>> =
            std::sync::Mutex::new(alloc::vec::Vec::new());
        let mut t = TABLE.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(d) = t.iter().find(|d| same(d)) {
            return d;
        }
        def.name = Box::leak(String::from(name).into_boxed_str());
        def.expr = Box::leak(String::from(expr_src).into_boxed_str());
        def.program = Box::leak(ops.to_vec().into_boxed_slice());
        def.params = Box::leak(specs.into_boxed_slice());
        let d: &'static CustomDef = Box::leak(Box::new(def));
        t.push(d);
        d
    }
    #[cfg(not(feature = "std"))]
    {
        let _ = same;
        def.name = Box::leak(String::from(name).into_boxed_str());
        def.expr = Box::leak(String::from(expr_src).into_boxed_str());
        def.program = Box::leak(ops.to_vec().into_boxed_slice());
        def.params = Box::leak(specs.into_boxed_slice());
        Box::leak(Box::new(def))
    }
}

/// A user-defined effect in a plant, with its parameter values (NaN: unknown, to be fitted).
#[derive(Clone, Copy)]
pub struct CustomActive {
    pub def: &'static CustomDef,
    pub values: [f64; MAX_CUSTOM_PARAMS],
}

impl PartialEq for CustomActive {
    fn eq(&self, other: &Self) -> bool {
        core::ptr::eq(self.def, other.def) && self.values() == other.values()
    }
}

impl fmt::Debug for CustomActive {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{self}")
    }
}

impl fmt::Display for CustomActive {
    /// `name(key=value, ...)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}(", self.def.name)?;
        for (i, (p, v)) in self.def.params.iter().zip(self.values()).enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            write!(f, "{}={v}", p.key)?;
        }
        f.write_str(")")
    }
}

impl CustomActive {
    pub fn name(&self) -> &'static str {
        self.def.name
    }
    /// Values in parameter order.
    pub fn values(&self) -> &[f64] {
        &self.values[..self.def.params.len()]
    }
    /// The value of `key`.
    pub fn get(&self, key: &str) -> Option<f64> {
        self.def.param_index(key).map(|i| self.values[i])
    }
    /// Sets `key`, checking its bounds (NaN marks it unknown).
    pub fn set(&mut self, key: &str, value: f64) -> Result<(), CustomError> {
        let i = self.def.param_index(key).ok_or(CustomError::Value {
            name: self.def.name,
            key: NameBuf::new(key),
            why: NameBuf::new("no such parameter"),
        })?;
        let p = &self.def.params[i];
        if !(value.is_nan() || (value >= p.min && value <= p.max)) {
            return Err(CustomError::Value {
                name: self.def.name,
                key: NameBuf::new(key),
                why: NameBuf::new("outside [min, max] or not finite"),
            });
        }
        self.values[i] = value;
        Ok(())
    }
    /// Evaluates at `signals`.
    #[inline]
    pub fn eval(&self, signals: &[f64; 7]) -> f64 {
        self.def.eval(signals, &self.values)
    }
    /// True when every parameter is set.
    pub fn is_complete(&self) -> bool {
        self.values().iter().all(|v| v.is_finite())
    }
}

/// The active user-defined effects of a plant: at most [`MAX_CUSTOM`], one per name, no heap.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CustomSlots {
    slots: [Option<CustomActive>; MAX_CUSTOM],
}

impl CustomSlots {
    pub const NONE: CustomSlots = CustomSlots {
        slots: [None; MAX_CUSTOM],
    };
    /// Activates (or replaces, by name) an effect.
    pub fn insert(&mut self, e: CustomActive) -> Result<(), CustomError> {
        if let Some(s) = self
            .slots
            .iter_mut()
            .flatten()
            .find(|s| s.name() == e.name())
        {
            *s = e;
            return Ok(());
        }
        match self.slots.iter_mut().find(|s| s.is_none()) {
            Some(s) => {
                *s = Some(e);
                Ok(())
            }
            None => Err(CustomError::TooMany),
        }
    }
    /// The effect called `name`.
    pub fn get(&self, name: &str) -> Option<&CustomActive> {
        self.iter().find(|s| s.name() == name)
    }
    pub fn get_mut(&mut self, name: &str) -> Option<&mut CustomActive> {
        self.slots.iter_mut().flatten().find(|s| s.name() == name)
    }
    /// Deactivates `name`.
    pub fn remove(&mut self, name: &str) -> Option<CustomActive> {
        self.slots
            .iter_mut()
            .find(|s| s.as_ref().is_some_and(|e| e.name() == name))
            .and_then(Option::take)
    }
    pub fn iter(&self) -> impl Iterator<Item = &CustomActive> {
        self.slots.iter().flatten()
    }
    pub fn iter_mut(&mut self) -> impl Iterator<Item = &mut CustomActive> {
        self.slots.iter_mut().flatten()
    }
    /// The effects acting at `place`.
    pub fn acting_on(&self, place: ActsOn) -> impl Iterator<Item = &CustomActive> {
        self.iter().filter(move |e| e.def.acts_on == place)
    }
    pub fn is_empty(&self) -> bool {
        self.iter().next().is_none()
    }
    pub fn len(&self) -> usize {
        self.iter().count()
    }
    /// True when some effect acts at `place`.
    pub fn has(&self, place: ActsOn) -> bool {
        self.acting_on(place).next().is_some()
    }
    /// Sum of the effects acting at `place` (a torque), at `signals`.
    #[inline]
    pub fn torque(&self, place: ActsOn, signals: &[f64; 7]) -> f64 {
        let mut s = 0.0;
        for e in self.acting_on(place) {
            s += e.eval(signals);
        }
        s
    }
    /// The input effects applied in turn to `signals[5]` (u) [V].
    #[inline]
    pub fn input(&self, signals: &[f64; 7]) -> f64 {
        let mut sig = *signals;
        for e in self.acting_on(ActsOn::Input) {
            sig[5] = e.eval(&sig);
        }
        sig[5]
    }
    /// The sensor effects applied in turn to `signals[0]` (theta_l) [rad].
    #[inline]
    pub fn sensor(&self, signals: &[f64; 7]) -> f64 {
        let mut sig = *signals;
        for e in self.acting_on(ActsOn::Sensor) {
            sig[0] = e.eval(&sig);
        }
        sig[0]
    }
    /// The true load angle whose measurement is `measured` [rad] (inverse of [`Self::sensor`] by
    /// secant iterations from `measured`; `measured` itself when it does not converge).
    pub fn sensor_inverse(&self, measured: f64, signals: &[f64; 7]) -> f64 {
        if !self.has(ActsOn::Sensor) {
            return measured;
        }
        let h = |th: f64| {
            let mut s = *signals;
            s[0] = th;
            self.sensor(&s) - measured
        };
        let (mut x0, mut x1) = (measured, measured + 1e-3);
        let (mut f0, mut f1) = (h(x0), h(x1));
        for _ in 0..40 {
            if !(f1.is_finite() && f0.is_finite()) {
                return measured;
            }
            if f1.abs() < 1e-13 {
                return x1;
            }
            let d = f1 - f0;
            if d == 0.0 {
                break;
            }
            let x2 = x1 - f1 * (x1 - x0) / d;
            (x0, f0) = (x1, f1);
            x1 = x2;
            f1 = h(x1);
        }
        if f1.is_finite() && f1.abs() < 1e-9 {
            x1
        } else {
            measured
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p<'a>(key: &'a str, value: f64, min: Option<f64>, max: Option<f64>) -> ParamDecl<'a> {
        ParamDecl {
            key,
            unit: "-",
            value,
            min,
            max,
        }
    }

    #[test]
    fn defines_interns_and_evaluates() {
        let a = CustomDef::new(
            "cable",
            ActsOn::LoadTorque,
            "k * (theta_l - theta0)",
            &[p("k", 0.5, Some(0.0), None), p("theta0", 0.1, None, None)],
        )
        .unwrap();
        let b = CustomDef::new(
            "cable",
            ActsOn::LoadTorque,
            "k * (theta_l - theta0)",
            &[p("k", 0.5, Some(0.0), None), p("theta0", 0.1, None, None)],
        )
        .unwrap();
        assert!(core::ptr::eq(a, b));
        let e = a.active();
        assert!((e.eval(&[1.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]) - 0.5).abs() < 1e-12);
        let mut s = CustomSlots::NONE;
        s.insert(e).unwrap();
        assert!(s.has(ActsOn::LoadTorque));
        assert!(!s.has(ActsOn::Sensor));
    }

    #[test]
    fn rejects_bad_definitions() {
        let err = |r: Result<&'static CustomDef, CustomError>| std::format!("{}", r.unwrap_err());
        let e = err(CustomDef::new("viscous", ActsOn::LoadTorque, "1", &[]));
        assert!(e.contains("catalogue"), "{e}");
        let e = err(CustomDef::new(
            "x",
            ActsOn::LoadTorque,
            "k * theta_z",
            &[p("k", 0.0, None, None)],
        ));
        assert!(e.contains("theta_z") && e.contains("column 5"), "{e}");
        let e = err(CustomDef::new(
            "x",
            ActsOn::LoadTorque,
            "k",
            &[p("k", 2.0, Some(0.0), Some(1.0))],
        ));
        assert!(e.contains("outside"), "{e}");
    }

    #[test]
    fn sensor_inverse_inverts() {
        let d = CustomDef::new(
            "ecc",
            ActsOn::Sensor,
            "theta_l + e * sin(theta_l)",
            &[p("e", 0.01, None, None)],
        )
        .unwrap();
        let mut s = CustomSlots::NONE;
        s.insert(d.active()).unwrap();
        let sig = [0.7, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let m = s.sensor(&sig);
        let back = s.sensor_inverse(m, &sig);
        assert!((back - 0.7).abs() < 1e-10, "{back}");
    }
}
