//! Simulation of a [`Plant`]: the full dynamics of eqs. 19-21 plus every active catalogue effect.
//!
//! # Model
//!
//! ```text
//! T_drv du_drv/dt = k_drv u_in - u_drv                               (driver low-pass, eq. 18)
//! L_a di_a/dt     = u_drv - R_eq i_a - k_e omega_m                   (armature, eq. 19)
//! J_eq domega_m/dt = k_t i_a - B_eq omega_m - tau_m - tau_l / N      (mechanics, eq. 20)
//! ```
//!
//! with u_in = delay(input maps(u)) and the resisting torques of the active effects, read from
//! the registry ([`crate::effects`]) by their [`SimRole`]: tau_m = the smooth motor-side
//! torques, tau_l = dry friction + the smooth load-side torques. With a contact effect (gear
//! play) the mechanics splits into two bodies: the motor side J_eq (1 - f) (rotor and gears) and
//! the load J_eq f (seen at motor side, f = the contact's `load_inertia_fraction`; load-side
//! torques act on it), joined through the play at the load by a spring-damper contact (load
//! side). Viscous friction B_eq is split between the bodies in the same ratio as the inertia, so
//! that a rigid contact gives back eq. 20. Dry friction acts at the load as in eq. 8 (on the load
//! body with play): after a reversal the load stays where friction stopped it while the motor
//! crosses the gap.
//!
//! # Integration
//!
//! The input is held constant over each control period `dt_s` (zero-order hold). The linear part
//! (driver, armature, mechanics, and the contact spring when in contact) is discretised
//! *exactly* with the matrix exponential, precomputed once per simulator for each mode (slipping
//! or stuck, free or in contact). The nonlinear torques (friction, smooth torques) enter as
//! inputs with a first-order hold over internal sub-steps of at most 100 us (an exponential
//! integrator of order 2: predictor with the torque at the start, corrector with the torque at
//! the predicted end). A linear plant (no dry friction, smooth torque or contact) takes a
//! single exact step per period, so the linear case equals the exact ZOH solution.
//!
//! Stick-slip uses a stuck/slipping state machine on the body that carries the dry friction (the
//! whole rigid drivetrain, or the load body with play): when its speed crosses zero it sticks
//! (speed = 0 exactly, the current keeps evolving); it breaks away when the net driving torque on
//! it (motor torque minus the smooth torques, or the contact torque with play) exceeds the
//! breakaway torque of [`Friction::breakaway_l`] (the breakaway level when one is active, else
//! the Coulomb level of that direction). Below breakaway the shaft does not creep and there is
//! no chattering around zero speed. Events (sticking, breakaway, contact) are resolved at
//! sub-step resolution. Against RK4 at 1 us (tests/e2e/sim.rs) the load angle agrees within ~1e-4
//! rad with dry friction, ~1e-6 rad with periodic torques, and ~2-4e-3 rad with gear play
//! (impacts at 100 us resolution; the motor side is put back on the flank when a free sub-step
//! ends in penetration). While a rigid drivetrain is stuck and stays below breakaway, a whole
//! period is one exact step.
//!
//! The simulations a diagnosis runs by the thousand ([`crate::fit::oe`]) go faster with
//! [`PlantSim::with_coarse_periods`]: a period in which no event can happen (the friction body
//! slides on or stays held below breakaway with a margin, the contact stays shut or open with a
//! margin, the friction torque barely changes) is one exact step; any other period runs in
//! sub-steps as above (module `coarse`).
//!
//! The transport `delay` is a fixed-size delay line (no heap) of [`DELAY_CAPACITY`] samples;
//! fractional delays are exact: the period is split at the instant the delayed input switches.
//!
//! # Log convention
//!
//! Row k of a log holds the measurements taken at `time_s[k]` and the voltage u applied from then
//! until row k+1: `state()` at time t_k is measured, then `step(u_k)` advances to t_k + dt_s.

// Small dense matrix code reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

mod coarse;
#[cfg(feature = "alloc")]
pub mod excitation;
pub mod sensors;

use crate::custom::{ActsOn as CustomPlace, CustomSlots};
use crate::effects::torque::{Friction, InputNonlinearity};
use crate::effects::{Contact, Effect, EffectKind, Signals, SimRole};
use crate::linalg::expm;
use crate::math;
use crate::plant::Plant;
use nalgebra::SMatrix;

pub use coarse::{COARSE_EVENT_MARGIN, COARSE_MAX_CONTACT_PHASE, COARSE_MAX_TORQUE_CHANGE};
pub use sensors::{Measurement, SensorConfig, Sensors};

/// Longest input history of the delay line [samples]: the delay may be at most
/// (DELAY_CAPACITY - 2) control periods (1.022 s at 1 kHz).
pub const DELAY_CAPACITY: usize = 1024;

/// Largest internal sub-step [s] when nonlinear mechanical effects are active.
pub const MAX_SUBSTEP_S: f64 = 100e-6;

/// Most sub-steps per control period.
const MAX_SUBSTEPS: usize = 1000;

/// Why a simulator could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    #[error("sample period must be > 0 and finite, got {0} s")]
    BadPeriod(f64),
    #[error(transparent)]
    Params(#[from] crate::params::ParamError),
    #[error(transparent)]
    Effect(#[from] crate::effects::EffectError),
    #[error("effect `delay`: {delay_s} s is longer than the simulator's delay line ({max_s} s at this sample period)")]
    DelayTooLong { delay_s: f64, max_s: f64 },
    #[error("contact effect (gear play): load_inertia_fraction must be strictly between 0 and 1, got {0}")]
    InertiaFraction(f64),
    #[error("effect `{effect}`: `{key}` = {} is not a usable value ({why})", math::Num(*.value))]
    BadValue {
        effect: &'static str,
        key: &'static str,
        value: f64,
        why: &'static str,
    },
    #[error("sample period {dt_s} s needs more than {max} internal sub-steps of {h_s} s")]
    TooManySubsteps { dt_s: f64, h_s: f64, max: usize },
    /// A user-defined effect ([`crate::custom`]) has a parameter without a value.
    #[error("user effect `{effect}`: a parameter has no value")]
    CustomIncomplete { effect: &'static str },
    /// The simulated state left any physical range (non-finite, or absurd angle or speed): the
    /// model or an effect makes it diverge.
    #[error("the simulation diverged at t = {time_s} s (theta_l = {theta_l_rad:e} rad, omega_m = {omega_m_rad_s:e} rad/s): check the plant's parameters and effects")]
    Diverged {
        time_s: f64,
        theta_l_rad: f64,
        omega_m_rad_s: f64,
    },
}

/// The physical state of the simulated gearmotor (true values, before the sensors).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlantState {
    /// Simulated time [s].
    pub time_s: f64,
    /// Driver input actually seen by the driver after the input effects and delay [V] (at
    /// the end of the last period).
    pub u_in_v: f64,
    /// Driver output voltage u_drv [V].
    pub u_drv_v: f64,
    /// Armature current i_a [A].
    pub i_a_a: f64,
    /// Motor speed omega_m [rad/s].
    pub omega_m_rad_s: f64,
    /// Motor angle theta_m [rad].
    pub theta_m_rad: f64,
    /// Load speed omega_l [rad/s] (omega_m / N without play).
    pub omega_l_rad_s: f64,
    /// Load angle theta_l [rad] (theta_m / N without play).
    pub theta_l_rad: f64,
    /// True while dry friction holds the shaft (omega_l = 0 exactly; with play the load body,
    /// without it the whole drivetrain).
    pub stuck: bool,
}

/// The torques acting at the current state, one per effect (see [`crate::effects::torque`] for
/// the sign convention: friction, smooth and contact torques are resisting torques).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Torques {
    /// Motor torque k_t i_a [N m], motor side.
    pub motor_m_nm: f64,
    /// Viscous friction B_eq omega_m [N m], motor side (both bodies with play).
    pub viscous_m_nm: f64,
    /// Dry friction [N m], load side: the kinetic friction while slipping, the holding torque
    /// while stuck.
    pub friction_l_nm: f64,
    /// Sum of the smooth motor-side effect torques [N m] (role [`SimRole::Smooth`]).
    pub smooth_m_nm: f64,
    /// Sum of the smooth load-side effect torques [N m].
    pub smooth_l_nm: f64,
    /// Contact torque transmitted to the load [N m], load side (0 inside the play or without a
    /// contact effect).
    pub contact_l_nm: f64,
}

const NS: usize = 6; // u_drv, i_a, omega_m, theta_m, omega_l, theta_l
const NI: usize = 4; // u_in, tau_m, tau_l, tau_offset (contact spring offset, load side)
const NR: usize = 2; // ramped inputs: tau_m, tau_l
const NA: usize = NS + NI + NR;

/// Exact discretisation of one mode over one sub-step length.
#[derive(Debug, Clone, Copy)]
struct Disc {
    /// State transition exp(A h), by columns: `phi_t[j][i]` is row i, column j (so that a step
    /// adds whole columns, which the compiler vectorises; each row is still summed in column
    /// order).
    phi_t: [[f64; NS]; NS],
    /// Zero-order-hold input matrix (u_in, tau_m, tau_l, tau_offset), by columns as `phi_t`.
    g0_t: [[f64; NS]; NI],
    /// First-order-hold correction for (tau_m, tau_l): response to an input ramping 0 -> 1.
    g1: [[f64; NR]; NS],
}

const ZERO_DISC: Disc = Disc {
    phi_t: [[0.0; NS]; NS],
    g0_t: [[0.0; NS]; NI],
    g1: [[0.0; NR]; NS],
};

/// The contact effect of the plant (load side): its parameters and its kind (for its torque).
#[derive(Debug, Clone, Copy)]
struct Play {
    gap: f64,
    stiffness: f64,
    damping: f64,
    contact: Contact,
    kind: EffectKind,
}

/// Most smooth effects per side.
const MAX_SMOOTH: usize = 4;

/// The smooth torques of one side (motor or load): the active effects of role
/// [`SimRole::Smooth`] acting there, and the last (angle, torque) when every one of them depends
/// on the angle only (reused while the angle is unchanged, e.g. a stuck shaft).
#[derive(Debug, Clone, Copy)]
struct SmoothSide {
    effects: [Option<Effect>; MAX_SMOOTH],
    angle_only: bool,
    cache: (f64, f64),
}

impl SmoothSide {
    fn new(effects: &crate::effects::Effects, side: crate::effects::ActsOn) -> SmoothSide {
        let mut out = SmoothSide {
            effects: [None; MAX_SMOOTH],
            angle_only: true,
            cache: (f64::NAN, 0.0),
        };
        let mut n = 0;
        for e in effects
            .iter()
            .filter(|e| e.kind.sim_role() == SimRole::Smooth && e.kind.acts_on() == side)
        {
            if n < MAX_SMOOTH {
                out.effects[n] = Some(*e);
                out.angle_only &= e.kind.model().depends_on_angle_only();
                n += 1;
            }
        }
        out
    }
    fn is_active(&self) -> bool {
        self.effects[0].is_some()
    }
    /// Sum of the torques at `s` [N m] (0 without effects).
    #[inline]
    fn at(&self, s: &Signals) -> f64 {
        let mut acc: Option<f64> = None;
        for e in self.effects.iter().flatten() {
            let t = e.kind.model().torque_nm(e.values(), s);
            acc = Some(acc.map_or(t, |a| a + t));
        }
        acc.unwrap_or(0.0)
    }
    /// [`Self::at`], reusing the last value while `angle` is unchanged (when allowed).
    #[inline]
    fn cached(&mut self, angle: f64, s: &Signals) -> f64 {
        if !self.is_active() {
            return 0.0;
        }
        if !self.angle_only {
            return self.at(s);
        }
        if angle != self.cache.0 {
            self.cache = (angle, self.at(s));
        }
        self.cache.1
    }
}

/// One control period's delayed inputs (this period's `new` and the last one's `old` [V], for a
/// delay that switches inside the period) and whether the stuck shortcut already stepped it.
struct Period {
    new: f64,
    old: f64,
    held: bool,
}

/// Mode index: bit 0 stuck, bit 1 in contact.
const STUCK: usize = 1;
const CONTACT: usize = 2;

/// A simulated gearmotor advanced one control period at a time.
#[derive(Debug, Clone)]
pub struct PlantSim {
    plant: Plant,
    dt_s: f64,
    // Constants.
    n: f64,
    k_t: f64,
    ns: usize,
    friction: Friction,
    dry: bool,
    input: InputNonlinearity,
    smooth_m: SmoothSide,
    smooth_l: SmoothSide,
    play: Option<Play>,
    substeps: usize,
    /// Delay in whole periods and the sub-step (index, split fraction) where the delayed input
    /// switches inside the period.
    delay_k: usize,
    switch_at: Option<(usize, bool)>,
    /// Discretisations [length][mode]: length 0 = full sub-step, 1 and 2 = the two parts of the
    /// sub-step split by a fractional delay.
    disc: [[Disc; 4]; 3],
    /// Lengths [s] of the three sub-step kinds.
    sub_len: [f64; 3],
    /// Stuck-mode discretisation over a whole period (rigid drivetrain with dry friction only).
    coarse_stuck: Option<Disc>,
    /// Whole-period discretisations, when periods between events are stepped whole
    /// ([`PlantSim::with_coarse_periods`]).
    coarse: Option<coarse::CoarseTables>,
    // State.
    /// What the end of the last period computed when it was stepped whole (it starts the next
    /// one).
    coarse_carry: Option<coarse::Carry>,
    /// Periods stepped whole since the simulator was built.
    whole_periods: u64,
    x: [f64; NS],
    stuck: bool,
    dir: f64,
    steps: u64,
    u_in_v: f64,
    history: [f64; DELAY_CAPACITY],
    head: usize,
    state: PlantState,
    /// User-defined effects ([`crate::custom`]), and whether any acts as a torque.
    custom: CustomSlots,
    custom_torque: bool,
}

impl PlantSim {
    /// A simulator at rest at the origin, with control period `dt_s` [s].
    ///
    /// ```
    /// use servo_core::{sim::PlantSim, Plant, PlantParams};
    /// let mut sim = PlantSim::new(&Plant::from_params(PlantParams::TABLE2)?, 1e-3)?;
    /// for _ in 0..1000 {
    ///     sim.step(5.0); // 5 V for 1 s
    /// }
    /// assert!(sim.state().omega_l_rad_s > 10.0);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn new(plant: &Plant, dt_s: f64) -> Result<PlantSim, SimError> {
        Self::with_max_substep(plant, dt_s, MAX_SUBSTEP_S)
    }

    /// As [`PlantSim::new`] with a chosen largest internal sub-step `max_substep_s` [s] (used
    /// only when nonlinear mechanical effects are active; smaller is more accurate and slower).
    pub fn with_max_substep(
        plant: &Plant,
        dt_s: f64,
        max_substep_s: f64,
    ) -> Result<PlantSim, SimError> {
        if !(dt_s > 0.0 && dt_s.is_finite()) {
            return Err(SimError::BadPeriod(dt_s));
        }
        if !(max_substep_s > 0.0 && max_substep_s.is_finite()) {
            return Err(SimError::BadPeriod(max_substep_s));
        }
        let p = &plant.params;
        p.validate()?;
        for e in plant.effects.iter() {
            e.check_complete()?;
        }
        let fx = &plant.effects;
        let friction = Friction::from_effects(fx);
        if let Some(b) = friction.breakaway {
            if b.omega_s <= 0.0 {
                return Err(SimError::BadValue {
                    effect: "dry friction",
                    key: "omega_s",
                    value: b.omega_s,
                    why: "must be > 0 rad/s",
                });
            }
        }
        let dry = friction.is_active();
        let smooth_m = SmoothSide::new(fx, crate::effects::ActsOn::MotorTorque);
        let smooth_l = SmoothSide::new(fx, crate::effects::ActsOn::LoadTorque);
        let mut frac = 0.3;
        let play = match fx.with_role(SimRole::Contact) {
            Some(e) => {
                let Some(c) = e.kind.model().contact(e.values()) else {
                    return Err(SimError::BadValue {
                        effect: e.kind.name(),
                        key: "gap",
                        value: f64::NAN,
                        why: "the values define no contact",
                    });
                };
                frac = c.load_inertia_fraction;
                if !(frac > 0.0 && frac < 1.0) {
                    return Err(SimError::InertiaFraction(frac));
                }
                if c.stiffness_nm_per_rad <= 0.0 {
                    return Err(SimError::BadValue {
                        effect: e.kind.name(),
                        key: "stiffness",
                        value: c.stiffness_nm_per_rad,
                        why: "must be > 0 N m/rad",
                    });
                }
                Some(Play {
                    gap: c.gap_rad,
                    stiffness: c.stiffness_nm_per_rad,
                    damping: c.damping_nms_per_rad,
                    contact: c,
                    kind: e.kind,
                })
            }
            None => None,
        };
        for c in plant.custom.iter() {
            if !c.is_complete() {
                return Err(SimError::CustomIncomplete { effect: c.name() });
            }
        }
        let custom_torque =
            plant.custom.has(CustomPlace::LoadTorque) || plant.custom.has(CustomPlace::MotorTorque);
        let nonlinear =
            dry || smooth_m.is_active() || smooth_l.is_active() || play.is_some() || custom_torque;
        let substeps = if nonlinear {
            (math::floor(dt_s / max_substep_s - 1e-9) as usize).saturating_add(1)
        } else {
            1
        };
        if substeps > MAX_SUBSTEPS {
            return Err(SimError::TooManySubsteps {
                dt_s,
                h_s: max_substep_s,
                max: MAX_SUBSTEPS,
            });
        }
        let h = dt_s / substeps as f64;

        // Delay: d = (k + f) dt; the delayed input switches at f dt = (j + r) h inside a period.
        let delay_s = fx
            .with_role(SimRole::InputDelay)
            .map_or(0.0, |e| e.kind.model().input_delay_s(e.values()));
        let periods = delay_s / dt_s;
        let mut delay_k = math::floor(periods + 1e-9) as usize;
        let mut f = periods - delay_k as f64;
        if f < 1e-9 {
            f = 0.0;
        }
        if f > 1.0 - 1e-9 {
            f = 0.0;
            delay_k = delay_k.saturating_add(1);
        }
        if delay_k.saturating_add(2) > DELAY_CAPACITY {
            return Err(SimError::DelayTooLong {
                delay_s,
                max_s: (DELAY_CAPACITY - 2) as f64 * dt_s,
            });
        }
        let mut switch_at = None;
        let mut split_r = 0.0;
        if f > 0.0 {
            let s = f * substeps as f64;
            let j = math::floor(s) as usize;
            let r = s - j as f64;
            if r < 1e-9 {
                switch_at = Some((j, false));
            } else if r > 1.0 - 1e-9 {
                switch_at = Some((j + 1, false));
            } else {
                switch_at = Some((j, true));
                split_r = r;
            }
        }

        let n = p.n;
        let ns = if play.is_some() { 6 } else { 4 };
        let mut disc = [[ZERO_DISC; 4]; 3];
        let lengths = [h, split_r * h, (1.0 - split_r) * h];
        let modes: &[usize] = if play.is_some() {
            &[0, STUCK, CONTACT, STUCK | CONTACT]
        } else {
            &[0, STUCK]
        };
        for (li, &len) in lengths.iter().enumerate() {
            if li > 0 && split_r == 0.0 {
                break;
            }
            for &mode in modes {
                disc[li][mode] = discretise(plant, frac, play.as_ref(), mode, len);
            }
        }
        let coarse_stuck = (dry && play.is_none() && substeps > 1 && !custom_torque)
            .then(|| discretise(plant, frac, None, STUCK, dt_s));
        let state = PlantState {
            stuck: dry,
            ..PlantState::default()
        };
        Ok(PlantSim {
            plant: *plant,
            dt_s,
            n,
            k_t: p.k_t,
            ns,
            friction,
            dry,
            input: InputNonlinearity::from_effects(fx),
            smooth_m,
            smooth_l,
            play,
            substeps,
            delay_k,
            switch_at,
            disc,
            sub_len: lengths,
            coarse_stuck,
            coarse: None,
            coarse_carry: None,
            whole_periods: 0,
            x: [0.0; NS],
            stuck: dry,
            dir: 0.0,
            steps: 0,
            u_in_v: 0.0,
            history: [0.0; DELAY_CAPACITY],
            head: 0,
            state,
            custom: plant.custom,
            custom_torque,
        })
    }

    /// The plant being simulated.
    pub fn plant(&self) -> &Plant {
        &self.plant
    }
    /// Control period [s].
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }
    /// Internal sub-steps per control period (1 for a linear plant).
    pub fn substeps(&self) -> usize {
        self.substeps
    }
    /// Control periods stepped whole since the simulator was built (see
    /// [`PlantSim::with_coarse_periods`]; 0 without it).
    pub fn whole_periods(&self) -> u64 {
        self.whole_periods
    }
    /// Current state.
    pub fn state(&self) -> &PlantState {
        &self.state
    }

    /// Replaces the state (e.g. to start from a logged position). Without play the load
    /// states are ignored and derived from the motor's (theta_l = theta_m / N). The shaft is
    /// stuck if `state.stuck` or if it is at rest with dry friction. The delay line is filled
    /// with `state.u_in_v` (the input assumed to have acted before); time continues from
    /// `state.time_s`.
    pub fn reset(&mut self, state: PlantState) {
        self.coarse_carry = None;
        self.x = [
            state.u_drv_v,
            state.i_a_a,
            state.omega_m_rad_s,
            state.theta_m_rad,
            state.omega_l_rad_s,
            state.theta_l_rad,
        ];
        if self.custom.has(CustomPlace::Sensor) {
            // The state given holds the angle as measured: start from the true one.
            let sig = custom_signals(&self.signals(&self.x));
            let th = self.custom.sensor_inverse(state.theta_l_rad, &sig);
            if self.play.is_some() {
                self.x[5] = th;
            } else {
                self.x[3] = th * self.n;
            }
        }
        if self.play.is_none() {
            self.x[4] = self.x[2] / self.n;
            self.x[5] = self.x[3] / self.n;
        }
        let w = self.fb_w();
        self.stuck = self.dry && (state.stuck || self.x[w] == 0.0);
        if self.stuck {
            self.x[w] = 0.0;
        }
        self.dir = math::sign(self.x[w]);
        let t = if state.time_s.is_finite() {
            state.time_s
        } else {
            0.0
        };
        self.steps = math::round(t / self.dt_s).max(0.0) as u64;
        self.u_in_v = state.u_in_v;
        self.history = [state.u_in_v; DELAY_CAPACITY];
        self.head = 0;
        self.publish(t);
    }

    /// Applies driver input `u_v` [V] for one control period (zero-order hold) and returns the
    /// state at the end of it. A non-finite `u_v` is treated as 0 V.
    pub fn step(&mut self, u_v: f64) -> &PlantState {
        let period = self.begin_period(u_v);
        let mut carry = None;
        let fine = !period.held && !self.coarse_period(&period);
        match self.switch_at {
            _ if !fine => {}
            None => {
                for _ in 0..self.substeps {
                    carry = self.substep(0, period.new, carry);
                }
            }
            Some((j, split)) => {
                for i in 0..self.substeps {
                    carry = self.switched_substep(i, j, split, &period, carry);
                }
            }
        }
        self.end_period(period.new);
        &self.state
    }

    /// [`Self::step`] of two simulators of the same plant and period at once: `self` with input
    /// `u_v` [V], `other` with `other_u_v` [V]. Each ends in exactly the state its own
    /// [`Self::step`] would give (the same operations in the same order); their sub-steps
    /// alternate, so that the processor overlaps the two independent chains of arithmetic (one
    /// simulation is a chain of dependent operations that leaves most of a core idle).
    ///
    /// Two simulators that differ in sub-steps or in where a delayed input switches are stepped
    /// in turn.
    pub fn step_pair(&mut self, other: &mut PlantSim, u_v: f64, other_u_v: f64) {
        if self.substeps != other.substeps || self.switch_at != other.switch_at {
            self.step(u_v);
            other.step(other_u_v);
            return;
        }
        let (pa, pb) = (self.begin_period(u_v), other.begin_period(other_u_v));
        let (mut ca, mut cb) = (None, None);
        // The periods each takes in sub-steps (not held stuck, not stepped whole).
        let fa = !pa.held && !self.coarse_period(&pa);
        let fb = !pb.held && !other.coarse_period(&pb);
        match self.switch_at {
            None => {
                for _ in 0..self.substeps {
                    if fa {
                        ca = self.substep(0, pa.new, ca);
                    }
                    if fb {
                        cb = other.substep(0, pb.new, cb);
                    }
                }
            }
            Some((j, split)) => {
                for i in 0..self.substeps {
                    if fa {
                        ca = self.switched_substep(i, j, split, &pa, ca);
                    }
                    if fb {
                        cb = other.switched_substep(i, j, split, &pb, cb);
                    }
                }
            }
        }
        self.end_period(pa.new);
        other.end_period(pb.new);
    }

    /// Sub-step `i` of a period whose delayed input switches at sub-step `j` (`split`: inside
    /// it, which then runs as its two parts).
    #[inline]
    fn switched_substep(
        &mut self,
        i: usize,
        j: usize,
        split: bool,
        period: &Period,
        carry: Option<(f64, f64)>,
    ) -> Option<(f64, f64)> {
        if i == j && split {
            let carry = self.substep(1, period.old, carry);
            self.substep(2, period.new, carry)
        } else {
            self.substep(0, if i < j { period.old } else { period.new }, carry)
        }
    }

    /// The start of a control period with driver input `u_v` [V]: the input effects and the
    /// delay line, and whether dry friction holds the shaft over the whole period (then already
    /// stepped, see [`Self::stays_stuck_over_period`]).
    #[inline]
    fn begin_period(&mut self, u_v: f64) -> Period {
        let mut u = if u_v.is_finite() {
            self.input.apply(u_v)
        } else {
            0.0
        };
        if self.custom.has(CustomPlace::Input) {
            let mut sig = custom_signals(&self.signals(&self.x));
            sig[5] = u;
            sig[6] = self.steps as f64 * self.dt_s;
            u = self.custom.input(&sig);
            if !u.is_finite() {
                u = 0.0;
            }
        }
        // Delay line: history[head] is the newest input.
        self.head = (self.head + 1) % DELAY_CAPACITY;
        self.history[self.head] = u;
        let new = self.history[(self.head + DELAY_CAPACITY - self.delay_k) % DELAY_CAPACITY];
        let old = self.history[(self.head + DELAY_CAPACITY - self.delay_k - 1) % DELAY_CAPACITY];
        let held = self.switch_at.is_none() && self.stuck && self.stays_stuck_over_period(new);
        Period { new, old, held }
    }

    /// The end of a control period whose delayed input was `new` [V]: time and the published
    /// state.
    #[inline]
    fn end_period(&mut self, new: f64) {
        self.u_in_v = new;
        self.steps += 1;
        self.publish(self.steps as f64 * self.dt_s);
    }

    /// Shortcut for a rigid drivetrain held by dry friction: one exact step over the whole period
    /// in the stuck mode, accepted when the driving torque stays below breakaway at both ends.
    /// While stuck the angles are fixed and the current follows two first-order lags in series
    /// (no overshoot), so the driving torque is monotone over the period and never exceeds
    /// breakaway in between. Returns false (state untouched) otherwise.
    fn stays_stuck_over_period(&mut self, u: f64) -> bool {
        let Some(coarse) = &self.coarse_stuck else {
            return false;
        };
        let x0 = self.x;
        let x1 = advance::<4>(coarse, &x0, &[u, 0.0, 0.0, 0.0]);
        let (tau_m, tau_l) = self.smooth_cached(&x0);
        let holds = |sim: &Self, x: &[f64; NS]| {
            let d = sim.drive_torque_l_with(x, tau_m, tau_l);
            d.abs() <= sim.friction.breakaway_l(math::sign(d))
        };
        if holds(self, &x0) && holds(self, &x1) {
            self.x = x1;
            self.x[2] = 0.0;
            self.x[3] = x0[3];
            true
        } else {
            false
        }
    }

    /// The torque of every effect at the current state.
    pub fn torques(&self) -> Torques {
        let x = &self.x;
        let b_eq = self.plant.b_eq();
        let sig = self.signals(x);
        let (cm, cl) = self.custom_torques(&sig);
        let smooth_m = self.smooth_m.at(&sig) + cm;
        let smooth_l = self.smooth_l.at(&sig) + cl;
        let contact = self.contact_torque_l(x);
        let friction = if !self.dry {
            0.0
        } else if self.stuck {
            self.drive_torque_l(x)
        } else {
            self.friction.torque_l(self.fb_speed_l(x), self.dir)
        };
        let viscous = match self.play {
            Some(pl) => {
                let f = pl.contact.load_inertia_fraction;
                b_eq * ((1.0 - f) * x[2] + f * self.n * x[4])
            }
            None => crate::effects::viscous::torque_m(b_eq, x[2]),
        };
        Torques {
            motor_m_nm: self.k_t * x[1],
            viscous_m_nm: viscous,
            friction_l_nm: friction,
            smooth_m_nm: smooth_m,
            smooth_l_nm: smooth_l,
            contact_l_nm: contact,
        }
    }

    fn publish(&mut self, time_s: f64) {
        let x = &self.x;
        let (omega_l, mut theta_l) = match self.play {
            Some(_) => (x[4], x[5]),
            None => (x[2] / self.n, x[3] / self.n),
        };
        if self.custom.has(CustomPlace::Sensor) {
            // With a user sensor effect the published load angle is the one measured.
            let mut sig = custom_signals(&self.signals(x));
            sig[6] = time_s;
            theta_l = self.custom.sensor(&sig);
        }
        self.state = PlantState {
            time_s,
            u_in_v: self.u_in_v,
            u_drv_v: x[0],
            i_a_a: x[1],
            omega_m_rad_s: x[2],
            theta_m_rad: x[3],
            omega_l_rad_s: omega_l,
            theta_l_rad: theta_l,
            stuck: self.stuck,
        };
    }

    #[inline]
    fn theta_l(&self, x: &[f64; NS]) -> f64 {
        if self.play.is_some() {
            x[5]
        } else {
            x[3] / self.n
        }
    }

    /// Contact torque on the load [N m] (0 without play or inside the gap).
    #[inline]
    fn contact_torque_l(&self, x: &[f64; NS]) -> f64 {
        match &self.play {
            Some(b) => b.kind.model().contact_torque_l(
                &b.contact,
                x[3] / self.n - x[5],
                x[2] / self.n - x[4],
            ),
            None => 0.0,
        }
    }

    /// The signals the effects see at state `x` (time: the start of the control period; u: the
    /// driver input of this period after the input effects).
    #[inline]
    fn signals(&self, x: &[f64; NS]) -> Signals {
        Signals {
            t_s: self.state.time_s,
            theta_l_rad: self.theta_l(x),
            theta_m_rad: x[3],
            omega_l_rad_s: self.fb_speed_l(x),
            omega_m_rad_s: x[2],
            i_a_a: x[1],
            u_v: self.u_in_v,
        }
    }

    /// Smooth (motor side, load side) torques at `x` [N m], reusing the last values while the
    /// angles are unchanged (when every effect allows it).
    #[inline(always)]
    fn smooth_cached(&mut self, x: &[f64; NS]) -> (f64, f64) {
        if !self.smooth_m.is_active() && !self.smooth_l.is_active() && !self.custom_torque {
            return (0.0, 0.0);
        }
        self.smooth_cached_active(x)
    }

    /// [`Self::smooth_cached`] with some smooth or user torque active (out of line: the check
    /// above stays inline in every sub-step).
    #[inline(never)]
    fn smooth_cached_active(&mut self, x: &[f64; NS]) -> (f64, f64) {
        let sig = self.signals(x);
        let (cm, cl) = self.custom_torques(&sig);
        let tau_m = self.smooth_m.cached(x[3], &sig) + cm;
        let tau_l = self.smooth_l.cached(sig.theta_l_rad, &sig) + cl;
        (tau_m, tau_l)
    }

    /// User-defined (motor side, load side) torques [N m] at `sig`, evaluated every time (they
    /// may depend on any signal).
    #[inline]
    fn custom_torques(&self, sig: &Signals) -> (f64, f64) {
        if !self.custom_torque {
            return (0.0, 0.0);
        }
        let s = custom_signals(sig);
        (
            self.custom.torque(CustomPlace::MotorTorque, &s),
            self.custom.torque(CustomPlace::LoadTorque, &s),
        )
    }

    /// Index of the speed of the body that carries the dry friction (omega_m rigid, omega_l with
    /// play); its angle is the next index.
    #[inline]
    fn fb_w(&self) -> usize {
        if self.play.is_some() {
            4
        } else {
            2
        }
    }

    /// Load-side speed of the friction body [rad/s].
    #[inline]
    fn fb_speed_l(&self, x: &[f64; NS]) -> f64 {
        if self.play.is_some() {
            x[4]
        } else {
            x[2] / self.n
        }
    }

    /// Net torque driving the friction body at rest [N m], load side: without play N (k_t i_a -
    /// tau_m) - tau_l; with play contact torque - tau_l (tau_m, tau_l: the smooth torques).
    fn drive_torque_l(&self, x: &[f64; NS]) -> f64 {
        let sig = self.signals(x);
        let (cm, cl) = self.custom_torques(&sig);
        let tau_l = self.smooth_l.at(&sig) + cl;
        let tau_m = self.smooth_m.at(&sig) + cm;
        self.drive_torque_l_with(x, tau_m, tau_l)
    }

    /// [`Self::drive_torque_l`] with the smooth torques given (tau_m [N m, motor side], tau_l
    /// [N m, load side]).
    #[inline]
    fn drive_torque_l_with(&self, x: &[f64; NS], tau_m: f64, tau_l: f64) -> f64 {
        match self.play {
            Some(_) => self.contact_torque_l(x) - tau_l,
            None => (self.k_t * x[1] - tau_m) * self.n - tau_l,
        }
    }

    /// Nonlinear input torques (tau_m motor side, tau_l load side) at state `x`.
    #[inline]
    fn nonlinear_torques(&mut self, x: &[f64; NS]) -> (f64, f64) {
        let (mut tau_m, mut tau_l) = self.smooth_cached(x);
        if self.dry && !self.stuck {
            // Friction of the current slip direction; a predicted reversal is held at zero speed
            // (the reversal itself is an event).
            let w = self.fb_speed_l(x);
            let w = if w * self.dir < 0.0 { 0.0 } else { w };
            let f = self.friction.torque_l(w, self.dir);
            if self.play.is_some() {
                tau_l += f;
            } else {
                tau_m += f / self.n;
            }
        }
        (tau_m, tau_l)
    }

    /// The contact mode (free or [`CONTACT`]) and the spring's offset torque [N m] for the motor
    /// at `delta` [rad, load side] from the middle of the gap, moving at `rate` [rad/s] against
    /// the load (free without play).
    #[inline]
    fn contact_mode(&self, (delta, rate): (f64, f64)) -> (usize, f64) {
        let Some(b) = &self.play else {
            return (0, 0.0);
        };
        let side = if delta > 0.0 { 1.0 } else { -1.0 };
        // Penetration beyond the flank (tiny negative values: on the flank after a projection,
        // up to rounding).
        let p = side * (side * delta - 0.5 * b.gap);
        // Without play the contact never opens: a compliance (shaft, coupling) is a linear
        // spring-damper that pulls as well as pushes.
        if b.gap <= 0.0
            || (side * p >= -1e-12 * b.gap.max(1e-9)
                && side * (b.stiffness * p + b.damping * rate) > 0.0)
        {
            (CONTACT, side * b.stiffness * 0.5 * b.gap)
        } else {
            (0, 0.0)
        }
    }

    /// One internal sub-step of length index `li` with driver input `u` held. `carry`: the
    /// nonlinear torques at the start, when known from the previous sub-step's prediction.
    fn substep(&mut self, li: usize, u: f64, carry: Option<(f64, f64)>) -> Option<(f64, f64)> {
        let mut carry = carry;
        // Breakaway.
        if self.stuck {
            let x = self.x;
            let (tau_m, tau_l) = self.smooth_cached(&x);
            let drive = self.drive_torque_l_with(&x, tau_m, tau_l);
            let dir = math::sign(drive);
            if dir != 0.0 && dir * drive > self.friction.breakaway_l(dir) {
                self.stuck = false;
                self.dir = dir;
                carry = None;
            }
        }
        // Contact mode.
        let delta = self.x[3] / self.n - self.x[5];
        let rate = self.x[2] / self.n - self.x[4];
        let (contact, tau_offset) = self.contact_mode((delta, rate));
        let mode = contact | if self.stuck { STUCK } else { 0 };
        let (tm0, tl0) = match carry {
            Some(t) => t,
            None => {
                let x = self.x;
                self.nonlinear_torques(&x)
            }
        };
        let d = &self.disc[li][mode];
        let x0 = self.x;
        let inp = [u, tm0, tl0, tau_offset];
        let xp = if self.ns == 4 {
            advance::<4>(d, &x0, &inp)
        } else {
            advance::<6>(d, &x0, &inp)
        };
        let (tm1, tl1) = self.nonlinear_torques(&xp);
        let (dm, dl) = (tm1 - tm0, tl1 - tl0);
        let d = &self.disc[li][mode];
        // Stored one element at a time: a copy of the whole array would read back, in wider
        // loads, the element-wide stores just made (a stalled store forwarding on x86).
        let ns = self.ns;
        for (i, x) in self.x.iter_mut().enumerate() {
            *x = if i < ns {
                xp[i] + (d.g1[i][0] * dm + d.g1[i][1] * dl)
            } else {
                xp[i]
            };
        }
        let mut next = Some((tm1, tl1));
        let w = self.fb_w();
        if mode & STUCK != 0 {
            self.x[w] = 0.0;
            self.x[w + 1] = x0[w + 1];
        } else if self.dry {
            let w0 = x0[w];
            let w1 = self.x[w];
            if w1 * self.dir <= 0.0 {
                // The friction body stops within this sub-step: it sticks at the zero crossing
                // (the part of the sub-step after it is taken as stuck); breakaway is checked at
                // the start of the next sub-step.
                let h = self.sub_len[li];
                let tc = if (w0 - w1).abs() > 0.0 && w0 * self.dir > 0.0 {
                    h * w0 / (w0 - w1)
                } else {
                    0.0
                };
                self.x[w + 1] -= 0.5 * w1 * (h - tc);
                self.x[w] = 0.0;
                self.stuck = true;
                next = None;
            } else {
                self.dir = math::sign(w1);
            }
        }
        if let Some(b) = &self.play {
            if mode & CONTACT == 0 {
                // Entering contact during a free sub-step: put the motor side back on the flank
                // (no spurious spring energy; the load, which the encoder sees and friction may
                // hold, is not moved), keep the speeds; contact starts next sub-step.
                let delta = self.x[3] / self.n - self.x[5];
                let p = b.kind.model().contact_penetration_l(&b.contact, delta);
                if p != 0.0 {
                    self.x[3] -= p * self.n;
                    next = None;
                }
            }
        }
        next
    }
}

/// The signals of user-defined effects, in [`crate::custom::SIGNALS`] order.
#[inline]
fn custom_signals(s: &Signals) -> [f64; 7] {
    [
        s.theta_l_rad,
        s.theta_m_rad,
        s.omega_l_rad_s,
        s.omega_m_rad_s,
        s.i_a_a,
        s.u_v,
        s.t_s,
    ]
}

/// x+ = Phi x + G0 inp over the first `N` states (4 rigid, 6 with play).
#[inline(always)]
fn advance<const N: usize>(d: &Disc, x0: &[f64; NS], inp: &[f64; NI]) -> [f64; NS] {
    // Column by column: row i sums phi[i][0] x0[0], ..., phi[i][N-1] x0[N-1], then the inputs,
    // in that order, from zero (the same arithmetic as a dot product per row).
    let mut xp = [0.0; NS];
    for j in 0..N {
        let (col, xj) = (&d.phi_t[j], x0[j]);
        for i in 0..N {
            xp[i] += col[i] * xj;
        }
    }
    for j in 0..NI {
        let (col, uj) = (&d.g0_t[j], inp[j]);
        for i in 0..N {
            xp[i] += col[i] * uj;
        }
    }
    xp
}

/// Exact discretisation of mode `mode` over a sub-step `h` [s] (zero-order hold of u_in and of
/// the torques, plus the first-order-hold correction of the torques).
fn discretise(plant: &Plant, frac: f64, play: Option<&Play>, mode: usize, h: f64) -> Disc {
    let p = &plant.params;
    let (n, k_t, k_e) = (p.n, p.k_t, p.k_e);
    let (t_drv, l_a, r_eq) = (p.t_drv(), p.l_a, p.r_eq());
    let (j_eq, b_eq) = (p.j_eq(), plant.b_eq());
    let mut a = [[0.0; NS]; NS];
    let mut b = [[0.0; NI]; NS];
    a[0][0] = -1.0 / t_drv;
    b[0][0] = p.k_drv / t_drv;
    a[1][0] = 1.0 / l_a;
    a[1][1] = -r_eq / l_a;
    a[1][2] = -k_e / l_a;
    a[3][2] = 1.0;
    match play {
        None => {
            a[2][1] = k_t / j_eq;
            a[2][2] = -b_eq / j_eq;
            b[2][1] = -1.0 / j_eq;
            b[2][2] = -1.0 / (n * j_eq);
        }
        Some(bl) => {
            let (j1, b1) = (j_eq * (1.0 - frac), b_eq * (1.0 - frac));
            let (j2, b2) = (n * n * j_eq * frac, n * n * b_eq * frac);
            a[2][1] = k_t / j1;
            a[2][2] = -b1 / j1;
            b[2][1] = -1.0 / j1;
            a[4][4] = -b2 / j2;
            b[4][2] = -1.0 / j2;
            a[5][4] = 1.0;
            if mode & CONTACT != 0 {
                // tau_c = k (theta_m/N - theta_l) + c (omega_m/N - omega_l) - tau_offset
                let (k, c) = (bl.stiffness, bl.damping);
                let row_c = [0.0, 0.0, c / n, k / n, -c, -k];
                for j in 0..NS {
                    a[2][j] -= row_c[j] / (n * j1);
                    a[4][j] += row_c[j] / j2;
                }
                b[2][3] = 1.0 / (n * j1);
                b[4][3] = -1.0 / j2;
            }
        }
    }
    if mode & STUCK != 0 {
        // Dry friction holds the friction body: its speed row is zero.
        let w = if play.is_some() { 4 } else { 2 };
        a[w] = [0.0; NS];
        b[w] = [0.0; NI];
    }
    // Augmented matrix (Van Loan): exp([[A h, B h, 0], [0, 0, E], [0, 0, 0]]) with E feeding the
    // ramp generators of the torque inputs.
    let mut m = SMatrix::<f64, NA, NA>::zeros();
    for i in 0..NS {
        for j in 0..NS {
            m[(i, j)] = a[i][j] * h;
        }
        for j in 0..NI {
            m[(i, NS + j)] = b[i][j] * h;
        }
    }
    m[(NS + 1, NS + NI)] = 1.0;
    m[(NS + 2, NS + NI + 1)] = 1.0;
    let e = expm(&m);
    let mut d = ZERO_DISC;
    for i in 0..NS {
        for j in 0..NS {
            d.phi_t[j][i] = e[(i, j)];
        }
        for j in 0..NI {
            d.g0_t[j][i] = e[(i, NS + j)];
        }
        for j in 0..NR {
            d.g1[i][j] = e[(i, NS + NI + j)];
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::Effect;

    fn plant_with(specs: &[&str]) -> Plant {
        let mut p = Plant::nominal();
        p.effects
            .insert(Effect::parse("viscous:b_eq=1e-6").unwrap());
        for s in specs {
            p.effects.insert(Effect::parse(s).unwrap());
        }
        p
    }

    #[test]
    fn steady_speed_matches_dc_gain() {
        let p = plant_with(&[]);
        let mut sim = PlantSim::new(&p, 1e-3).unwrap();
        assert_eq!(sim.substeps(), 1);
        for _ in 0..2000 {
            sim.step(5.0);
        }
        let k = &p.params;
        let w = k.k_drv * k.k_t * 5.0 / (k.r_eq() * 1e-6 + k.k_t * k.k_e);
        assert!(
            (sim.state().omega_m_rad_s - w).abs() < 1e-6 * w,
            "{} vs {w}",
            sim.state().omega_m_rad_s
        );
        assert!((sim.state().time_s - 2.0).abs() < 1e-12);
    }

    /// Two simulators stepped as a pair end every period exactly where each alone does, with
    /// dry friction (stuck spells), a gear play and a delay that switches inside the period.
    #[test]
    fn a_pair_steps_exactly_as_each_alone() {
        // The gear play found through the registry (its contact role), not by name.
        let play = EffectKind::ALL
            .into_iter()
            .find(|k| k.sim_role() == SimRole::Contact)
            .unwrap();
        let play = alloc::format!("{play}:gap=0.03");
        for (specs, whole) in [
            (&["coulomb:tau_sf=0.009", play.as_str()][..], false),
            (&["coulomb:tau_sf=0.009", "delay:delay=0.00125"][..], false),
            (&["coulomb:tau_sf=0.009", play.as_str()][..], true),
            (&["coulomb:tau_sf=0.009", "delay:delay=0.00125"][..], true),
        ] {
            let p = plant_with(specs);
            let mut a = PlantSim::new(&p, 1e-3).unwrap();
            if whole {
                a = a.with_coarse_periods();
            }
            let mut b = a.clone();
            let (mut a2, mut b2) = (a.clone(), a.clone());
            for k in 0..3000 {
                let t = k as f64 * 1e-3;
                let (ua, ub) = (
                    3.0 * math::sin(7.0 * t),
                    if k % 400 < 200 { 2.0 } else { -0.3 },
                );
                a.step_pair(&mut b, ua, ub);
                a2.step(ua);
                b2.step(ub);
                assert_eq!(a.state(), a2.state(), "{specs:?} at {k}");
                assert_eq!(b.state(), b2.state(), "{specs:?} at {k}");
            }
        }
    }

    /// Load angles of a fine and a coarse-period simulation of `specs` driven by a varied input
    /// (sines with reversals, steps) over 6 s: the largest difference [rad] and the share of
    /// periods stepped whole.
    fn fine_against_coarse(specs: &[&str]) -> (f64, f64) {
        let p = plant_with(specs);
        let mut fine = PlantSim::new(&p, 1e-3).unwrap();
        let mut coarse = fine.clone().with_coarse_periods();
        let mut worst: f64 = 0.0;
        let periods = 6000;
        for k in 0..periods {
            let t = k as f64 * 1e-3;
            let u = 4.0 * math::sin(2.0 * t)
                + 1.5 * math::sin(11.0 * t)
                + if k % 1500 < 700 { 1.0 } else { -2.0 };
            fine.step(u);
            coarse.step(u);
            worst = worst.max((fine.state().theta_l_rad - coarse.state().theta_l_rad).abs());
        }
        (worst, coarse.whole_periods() as f64 / periods as f64)
    }

    /// The catalogue effect of simulation role `role` with a parameter `key`, found through the
    /// registry (not by name).
    fn effect_by(role: SimRole, key: &str) -> EffectKind {
        EffectKind::ALL
            .into_iter()
            .find(|k| k.sim_role() == role && k.params().iter().any(|p| p.key == key))
            .unwrap()
    }

    #[test]
    fn whole_periods_follow_the_sub_steps() {
        let play = alloc::format!("{}:gap=0.03", effect_by(SimRole::Contact, "gap"));
        // A breakaway friction with its speed scale, an angle-periodic torque.
        let hump = alloc::format!(
            "{}:tau_s=0.02,omega_s=0.8",
            effect_by(SimRole::DryFriction, "omega_s")
        );
        let ripple = alloc::format!(
            "{}:amplitude=0.002,harmonic=4,phase=0",
            effect_by(SimRole::Smooth, "harmonic")
        );
        // Within the sub-steps' own accuracy against RK4 at 1 us (module docs): ~1e-4 rad with
        // dry friction, 2-4e-3 rad with a gear play (whose impacts and stops at reversals make
        // the two drift apart by an event's resolution each time). Each against RK4:
        // tests/e2e/sim.rs.
        for (specs, bar_rad) in [
            (&["coulomb:tau_sf=0.009"][..], 1e-6),
            (
                &["coulomb:tau_sf=0.009", hump.as_str(), "delay:delay=0.00125"][..],
                1e-4,
            ),
            (&["coulomb:tau_sf=0.009", play.as_str()][..], 4e-3),
            (
                &["coulomb:tau_sf=0.009", play.as_str(), "delay:delay=0.0304"][..],
                4e-3,
            ),
        ] {
            let (worst, share) = fine_against_coarse(specs);
            std::eprintln!(
                "{specs:?}: largest difference {worst:.2e} rad, {:.0} % of the periods whole",
                100.0 * share
            );
            assert!(share > 0.5, "{specs:?}: only {share} of the periods whole");
            assert!(worst < bar_rad, "{specs:?}: {worst} rad apart");
        }
        // An angle-dependent torque is always sub-stepped.
        let (worst, share) = fine_against_coarse(&["coulomb:tau_sf=0.009", ripple.as_str()]);
        assert_eq!((worst, share), (0.0, 0.0));
    }

    /// A load held by dry friction while the motor crosses the gap and presses on a flank (with
    /// play), or while a delayed input switches inside the period (without): the held periods
    /// are stepped whole, the load does not move, the motor and the current follow the
    /// sub-steps to rounding, and the breakaway that ends the hold falls in the same period.
    #[test]
    fn held_periods_are_stepped_whole() {
        let play = alloc::format!("{}:gap=0.03", effect_by(SimRole::Contact, "gap"));
        for specs in [
            &["coulomb:tau_sf=0.009", play.as_str()][..],
            &["coulomb:tau_sf=0.009", "delay:delay=0.00125"][..],
        ] {
            let p = plant_with(specs);
            let mut fine = PlantSim::new(&p, 1e-3).unwrap();
            let mut coarse = fine.clone().with_coarse_periods();
            // 0.02 V drives less than half the breakaway torque through the gearbox; the sign
            // flips every 0.5 s (the motor crosses the gap), then 2 V breaks the load away.
            let (hold, periods) = (4000, 4500);
            let (mut worst_m, mut worst_i): (f64, f64) = (0.0, 0.0);
            let mut whole_in_hold = 0;
            for k in 0..periods {
                let u = if k >= hold {
                    2.0
                } else if (k / 500) % 2 == 0 {
                    0.02
                } else {
                    -0.02
                };
                let before = coarse.whole_periods();
                fine.step(u);
                coarse.step(u);
                let (f, c) = (fine.state(), coarse.state());
                if k < hold {
                    whole_in_hold += (coarse.whole_periods() - before) as usize;
                    assert!(f.stuck && c.stuck, "{specs:?}: broke away at {k}");
                    assert_eq!(c.theta_l_rad, 0.0, "{specs:?}: the held load moved");
                }
                assert_eq!(
                    f.stuck, c.stuck,
                    "{specs:?}: breakaway at another period ({k})"
                );
                worst_m = worst_m.max((f.theta_m_rad - c.theta_m_rad).abs());
                worst_i = worst_i.max((f.i_a_a - c.i_a_a).abs());
            }
            std::eprintln!(
                "{specs:?}: {whole_in_hold} of {hold} held periods whole, motor {worst_m:.1e} \
                 rad and current {worst_i:.1e} A apart"
            );
            assert!(
                whole_in_hold > hold * 8 / 10,
                "{specs:?}: {whole_in_hold} whole"
            );
            assert!(
                worst_m < 1e-6 && worst_i < 1e-6,
                "{specs:?}: {worst_m} rad {worst_i} A"
            );
        }
    }

    #[test]
    fn rejects_a_bad_period() {
        assert!(matches!(
            PlantSim::new(&Plant::nominal(), 0.0),
            Err(SimError::BadPeriod(_))
        ));
    }
}
