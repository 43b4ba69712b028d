//! The effect registry: every physical mechanism servo knows, one file per effect behind one
//! trait ([`EffectModel`]), found through one registry.
//!
//! The simulator uses an effect as truth, `compare --add` fits it to data and `diagnose` searches
//! it; all of them read what they need from the effect's [`EffectModel`] (parameters, where it
//! acts, its physics, its regressors or search grid, its constraints and refinement hints, its
//! evidence signature, the experiment that resolves it, the regimes it shows in). No consumer
//! names an effect. Names and parameter keys are fixed: users type them
//! (`--plant-effect backlash:gap=0.04`, TOML `[effects.backlash] gap = 0.04`). Units are SI;
//! "motor side" and "load side" as in the handout.
//!
//! # The catalogue
//!
//! | effect | acts on | parameters |
//! |---|---|---|
//! | `viscous` | motor torque | `b_eq` N m s/rad, motor side |
//! | `coulomb` | load torque | `tau_sf` N m, load side (eq. 8) |
//! | `stribeck` | load torque | `tau_s` breakaway torque N m, load side (> tau_sf); `omega_s` Stribeck speed rad/s, load side |
//! | `asymmetry` | load torque | `tau_sf_pos`, `tau_sf_neg` N m, load side: direction-dependent Coulomb friction |
//! | `backlash` | load torque | `gap` rad at the load; `stiffness` N m/rad and `damping` N m s/rad of the contact (load side); `load_inertia_fraction` of J_eq on the load side of the gap |
//! | `cogging` | motor torque | `amplitude` N m at the motor, `harmonic` cycles per motor revolution, `phase` rad |
//! | `imbalance` | load torque | `amplitude` N m at the load, `phase` rad: torque periodic in load angle |
//! | `saturation` | input u -> u_in | `limit` V on the driver input u (symmetric) |
//! | `deadzone` | input u -> u_in | `width` V: dead band (half width) on the driver input u |
//! | `delay` | input u -> u_in | `delay` s: input transport delay beyond the one-sample zero-order hold |
//!
//! (A test checks that this table agrees with the registry.)
//!
//! # Adding an effect
//!
//! One new file `effects/<name>.rs` with a unit struct implementing [`EffectModel`], one line in
//! the [`catalogue!`] invocation below, and its tests: see `docs/adding-an-effect.md`. Effects
//! defined at run time (user-defined effects from a model file) implement the same trait and
//! join the registry through [`register`] (feature `std`).

pub mod periodic;
pub mod torque;

use core::fmt;

/// One parameter of an effect.
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

/// A [`ParamSpec`] in a `const` context.
pub const fn spec(
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

/// Where an effect acts in the model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ActsOn {
    /// A resisting torque at the load (output shaft) [N m], seen at the motor as tau_l / N.
    LoadTorque,
    /// A resisting torque at the rotor [N m].
    MotorTorque,
    /// The driver input: u -> u_in [V] (memoryless map or delay).
    Input,
    /// The electrical balance (armature circuit) [V].
    Electrical,
    /// The sensor: theta_l as measured [rad].
    Sensor,
}

impl ActsOn {
    /// Machine name, as in a model file (`load_torque`, `motor_torque`, `input`, `electrical`,
    /// `sensor`).
    pub const fn name(self) -> &'static str {
        match self {
            ActsOn::LoadTorque => "load_torque",
            ActsOn::MotorTorque => "motor_torque",
            ActsOn::Input => "input",
            ActsOn::Electrical => "electrical",
            ActsOn::Sensor => "sensor",
        }
    }
    /// Human name with unit, for tables.
    pub const fn describe(self) -> &'static str {
        match self {
            ActsOn::LoadTorque => "load torque [N m]",
            ActsOn::MotorTorque => "motor torque [N m]",
            ActsOn::Input => "input u -> u_in [V]",
            ActsOn::Electrical => "electrical [V]",
            ActsOn::Sensor => "sensor [rad]",
        }
    }
    /// True for the torque balance (load or motor torque).
    pub const fn is_mechanical(self) -> bool {
        matches!(self, ActsOn::LoadTorque | ActsOn::MotorTorque)
    }
}

/// How the simulator integrates an effect (which of the [`EffectModel`] physics hooks it reads).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimRole {
    /// Part of the linear dynamics the simulator discretises exactly (viscous friction B_eq,
    /// taken from the plant's parameters).
    Linear,
    /// Dry friction with stick-slip: the simulator builds one [`torque::Friction`] from every
    /// active effect of this role, in registry order, through [`EffectModel::dry_friction`].
    DryFriction,
    /// A compliant contact with play between motor and load (two-body mechanics), through
    /// [`EffectModel::contact`]. At most one per plant.
    Contact,
    /// A smooth torque evaluated at every internal sub-step through
    /// [`EffectModel::torque_nm`], on the side given by [`EffectModel::acts_on`].
    Smooth,
    /// A memoryless map of the driver input through [`EffectModel::input_v`]; maps are applied in
    /// increasing `order`, the catalogue's dead band (order 10) before its saturation (order 20),
    /// so that a saturation bounds u_in.
    InputMap { order: u8 },
    /// A transport delay of the driver input, [`EffectModel::input_delay_s`].
    InputDelay,
    /// A map of the measured load angle, [`EffectModel::measured_theta_l_rad`].
    Sensor,
}

/// The signals an effect may depend on, at one instant (SI units; see the handout).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Signals {
    /// Time [s].
    pub t_s: f64,
    /// Load angle theta_l [rad].
    pub theta_l_rad: f64,
    /// Motor angle theta_m [rad].
    pub theta_m_rad: f64,
    /// Load speed omega_l [rad/s].
    pub omega_l_rad_s: f64,
    /// Motor speed omega_m [rad/s].
    pub omega_m_rad_s: f64,
    /// Armature current i_a [A].
    pub i_a_a: f64,
    /// Driver input u [V] as commanded.
    pub u_v: f64,
}

/// The contact of an effect of role [`SimRole::Contact`], load side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// Total play at the load [rad].
    pub gap_rad: f64,
    /// Contact stiffness [N m/rad].
    pub stiffness_nm_per_rad: f64,
    /// Contact damping [N m s/rad].
    pub damping_nms_per_rad: f64,
    /// Share of J_eq on the load side of the play (strictly between 0 and 1).
    pub load_inertia_fraction: f64,
}

/// One sample as a regressor sees it (raw motor speed, motor angle), with the constants the
/// regressors need.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Motor speed omega_m [rad/s] (unfiltered: regressors go through the fit's filter).
    pub omega_m_rad_s: f64,
    /// Motor angle theta_m [rad].
    pub theta_m_rad: f64,
    /// (cos theta_m, sin theta_m), precomputed: integer harmonics may be taken from it by complex
    /// powers instead of trigonometric calls ([`periodic::phasor_pow`]).
    pub motor_phasor: [f64; 2],
    /// Driver input u [V] at this sample.
    pub u_v: f64,
    /// Driver input u [V] at the previous sample (equal to `u_v` at the first sample).
    pub u_prev_v: f64,
    /// Gear ratio N (omega_l = omega_m / N).
    pub n: f64,
    /// Cut-off of the fit's zero-phase filter [Hz].
    pub filter_hz: f64,
}

/// The sign constraint of a linear coefficient.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CoefSign {
    /// >= 0.
    NonNegative,
    /// Any sign.
    Free,
}

/// How far a parameter refined on the simulation may move from its least-squares value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Span {
    /// Plus or minus this much (same unit as the parameter).
    Add(f64),
    /// Divided or multiplied by up to this factor.
    Scale(f64),
}

/// How a nonlinear parameter is searched.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SearchScale {
    /// Grid, then golden section on the value.
    Linear,
    /// Grid, then golden section on the logarithm of the value.
    Log,
    /// Grid only (integer values).
    Integer,
}

/// Where along a search grid the effect vanishes (ties go there: data that do not reach an
/// effect cannot size it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoEffectAt {
    Nowhere,
    /// The first grid value (a zero dead band or delay).
    First,
    /// The last grid value (a limit above every logged input).
    Last,
}

/// The search of one nonlinear parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Search {
    pub scale: SearchScale,
    pub no_effect_at: NoEffectAt,
}

impl Search {
    /// Linear grid, no "no effect" end.
    pub const LINEAR: Search = Search {
        scale: SearchScale::Linear,
        no_effect_at: NoEffectAt::Nowhere,
    };
}

/// What a search grid may depend on (from the data and the fit options).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridContext {
    /// Largest load speed in the torque-balance rows [rad/s].
    pub omega_l_max_rad_s: f64,
    /// Largest commanded |u| [V] (at least 1e-6).
    pub u_max_v: f64,
    /// Smallest sample period of the logs [s].
    pub dt_s: f64,
    /// Largest input delay searched [s] (fit option).
    pub max_delay_s: f64,
    /// Largest harmonic of a periodic torque searched (fit option).
    pub max_harmonic: u32,
}

/// An operating regime (see `compare::regimes`): where missing physics leaves its fingerprint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Regime {
    /// Within the reversal window of a change of direction of the load speed.
    Reversal,
    /// |omega_l| below the standstill threshold (not near a reversal).
    Standstill,
    /// |u| at 95 % of its limit or more.
    VoltageLimit,
    /// Moving with a large |d omega_l / dt|.
    Acceleration,
    /// Moving at roughly constant speed.
    ConstantSpeed,
}

/// How a controller compensates an effect ([`crate::control::compensation`], issue #29): what
/// [`EffectModel::compensation`] declares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compensation {
    /// Part of the linear feedforward (B_eq: the `viscous` term of `--ff`).
    Linear,
    /// A torque the drive adds: [`EffectModel::torque_nm`] evaluated on the reference state
    /// (speeds and accelerations of the reference; the angle as `angle` says), converted to
    /// volts through the motor (eqs. 1, 5, 22).
    Torque {
        /// Where the angle comes from.
        angle: AngleFrom,
    },
    /// The plant's dry-friction curve ([`torque::Friction`]) at the reference speed, with a
    /// smoothed sign.
    DryFriction,
    /// The inverse of the input map, [`EffectModel::inverse_input_v`], on the whole command.
    InputInverse,
    /// A bound of the input: the controller's output limit is narrowed to it, so that its
    /// anti-windup sees the real bound.
    Limit,
    /// A transport delay: the feedforward reads the reference `input_delay_s` ahead (a phase
    /// lead of the feedforward; the PID still sees the delay).
    Lead,
    /// Not compensated, and why (one sentence).
    Not(&'static str),
}

/// The angle a [`Compensation::Torque`] is evaluated at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AngleFrom {
    /// The reference's load angle (pure feedforward).
    Reference,
    /// The measured load angle (and the motor angle N theta_l from it): cancellation of a
    /// position-dependent torque where the shaft is, not where it should be.
    Measured,
}

/// A physical mechanism: everything servo needs to simulate it, fit it and diagnose it.
///
/// Catalogue effects are unit structs in `effects/<name>.rs` listed once in the registry; a
/// run-time effect (e.g. from an expression in a model file) implements the same trait and is
/// registered with [`register`]. Every method has a default except the identity, the
/// parameters and where it acts; the defaults describe an effect of role [`SimRole::Smooth`]
/// whose torque is linear in no parameter (everything searched or kept).
///
/// Parameter values are always passed as a slice `v` in the order of [`EffectModel::params`]
/// (same length); a value may be NaN only where a method says so.
pub trait EffectModel: Sync + Send {
    // ---- identity ----
    /// The name users type: ASCII lowercase letters, digits and `_`, unique in the registry.
    fn name(&self) -> &str;
    /// One-line physical description (used in tables, evidence and verdicts).
    fn description(&self) -> &str;
    /// The parameters, in order (at most [`MAX_PARAMS`]). Keys are unique.
    fn params(&self) -> &[ParamSpec];
    /// Where the effect acts.
    fn acts_on(&self) -> ActsOn;
    /// The key of the main parameter (the one a user quotes: a gap, an amplitude, a limit); must
    /// be one of [`EffectModel::params`]. Its unit is that parameter's unit.
    fn main_param(&self) -> &str {
        self.params().first().map_or("", |p| p.key)
    }

    // ---- physics ----
    /// How the simulator integrates it. Default: [`SimRole::Smooth`].
    fn sim_role(&self) -> SimRole {
        SimRole::Smooth
    }
    /// [`SimRole::Smooth`]: the resisting torque [N m] at `s`, at the load for
    /// [`ActsOn::LoadTorque`] and at the rotor for [`ActsOn::MotorTorque`] (subtracted from the
    /// motor torque, like tau_d in eq. 9). Must be finite for finite inputs. Default 0.
    fn torque_nm(&self, v: &[f64], s: &Signals) -> f64 {
        let _ = (v, s);
        0.0
    }
    /// [`SimRole::Smooth`]: true when [`EffectModel::torque_nm`] depends on the angle of its side
    /// only (theta_l for a load torque, theta_m for a motor torque), so the simulator may reuse
    /// the value while the angle does not change. Default false.
    fn depends_on_angle_only(&self) -> bool {
        false
    }
    /// A load torque set by the load's position alone that can dwarf the friction (an arm's or
    /// a pendulum's gravity, m g L sin(theta_l + phi)): identification fits it with the base
    /// when it dominates the balance instead of returning an unphysical inertia
    /// ([`crate::fit::udriven`]). Default false.
    fn dominant_load_candidate(&self) -> bool {
        false
    }
    /// A torque locked to an angle (periodic in theta_m for a motor torque, in theta_l for a
    /// load torque, its amplitude independent of speed): the orders it can take [cycles per
    /// revolution of its side], given the search's context. The diagnosis calls a residual
    /// periodic at any other order, or with an amplitude that changes with speed, a shape no
    /// effect of the catalogue makes. Default `None`: not locked to an angle.
    #[cfg(feature = "alloc")]
    fn angle_orders(&self, ctx: &GridContext) -> Option<alloc::vec::Vec<f64>> {
        let _ = ctx;
        None
    }
    /// [`SimRole::DryFriction`]: adds this effect's part to the dry friction `f` (effects are
    /// applied in registry order; a later one may replace an earlier one's levels).
    fn dry_friction(&self, v: &[f64], f: &mut torque::Friction) {
        let _ = (v, f);
    }
    /// [`SimRole::Contact`]: the contact (`None` when the values do not define one).
    fn contact(&self, v: &[f64]) -> Option<Contact> {
        let _ = v;
        None
    }
    /// [`SimRole::Contact`]: the transmitted contact torque [N m] at the load for the relative
    /// angle `delta_l` = theta_m / N - theta_l [rad] and its rate [rad/s]; 0 inside the play.
    fn contact_torque_l(&self, c: &Contact, delta_l: f64, delta_dot_l: f64) -> f64 {
        let _ = (c, delta_l, delta_dot_l);
        0.0
    }
    /// [`SimRole::Contact`]: how far [rad] the motor side (reflected to the load) is past the
    /// edge of the play: positive on the driving flank, negative on the other, 0 inside.
    fn contact_penetration_l(&self, c: &Contact, delta_l: f64) -> f64 {
        let _ = (c, delta_l);
        0.0
    }
    /// [`SimRole::InputMap`]: u -> u_in [V]. Default identity.
    fn input_v(&self, v: &[f64], u_v: f64) -> f64 {
        let _ = v;
        u_v
    }
    /// [`SimRole::InputDelay`]: the delay [s] (>= 0). Default 0.
    fn input_delay_s(&self, v: &[f64]) -> f64 {
        let _ = v;
        0.0
    }
    /// [`SimRole::Sensor`]: the load angle as measured [rad] when the true signals are `s`.
    /// Default theta_l.
    fn measured_theta_l_rad(&self, v: &[f64], s: &Signals) -> f64 {
        let _ = v;
        s.theta_l_rad
    }

    // ---- compensation ----
    /// How a controller compensates this effect. Default from the simulator role: a smooth
    /// torque is compensated as a torque at the reference state (at the measured angle when it
    /// depends on the angle only), dry friction by the friction curve, a delay by a lead, the
    /// linear part by the linear feedforward; an input map without a declared inverse, a contact
    /// and a sensor map are not compensated.
    fn compensation(&self) -> Compensation {
        match self.sim_role() {
            SimRole::Linear => Compensation::Linear,
            SimRole::DryFriction => Compensation::DryFriction,
            SimRole::Smooth => Compensation::Torque {
                angle: if self.depends_on_angle_only() {
                    AngleFrom::Measured
                } else {
                    AngleFrom::Reference
                },
            },
            SimRole::InputMap { .. } => Compensation::Not("the input map declares no inverse"),
            SimRole::InputDelay => Compensation::Lead,
            SimRole::Contact => Compensation::Not(
                "a play between motor and load cannot be cancelled from the load angle",
            ),
            SimRole::Sensor => Compensation::Not("a sensor map changes no torque"),
        }
    }
    /// [`Compensation::InputInverse`]: the command u [V] for which the input map gives
    /// `u_in_v`, its sign smoothed over `smooth_v` [V] (> 0) around 0 so that the command does
    /// not chatter at rest. Must be odd in `u_in_v` for a symmetric map. Default identity.
    fn inverse_input_v(&self, v: &[f64], u_in_v: f64, smooth_v: f64) -> f64 {
        let _ = (v, smooth_v);
        u_in_v
    }

    // ---- fit ----
    /// May the fit estimate `key` (false: it keeps its value or default unless the user asks
    /// otherwise)? Default true.
    fn fittable(&self, key: &str) -> bool {
        let _ = key;
        true
    }
    /// How the nonlinear parameter `key` is searched. Default [`Search::LINEAR`].
    fn search(&self, key: &str) -> Search {
        let _ = key;
        Search::LINEAR
    }
    /// The grid over which the nonlinear parameter `key` is searched (non-empty, finite values
    /// within the physical range). `None` (the default): the parameter keeps its current value.
    #[cfg(feature = "alloc")]
    fn search_grid(&self, key: &str, ctx: &GridContext) -> Option<alloc::vec::Vec<f64>> {
        let _ = (key, ctx);
        None
    }
    /// Parameters refined on the simulation after the least-squares fit, with how far they may
    /// move. Default none.
    fn polish(&self) -> &[(&'static str, Span)] {
        &[]
    }
    /// Number of linear coefficients of the effect in the torque balance (0 for effects without
    /// regressors: input, contact, or everything searched). Default 0.
    fn linear_coefs(&self) -> usize {
        0
    }
    /// Sign constraint of linear coefficient `j` (< [`EffectModel::linear_coefs`]).
    fn coef_sign(&self, j: usize) -> CoefSign {
        let _ = j;
        CoefSign::Free
    }
    /// Regressor of linear coefficient `j` at sample `x`: the torque at the motor [N m] per unit
    /// coefficient, with the nonlinear parameters of `v` (all finite). Default 0.
    fn regressor(&self, v: &[f64], j: usize, x: &Sample) -> f64 {
        let _ = (v, j, x);
        0.0
    }
    /// Every regressor at sample `x` into `out` (length [`EffectModel::linear_coefs`]), in one
    /// call (an effect whose regressors share work overrides this). Default:
    /// [`EffectModel::regressor`] for each coefficient.
    fn regressors(&self, v: &[f64], x: &Sample, out: &mut [f64]) {
        for (j, o) in out.iter_mut().enumerate() {
            *o = self.regressor(v, j, x);
        }
    }
    /// Are the linear coefficients estimated, given which parameters are fitted (`fit`, in
    /// parameter order)? Default: any linear parameter fitted.
    fn coefs_fitted(&self, fit: &[bool]) -> bool {
        self.params()
            .iter()
            .zip(fit)
            .any(|(p, f)| *f && !p.nonlinear)
    }
    /// Value of coefficient `j` from the parameter values (when they are not fitted). `tau_sf` is
    /// the model's Coulomb level [N m].
    fn coef_from_values(&self, v: &[f64], j: usize, tau_sf: f64) -> f64 {
        let _ = (v, j, tau_sf);
        0.0
    }
    /// Parameter values from the fitted coefficients `c` (length [`EffectModel::linear_coefs`]);
    /// `v` holds the current values (nonlinear ones set) and is updated in place.
    fn values_from_coefs(&self, c: &[f64], v: &mut [f64], tau_sf: f64) {
        let _ = (c, v, tau_sf);
    }
    /// Standard error of parameter `key` from the fitted coefficients `coefs` and their
    /// standard errors `se`, if it has one (`None`: the data do not give it an interval).
    fn std_err(&self, key: &str, se: &[f64], coefs: &[f64]) -> Option<f64> {
        let _ = (key, se, coefs);
        None
    }

    // ---- diagnosis ----
    /// The experiment that best exposes the effect (one sentence, imperative).
    fn experiment(&self) -> &str {
        "log the current and both angles over motions that reach where the effect acts"
    }
    /// The regimes where its error shows.
    fn regimes(&self) -> &[Regime] {
        &[]
    }
    /// Short phrase naming it among a regime's suspects (e.g. "backlash (gear play)").
    fn suspect_phrase(&self) -> &str {
        self.name()
    }
    /// Parameters compared across independent parts of the data (consistency checks of the
    /// diagnosis). Default none (no consistency check).
    fn compared(&self) -> &[&'static str] {
        &[]
    }
    /// Should the effect be the same at slow and at fast motion (a consistency check)?
    fn speed_independent(&self) -> bool {
        false
    }
    /// Number of signature components ([`EffectModel::signature`]); 0: none.
    fn signature_len(&self) -> usize {
        0
    }
    /// Component `j` of the effect's evidence signature at sample `x`: the signal whose
    /// correlation with the residual the effect removes.
    fn signature(&self, v: &[f64], j: usize, x: &Sample) -> f64 {
        let _ = (v, j, x);
        0.0
    }
    /// Name of the signature, in words.
    #[cfg(feature = "alloc")]
    fn signature_name(&self, v: &[f64]) -> alloc::string::String {
        let _ = v;
        alloc::format!("the {} regressor", self.name())
    }
    /// Needs the effect another one already in the model (e.g. Stribeck decays to the Coulomb
    /// level)? `has` tells whether an effect (by name) is in the model. Default true.
    fn applicable(&self, has: &dyn Fn(&str) -> bool) -> bool {
        let _ = has;
        true
    }
    /// Order in which the diagnosis starts candidate fits (0 first): the costliest (most
    /// simulations) first, so that two threads end together. A scheduling hint only; default 6.
    fn schedule_rank(&self) -> u8 {
        6
    }
    /// Hooks of the fit and the diagnosis that need the data (alloc): see [`FitHooks`].
    #[cfg(feature = "alloc")]
    fn fit_hooks(&self) -> Option<&dyn FitHooks> {
        None
    }
}

/// Hooks of an effect that need the fit's data structures (feature `alloc`): physical
/// constraints, and parameters sized on the simulation.
#[cfg(feature = "alloc")]
pub trait FitHooks: Sync + Send {
    /// The physical constraints and the meaning of the fitted parameters `params` (this effect's
    /// and, for friction, the Coulomb level) in the data `ds`; `cand` is the fitted model with
    /// the effect, `base` the model without it.
    fn constraints(
        &self,
        ds: &crate::fit::Dataset,
        params: &[crate::fit::ParamEstimate],
        cand: &crate::plant::Plant,
        base: &crate::plant::Plant,
    ) -> alloc::vec::Vec<crate::verdict::Check> {
        let _ = (ds, params, cand, base);
        alloc::vec::Vec::new()
    }
    /// True when the effect is judged on the simulation (output error) rather than on an
    /// equation residual (it has no regressors).
    fn judged_on_simulation(&self) -> bool {
        false
    }
    /// Sizes parameters on the simulation after the least-squares fit, for slot `i` of
    /// `solved`; `fit_main`: the main parameter is fitted; `fit_j`: J_eq may be refined.
    fn refine_on_simulation(
        &self,
        ds: &crate::fit::Dataset,
        solved: &mut crate::fit::Solved,
        i: usize,
        fit_main: bool,
        fit_j: bool,
    ) -> Result<(), crate::fit::FitError> {
        let _ = (ds, solved, i, fit_main, fit_j);
        Ok(())
    }
    /// A check of [`FitHooks::constraints`] that reads a balance no other effect of the model
    /// acts in, failed: the data contradict the effect with `params` whatever else `base` (the
    /// model without it) holds (a gear play the motor never crosses, in the electrical
    /// balance). `None` when it holds or cannot be judged. A joint search drops such a member
    /// first, before those that merely add too little.
    fn refuted(
        &self,
        ds: &crate::fit::Dataset,
        params: &[crate::fit::ParamEstimate],
        base: &crate::plant::Plant,
    ) -> Option<crate::verdict::Check> {
        let _ = (ds, params, base);
        None
    }
    /// For a significant candidate: its main parameter against another one the fit assumed
    /// (e.g. a gap against the contact stiffness), refitted over a plausible range of it, with a
    /// sentence for the evidence. `None`: nothing to report.
    fn conditional(
        &self,
        ds: &crate::fit::Dataset,
        model: &crate::plant::Plant,
        c: &crate::verdict::Candidate,
    ) -> Option<(crate::verdict::Conditional, alloc::string::String)> {
        let _ = (ds, model, c);
        None
    }
    /// A mechanism outside the catalogue that this effect's own simulation machinery can size
    /// (a gear play's contact without the gap: a linear shaft or coupling), fitted on the data
    /// `ds` from the model `start` (it lacks this effect; the diagnosis asks from the user's
    /// model and from its simulation reference and keeps the fit with the lower error on the
    /// fit blocks). Asked only when no catalogue effect passes and a balance is above its noise
    /// floor; reported as a signature when it predicts the held-out motion materially better
    /// than the reference ([`crate::diagnose::DiagnoseOptions::min_simulation_oe_drop`]).
    /// `None`: none, or it cannot be sized on these data.
    fn neighbour(
        &self,
        ds: &crate::fit::Dataset,
        start: &crate::plant::Plant,
    ) -> Option<crate::verdict::Neighbour> {
        let _ = (ds, start);
        None
    }
    /// A note on a significant candidate (e.g. what its estimate is conditional on).
    fn candidate_note(
        &self,
        ds: &crate::fit::Dataset,
        model: &crate::plant::Plant,
        c: &crate::verdict::Candidate,
    ) -> Option<alloc::string::String> {
        let _ = (ds, model, c);
        None
    }
}

/// Most parameters of any effect.
pub const MAX_PARAMS: usize = 8;

/// Most run-time (user) effects registered in one process.
pub const MAX_USER_EFFECTS: usize = 16;

/// The catalogue: one line per effect, `module::Model => Name`. Declares the module, the
/// [`EffectKind`] constant `EffectKind::Name`, its slot, and [`EffectKind::ALL`].
macro_rules! catalogue {
    ($($module:ident :: $model:ident => $konst:ident),* $(,)?) => {
        $(pub mod $module;)*

        #[allow(clippy::upper_case_acronyms)]
        #[repr(u8)]
        enum CatalogueSlot { $($konst),* }

        /// The catalogue's models, by slot.
        static CATALOGUE: [&'static dyn EffectModel; CATALOGUE_LEN] = [$(&$module::$model),*];

        /// Number of catalogue effects.
        pub const CATALOGUE_LEN: usize = [$(CatalogueSlot::$konst),*].len();

        #[allow(non_upper_case_globals)]
        impl EffectKind {
            $(
                #[doc = concat!("The catalogue effect `", stringify!($module), "`.")]
                pub const $konst: EffectKind = EffectKind(CatalogueSlot::$konst as u8);
            )*
            /// Every catalogue kind, in catalogue order.
            pub const ALL: [EffectKind; CATALOGUE_LEN] = [$(EffectKind::$konst),*];
        }
    };
}

catalogue! {
    viscous::Viscous => Viscous,
    coulomb::Coulomb => Coulomb,
    stribeck::Stribeck => Stribeck,
    asymmetry::Asymmetry => Asymmetry,
    backlash::Backlash => Backlash,
    cogging::Cogging => Cogging,
    imbalance::Imbalance => Imbalance,
    saturation::Saturation => Saturation,
    deadzone::Deadzone => Deadzone,
    delay::Delay => Delay,
}

/// The catalogue effect that carries a gravity load on an arm: a resisting torque amplitude
/// sin(theta + phase) (the smart-servo model reads a pendulum's m g L from it).
pub const GRAVITY: EffectKind = EffectKind::Imbalance;

/// Total number of slots of an [`Effects`] set: the catalogue and the user effects.
pub const MAX_EFFECTS: usize = CATALOGUE_LEN + MAX_USER_EFFECTS;

/// A registered effect: a handle (its slot in the registry). Copy, comparable, cheap.
///
/// Catalogue kinds are constants (`EffectKind::ALL`); run-time kinds come from [`register`].
/// Everything about the effect is in its [`EffectKind::model`].
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct EffectKind(u8);

/// The user part of the registry (std only: it needs a lock).
#[cfg(feature = "std")]
static USER: std::sync::RwLock<[Option<&'static dyn EffectModel>; MAX_USER_EFFECTS]> =
    std::sync::RwLock::new([None; MAX_USER_EFFECTS]);

/// Why a run-time effect could not be registered.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RegistryError {
    #[error("`{0}` is a catalogue effect; give a user-defined effect another name")]
    CatalogueName(EffectName),
    #[error(
        "effect name `{0}`: use ASCII lowercase letters, digits and `_`, starting with a letter"
    )]
    BadName(EffectName),
    #[error("effect `{name}` has {count} parameters; at most {max} are supported")]
    TooManyParams {
        name: EffectName,
        count: usize,
        max: usize,
    },
    #[error("effect `{name}`: parameter `{key}` appears twice")]
    DuplicateParam { name: EffectName, key: EffectName },
    #[error("effect `{name}`: main parameter `{key}` is not one of its parameters")]
    BadMainParam { name: EffectName, key: EffectName },
    #[error("too many user-defined effects (at most {0} per run)")]
    Full(usize),
}

/// Registers a run-time effect (e.g. a user-defined effect from a model file) and returns its
/// kind. Registering a name again replaces its model and keeps its kind (handles taken before
/// then see the new model). The model lives for the rest of the process (it is leaked, like the
/// `&'static str` keys of its [`ParamSpec`]s, which a run-time model may get with `Box::leak`):
/// register once per effect definition, not in a loop.
///
/// Run-time kinds are not diagnosis candidates by default (the registry is process-wide, and a
/// diagnosis must not depend on what another part of the process registered): pass them in
/// `DiagnoseOptions::extra_candidates` or `candidates`.
#[cfg(feature = "std")]
pub fn register(model: alloc::boxed::Box<dyn EffectModel>) -> Result<EffectKind, RegistryError> {
    let name = model.name();
    let ok_name = name.chars().next().is_some_and(|c| c.is_ascii_lowercase())
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_');
    if !ok_name {
        return Err(RegistryError::BadName(EffectName::new(name)));
    }
    if EffectKind::ALL.iter().any(|k| k.name() == name) {
        return Err(RegistryError::CatalogueName(EffectName::new(name)));
    }
    let params = model.params();
    if params.len() > MAX_PARAMS {
        return Err(RegistryError::TooManyParams {
            name: EffectName::new(name),
            count: params.len(),
            max: MAX_PARAMS,
        });
    }
    for (i, p) in params.iter().enumerate() {
        if params[..i].iter().any(|q| q.key == p.key) {
            return Err(RegistryError::DuplicateParam {
                name: EffectName::new(name),
                key: EffectName::new(p.key),
            });
        }
    }
    let main = model.main_param();
    if !params.iter().any(|p| p.key == main) {
        return Err(RegistryError::BadMainParam {
            name: EffectName::new(name),
            key: EffectName::new(main),
        });
    }
    let mut user = USER.write().unwrap_or_else(|e| e.into_inner());
    let slot = match user
        .iter()
        .position(|m| m.is_some_and(|m| m.name() == name))
    {
        Some(i) => i,
        None => user
            .iter()
            .position(Option::is_none)
            .ok_or(RegistryError::Full(MAX_USER_EFFECTS))?,
    };
    user[slot] = Some(alloc::boxed::Box::leak(model));
    Ok(EffectKind((CATALOGUE_LEN + slot) as u8))
}

/// Placeholder for a slot that holds no model (never reachable through a public constructor).
struct Unregistered;
impl EffectModel for Unregistered {
    fn name(&self) -> &str {
        "unregistered"
    }
    fn description(&self) -> &str {
        "no effect"
    }
    fn params(&self) -> &[ParamSpec] {
        &[]
    }
    fn acts_on(&self) -> ActsOn {
        ActsOn::LoadTorque
    }
}

impl EffectKind {
    /// The effect's model: everything about it.
    pub fn model(self) -> &'static dyn EffectModel {
        let i = self.0 as usize;
        if let Some(m) = CATALOGUE.get(i) {
            return *m;
        }
        #[cfg(feature = "std")]
        {
            let user = USER.read().unwrap_or_else(|e| e.into_inner());
            if let Some(Some(m)) = user.get(i - CATALOGUE_LEN) {
                return *m;
            }
        }
        &Unregistered
    }

    /// Slot of the kind in an [`Effects`] set (< [`MAX_EFFECTS`]).
    pub const fn slot(self) -> usize {
        self.0 as usize
    }

    /// True for catalogue effects, false for run-time ones.
    pub const fn is_catalogue(self) -> bool {
        (self.0 as usize) < CATALOGUE_LEN
    }

    /// The name users type.
    pub fn name(self) -> &'static str {
        self.model().name()
    }

    /// Looks a kind up by its name (catalogue first, then run-time effects).
    pub fn from_name(name: &str) -> Option<EffectKind> {
        EffectKind::registered().find(|k| k.name() == name)
    }

    /// Every registered kind: the catalogue in order, then the run-time effects.
    pub fn registered() -> impl Iterator<Item = EffectKind> {
        #[cfg_attr(not(feature = "std"), allow(unused_mut))]
        let mut user = [None; MAX_USER_EFFECTS];
        #[cfg(feature = "std")]
        {
            let u = USER.read().unwrap_or_else(|e| e.into_inner());
            for (i, m) in u.iter().enumerate() {
                if m.is_some() {
                    user[i] = Some(EffectKind((CATALOGUE_LEN + i) as u8));
                }
            }
        }
        EffectKind::ALL
            .into_iter()
            .chain(user.into_iter().flatten())
    }

    /// One-line physical description.
    pub fn description(self) -> &'static str {
        self.model().description()
    }

    /// Where the effect acts.
    pub fn acts_on(self) -> ActsOn {
        self.model().acts_on()
    }

    /// How the simulator integrates it.
    pub fn sim_role(self) -> SimRole {
        self.model().sim_role()
    }

    /// The equation where the effect lives: true for the torque balance (mechanical), false for the
    /// electrical/input side.
    pub fn is_mechanical(self) -> bool {
        self.acts_on().is_mechanical()
    }

    /// The parameters of this kind, in order.
    pub fn params(self) -> &'static [ParamSpec] {
        let p = self.model().params();
        &p[..p.len().min(MAX_PARAMS)]
    }

    /// The parameter spec for `key`.
    pub fn param(self, key: &str) -> Option<&'static ParamSpec> {
        self.params().iter().find(|p| p.key == key)
    }

    /// The main parameter (key and unit).
    pub fn main_param(self) -> Option<&'static ParamSpec> {
        self.param(self.model().main_param())
    }
}

impl fmt::Display for EffectKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl fmt::Debug for EffectKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Displays the registered effect names, comma-separated (for error messages).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RegisteredNames;
impl fmt::Display for RegisteredNames {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, k) in EffectKind::registered().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            f.write_str(k.name())?;
        }
        Ok(())
    }
}

/// Displays every registered effect with its parameters and units, `;`-separated (for help
/// texts): `viscous b_eq [N m s/rad]; coulomb tau_sf [N m]; ...`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParamsSummary;
impl fmt::Display for ParamsSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, k) in EffectKind::registered().enumerate() {
            if i > 0 {
                f.write_str("; ")?;
            }
            write!(f, "{} ({})", k.name(), k.acts_on().describe())?;
            for (j, p) in k.params().iter().enumerate() {
                write!(
                    f,
                    "{} {} [{}]",
                    if j == 0 { ":" } else { "," },
                    p.key,
                    p.unit
                )?;
            }
        }
        Ok(())
    }
}

/// Displays the registry as a Markdown table (effect, where it acts, parameters with units and
/// meaning, the experiment that resolves it): the table of the guide (docs/guide/src/effects.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CatalogueTable;
impl fmt::Display for CatalogueTable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("| effect | acts on | parameters | resolved by |\n|---|---|---|---|\n")?;
        for k in EffectKind::registered() {
            write!(f, "| `{}` | {} | ", k.name(), k.acts_on().describe())?;
            for (j, p) in k.params().iter().enumerate() {
                if j > 0 {
                    f.write_str("; ")?;
                }
                write!(f, "`{}` {}: {}", p.key, p.unit, p.doc)?;
                if let Some(d) = p.default {
                    write!(f, " (default {d})")?;
                }
            }
            writeln!(f, " | {} |", k.model().experiment())?;
        }
        Ok(())
    }
}

/// One effect with its parameter values (in the order of [`EffectKind::params`]).
#[derive(Clone, Copy)]
pub struct Effect {
    pub kind: EffectKind,
    values: [f64; MAX_PARAMS],
}

impl PartialEq for Effect {
    /// Same kind and same values (unused slots ignored).
    fn eq(&self, other: &Effect) -> bool {
        self.kind == other.kind && self.values() == other.values()
    }
}

impl fmt::Debug for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Effect")
            .field("kind", &self.kind)
            .field("values", &self.values())
            .finish()
    }
}

/// Why an effect specification was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EffectError {
    #[error("unknown effect `{0}`; the registry has {RegisteredNames}")]
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
    #[error("effect `{effect}`: `{key}` = {} is below its physical minimum {} {unit}", crate::math::Num(*.value), crate::math::Num(*.min))]
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
        let mut values = [0.0; MAX_PARAMS];
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

/// The set of active effects of a plant or model: at most one of each kind, no heap. Its slots
/// are sized from the registry ([`MAX_EFFECTS`]), so every kind has one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Effects {
    slots: [Option<Effect>; MAX_EFFECTS],
}

impl Default for Effects {
    fn default() -> Self {
        Effects::NONE
    }
}

impl Effects {
    /// No effect active.
    pub const NONE: Effects = Effects {
        slots: [None; MAX_EFFECTS],
    };

    /// The effect of `kind`, if active.
    pub fn get(&self, kind: EffectKind) -> Option<&Effect> {
        self.slots.get(kind.slot()).and_then(Option::as_ref)
    }
    /// Mutable access to the effect of `kind`, if active.
    pub fn get_mut(&mut self, kind: EffectKind) -> Option<&mut Effect> {
        self.slots.get_mut(kind.slot()).and_then(Option::as_mut)
    }
    /// Activates (or replaces) an effect.
    pub fn insert(&mut self, e: Effect) {
        if let Some(s) = self.slots.get_mut(e.kind.slot()) {
            *s = Some(e);
        }
    }
    /// Deactivates an effect, returning it.
    pub fn remove(&mut self, kind: EffectKind) -> Option<Effect> {
        self.slots.get_mut(kind.slot()).and_then(Option::take)
    }
    /// Is `kind` active?
    pub fn contains(&self, kind: EffectKind) -> bool {
        self.get(kind).is_some()
    }
    /// Active effects in registry order (catalogue first).
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
    /// The active effect of simulator role `role`, if any (the first in registry order).
    pub fn with_role(&self, role: SimRole) -> Option<&Effect> {
        self.iter().find(|e| e.kind.sim_role() == role)
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
        let err = Effect::parse("friction").unwrap_err();
        assert!(matches!(err, EffectError::UnknownEffect(_)));
        assert!(std::format!("{err}").contains("viscous, coulomb"));
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

    /// The registry's invariants: unique names and keys, main parameters among the parameters,
    /// at most MAX_PARAMS each, and every kind has a slot.
    #[test]
    fn registry_is_consistent() {
        let mut s = Effects::NONE;
        for (i, k) in EffectKind::ALL.iter().enumerate() {
            assert_eq!(k.slot(), i);
            assert!(k.model().params().len() <= MAX_PARAMS, "{k}");
            assert!(k.main_param().is_some(), "{k}: main parameter");
            assert_eq!(EffectKind::from_name(k.name()), Some(*k));
            for (j, p) in k.params().iter().enumerate() {
                assert!(!k.params()[..j].iter().any(|q| q.key == p.key), "{k}");
            }
            s.insert(Effect::unset(*k));
        }
        assert_eq!(s.len(), CATALOGUE_LEN);
    }

    /// The module docs' table lists every catalogue effect with where it acts.
    #[test]
    fn docs_table_matches_the_registry() {
        let src = include_str!("effects.rs");
        for k in EffectKind::ALL {
            let row = std::format!("| `{}` | {} |", k.name(), {
                let d = k.acts_on().describe();
                d.split(" [").next().unwrap_or(d)
            });
            assert!(src.contains(&row), "missing docs row `{row}`");
        }
    }
}
