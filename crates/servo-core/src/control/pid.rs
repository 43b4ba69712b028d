//! Discrete PID controller in parallel form, for the position loop of the handout (sec. 3):
//!
//! ```text
//! C(s) = K_P + K_I / s + K_D s / (T_L s + 1)        (eqs. 42, 53)
//! ```
//!
//! acting on the load-angle error e = r - y [rad] and producing the driver input u [V]. The
//! controller is pure: it holds its own state and knows nothing about sensors, clocks or plants;
//! the run loop feeds it reference, measurement and feedforward each sample.
//!
//! # Discretisation (sample period T_s)
//! The integral and the real derivative are discretised with the same rule:
//!
//! * [`Discretization::BackwardEuler`], s = (1 - z^-1) / T_s:
//!   `I_k = I_{k-1} + K_I T_s e_k`,
//!   `f_k = T_L/(T_L + T_s) f_{k-1} + (x_k - x_{k-1}) / (T_L + T_s)`.
//! * [`Discretization::Tustin`], s = 2/T_s (1 - z^-1)/(1 + z^-1):
//!   `I_k = I_{k-1} + K_I T_s (e_k + e_{k-1}) / 2`,
//!   `f_k = (2 T_L - T_s)/(2 T_L + T_s) f_{k-1} + 2 (x_k - x_{k-1}) / (2 T_L + T_s)`.
//!
//! where `f` is the filtered derivative [rad/s] of the derivative input x (the error e, or -y with
//! [`DerivativeOn::Measurement`]) and `D_k = K_D f_k`. With T_L = 0 both rules use the plain
//! backward difference `f_k = (x_k - x_{k-1}) / T_s` (Tustin's ideal differentiator has a pole at
//! z = -1 and would ring). Note that Tustin with 0 < T_L < T_s/2 gives a negative filter pole
//! (alternating sign); choose T_L >= T_s/2 with Tustin.
//!
//! Output: `v_k = P_k + I_k + D_k + FF_k`, `u_k = clamp(v_k, u_min, u_max)`, `P_k = K_P e_k`.
//!
//! # Initial conditions
//! After [`Pid::new`] or [`Pid::reset`] the integral, the filtered derivative and the previous
//! error are zero (the controller starts from rest), except that the previous derivative input
//! `x_{-1}` is taken equal to the first `x_0`: the first sample has no derivative kick, because the
//! history of the measurement before the controller started is unknown.
//!
//! # Anti-windup
//! * [`AntiWindup::None`]: the integral runs free.
//! * [`AntiWindup::Clamping`] (conditional integration): the integral is not updated on a sample
//!   where the output would saturate and the integral increment pushes further into that limit.
//! * [`AntiWindup::BackCalculation`] with gain K_w [1/s]: `dI/dt = K_I e + K_w (u - v)`, with the
//!   tracking term taken implicitly (backward Euler, evaluated at the current sample), so it is
//!   stable for any K_w T_s: when saturated at u_max,
//!   `I_k = (I_k' + T_s K_w (u_max - P_k - D_k - FF_k)) / (1 + T_s K_w)` where I_k' is the
//!   integral after the ordinary increment.
//!
//! # Bumpless gain change
//! [`Pid::set_gains`] changes K_P, K_I, K_D, T_L and moves the integral by the jump the new gains
//! would cause in P + D at the last sample, so the output is continuous. The integral is stored in
//! volts (the integral of K_I e) and the derivative state in rad/s, so K_I and K_D changes need no
//! state rescaling.
//!
//! Non-finite inputs (NaN/inf reference, measurement or feedforward) do not touch the state; the
//! output repeats the last one with [`PidOutput::invalid_input`] set.

use super::{check_non_negative, check_positive, ControlError};

/// What the derivative term differentiates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum DerivativeOn {
    /// The error e = r - y (the linear controller C(s) of the design; kicks on reference steps).
    #[default]
    Error,
    /// Minus the measurement, -y (no derivative kick on reference steps; same loop gain). When
    /// tracking a moving reference with feedforward, prefer [`DerivativeOn::Error`]: on the
    /// measurement the D term brakes the motion by K_D omega_ref and undoes part of the feedforward.
    Measurement,
}

/// Discretisation rule for the integral and the derivative.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Discretization {
    /// s = (1 - z^-1)/T_s.
    #[default]
    BackwardEuler,
    /// s = 2/T_s (1 - z^-1)/(1 + z^-1) (bilinear).
    Tustin,
}

/// Anti-windup scheme.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum AntiWindup {
    /// No anti-windup: the integral runs free during saturation.
    #[default]
    None,
    /// Conditional integration: freeze the integral while saturated in the increment's direction.
    Clamping,
    /// Back-calculation: feed (u - v) back into the integral with gain `kw` [1/s].
    BackCalculation {
        /// Tracking gain K_w [1/s] (a common choice is sqrt(K_I/K_D) or 1/T_I..10/T_I).
        kw: f64,
    },
}

/// The four gains of the parallel PID, as `servo design` writes them.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct PidGains {
    /// Proportional gain K_P [V/rad].
    pub kp: f64,
    /// Integral gain K_I [V/(rad s)].
    pub ki: f64,
    /// Derivative gain K_D [V s/rad].
    pub kd: f64,
    /// Real-derivative time constant T_L [s] (eq. 53); 0 = ideal (backward difference).
    pub tl_s: f64,
}

impl PidGains {
    /// Checks every gain is finite and >= 0.
    pub fn validate(&self) -> Result<(), ControlError> {
        check_non_negative("kp", "V/rad", self.kp)?;
        check_non_negative("ki", "V/(rad s)", self.ki)?;
        check_non_negative("kd", "V s/rad", self.kd)?;
        check_non_negative("tl_s", "s", self.tl_s)?;
        Ok(())
    }
}

/// Full configuration of a [`Pid`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct PidConfig {
    /// Proportional gain K_P [V/rad].
    pub kp: f64,
    /// Integral gain K_I [V/(rad s)].
    pub ki: f64,
    /// Derivative gain K_D [V s/rad].
    pub kd: f64,
    /// Real-derivative time constant T_L [s]; 0 = ideal derivative (backward difference).
    pub tl_s: f64,
    /// Sample period T_s [s].
    pub ts_s: f64,
    /// Derivative on the error or on the measurement.
    pub derivative_on: DerivativeOn,
    /// Discretisation of the integral and the derivative.
    pub discretization: Discretization,
    /// Lower output limit [V] (`f64::NEG_INFINITY` for none).
    pub u_min_v: f64,
    /// Upper output limit [V] (`f64::INFINITY` for none).
    pub u_max_v: f64,
    /// Anti-windup scheme.
    pub anti_windup: AntiWindup,
}

impl PidConfig {
    /// Gains at sample period `ts_s` [s] with the defaults: derivative on error, backward Euler,
    /// no output limits, no anti-windup.
    pub fn new(gains: PidGains, ts_s: f64) -> PidConfig {
        PidConfig {
            kp: gains.kp,
            ki: gains.ki,
            kd: gains.kd,
            tl_s: gains.tl_s,
            ts_s,
            derivative_on: DerivativeOn::Error,
            discretization: Discretization::BackwardEuler,
            u_min_v: f64::NEG_INFINITY,
            u_max_v: f64::INFINITY,
            anti_windup: AntiWindup::None,
        }
    }

    /// The same configuration with symmetric output limits +-`limit_v` [V].
    pub fn with_symmetric_limit(self, limit_v: f64) -> PidConfig {
        PidConfig {
            u_min_v: -limit_v,
            u_max_v: limit_v,
            ..self
        }
    }

    /// The four gains.
    pub fn gains(&self) -> PidGains {
        PidGains {
            kp: self.kp,
            ki: self.ki,
            kd: self.kd,
            tl_s: self.tl_s,
        }
    }

    /// Checks gains (finite, >= 0), period (> 0), limits (ordered, not NaN) and K_w (finite, >= 0).
    pub fn validate(&self) -> Result<(), ControlError> {
        self.gains().validate()?;
        check_positive("ts_s", "s", self.ts_s)?;
        if self.u_min_v.is_nan() || self.u_max_v.is_nan() || self.u_min_v >= self.u_max_v {
            return Err(ControlError::BadLimits {
                min: self.u_min_v,
                max: self.u_max_v,
            });
        }
        if let AntiWindup::BackCalculation { kw } = self.anti_windup {
            check_non_negative("kw", "1/s", kw)?;
        }
        Ok(())
    }
}

/// One controller output with its parts, for logging.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct PidOutput {
    /// Output to apply, after the limits [V].
    pub u_v: f64,
    /// Proportional term K_P e [V].
    pub p_v: f64,
    /// Integral term [V] (after anti-windup).
    pub i_v: f64,
    /// Derivative term K_D f [V].
    pub d_v: f64,
    /// Feedforward passed in [V].
    pub ff_v: f64,
    /// Output before the limits, P + I + D + FF [V].
    pub u_unsat_v: f64,
    /// Whether the limits were active (u_v != u_unsat_v).
    pub saturated: bool,
    /// Whether an input was not finite (state untouched, last output repeated).
    pub invalid_input: bool,
}

/// Discrete PID controller; see the [module documentation](self) for the exact equations.
#[derive(Debug, Clone)]
pub struct Pid {
    cfg: PidConfig,
    // Precomputed coefficients.
    /// Filter pole of the derivative: f_k = a f_{k-1} + b (x_k - x_{k-1}).
    d_a: f64,
    /// Filter input gain [1/s].
    d_b: f64,
    /// Weight of e_k in the integral increment (K_I T_s or K_I T_s / 2) [V/rad].
    i_w0: f64,
    /// Weight of e_{k-1} in the integral increment (0 or K_I T_s / 2) [V/rad].
    i_w1: f64,
    /// T_s K_w of back-calculation (0 otherwise).
    kw_ts: f64,
    /// 1 / (1 + T_s K_w).
    kw_den_inv: f64,
    // State.
    /// Integral term [V].
    i_v: f64,
    /// Filtered derivative of x [rad/s].
    f_rad_s: f64,
    /// Previous error e_{k-1} [rad].
    e_prev: f64,
    /// Previous derivative input x_{k-1} [rad].
    x_prev: f64,
    /// False until the first update after new/reset.
    primed: bool,
    last: PidOutput,
}

impl Pid {
    /// A controller at rest; fails if the configuration does not validate.
    pub fn new(cfg: PidConfig) -> Result<Pid, ControlError> {
        cfg.validate()?;
        let mut pid = Pid {
            cfg,
            d_a: 0.0,
            d_b: 0.0,
            i_w0: 0.0,
            i_w1: 0.0,
            kw_ts: 0.0,
            kw_den_inv: 1.0,
            i_v: 0.0,
            f_rad_s: 0.0,
            e_prev: 0.0,
            x_prev: 0.0,
            primed: false,
            last: PidOutput::default(),
        };
        pid.precompute();
        Ok(pid)
    }

    fn precompute(&mut self) {
        let c = &self.cfg;
        let (ts, tl) = (c.ts_s, c.tl_s);
        let (a, b) = if tl == 0.0 {
            (0.0, 1.0 / ts)
        } else {
            match c.discretization {
                Discretization::BackwardEuler => (tl / (tl + ts), 1.0 / (tl + ts)),
                Discretization::Tustin => {
                    ((2.0 * tl - ts) / (2.0 * tl + ts), 2.0 / (2.0 * tl + ts))
                }
            }
        };
        self.d_a = a;
        self.d_b = b;
        match c.discretization {
            Discretization::BackwardEuler => {
                self.i_w0 = c.ki * ts;
                self.i_w1 = 0.0;
            }
            Discretization::Tustin => {
                self.i_w0 = 0.5 * c.ki * ts;
                self.i_w1 = 0.5 * c.ki * ts;
            }
        }
        self.kw_ts = match c.anti_windup {
            AntiWindup::BackCalculation { kw } => kw * ts,
            _ => 0.0,
        };
        self.kw_den_inv = 1.0 / (1.0 + self.kw_ts);
    }

    /// The configuration in use.
    pub fn config(&self) -> &PidConfig {
        &self.cfg
    }

    /// The output of the last update (all zero before the first one).
    pub fn last_output(&self) -> &PidOutput {
        &self.last
    }

    /// Back to rest: integral, derivative filter and error history cleared.
    pub fn reset(&mut self) {
        self.i_v = 0.0;
        self.f_rad_s = 0.0;
        self.e_prev = 0.0;
        self.x_prev = 0.0;
        self.primed = false;
        self.last = PidOutput::default();
    }

    /// Sets the integral term [V], e.g. to start closed loop from an open-loop voltage without a
    /// bump (set it to the voltage being applied minus the expected P + D + FF).
    pub fn preload_integral(&mut self, i_v: f64) {
        if i_v.is_finite() {
            self.i_v = i_v;
        }
    }

    /// Restarts the controller so that it takes over from an output `u_v` [V] that was being
    /// applied (open loop, another controller) without a bump: the history is primed with the
    /// current error (no derivative kick) and the integral set to `u_v - K_P e - FF`. The next
    /// [`update`](Self::update) with the same inputs then returns `u_v` plus one integral
    /// increment (K_I T_s e).
    pub fn bumpless_start(
        &mut self,
        u_v: f64,
        reference_rad: f64,
        measurement_rad: f64,
        feedforward_v: f64,
    ) {
        self.reset();
        let e = reference_rad - measurement_rad;
        if !(e.is_finite() && u_v.is_finite() && feedforward_v.is_finite()) {
            return;
        }
        self.x_prev = match self.cfg.derivative_on {
            DerivativeOn::Error => e,
            DerivativeOn::Measurement => -measurement_rad,
        };
        self.e_prev = e;
        self.primed = true;
        self.i_v = u_v - self.cfg.kp * e - feedforward_v;
    }

    /// Changes the gains without a bump in the output: the integral absorbs the change of
    /// P + D at the last sample's error and derivative state.
    pub fn set_gains(&mut self, gains: PidGains) -> Result<(), ControlError> {
        gains.validate()?;
        if self.primed {
            let e = self.last_error();
            let old_pd = self.cfg.kp * e + self.cfg.kd * self.f_rad_s;
            let new_pd = gains.kp * e + gains.kd * self.f_rad_s;
            self.i_v += old_pd - new_pd;
        }
        self.cfg.kp = gains.kp;
        self.cfg.ki = gains.ki;
        self.cfg.kd = gains.kd;
        self.cfg.tl_s = gains.tl_s;
        self.precompute();
        Ok(())
    }

    /// Changes the output limits [V] (ordered, infinite allowed).
    pub fn set_limits(&mut self, u_min_v: f64, u_max_v: f64) -> Result<(), ControlError> {
        let cfg = PidConfig {
            u_min_v,
            u_max_v,
            ..self.cfg
        };
        cfg.validate()?;
        self.cfg = cfg;
        Ok(())
    }

    /// Error at the last update [rad].
    fn last_error(&self) -> f64 {
        self.e_prev
    }

    /// One controller step: reference r [rad], measurement y [rad], feedforward [V] (added to the
    /// output before the limits). Returns the output and its parts.
    #[inline]
    pub fn update(
        &mut self,
        reference_rad: f64,
        measurement_rad: f64,
        feedforward_v: f64,
    ) -> PidOutput {
        if !(reference_rad.is_finite() && measurement_rad.is_finite() && feedforward_v.is_finite())
        {
            return PidOutput {
                invalid_input: true,
                ..self.last
            };
        }
        let c = &self.cfg;
        let e = reference_rad - measurement_rad;
        let x = match c.derivative_on {
            DerivativeOn::Error => e,
            DerivativeOn::Measurement => -measurement_rad,
        };
        if !self.primed {
            self.x_prev = x;
            self.primed = true;
        }
        let f = self.d_a * self.f_rad_s + self.d_b * (x - self.x_prev);
        let p = c.kp * e;
        let d = c.kd * f;
        let di = self.i_w0 * e + self.i_w1 * self.e_prev;
        let pdf = p + d + feedforward_v;
        let mut i = self.i_v + di;
        let v_free = pdf + i;
        match c.anti_windup {
            AntiWindup::None => {}
            AntiWindup::Clamping => {
                if (v_free > c.u_max_v && di > 0.0) || (v_free < c.u_min_v && di < 0.0) {
                    i = self.i_v;
                }
            }
            AntiWindup::BackCalculation { .. } => {
                if v_free > c.u_max_v {
                    i = (i + self.kw_ts * (c.u_max_v - pdf)) * self.kw_den_inv;
                } else if v_free < c.u_min_v {
                    i = (i + self.kw_ts * (c.u_min_v - pdf)) * self.kw_den_inv;
                }
            }
        }
        let v = pdf + i;
        // Branch-free clamp (limits validated ordered and not NaN; v is finite).
        let u = v.max(c.u_min_v).min(c.u_max_v);
        self.i_v = i;
        self.f_rad_s = f;
        self.e_prev = e;
        self.x_prev = x;
        self.last = PidOutput {
            u_v: u,
            p_v: p,
            i_v: i,
            d_v: d,
            ff_v: feedforward_v,
            u_unsat_v: v,
            saturated: u != v,
            invalid_input: false,
        };
        self.last
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(kp: f64, ki: f64, kd: f64, tl_s: f64, ts_s: f64) -> PidConfig {
        PidConfig::new(PidGains { kp, ki, kd, tl_s }, ts_s)
    }

    fn assert_seq(pid: &mut Pid, inputs: &[(f64, f64)], expected: &[(f64, f64, f64, f64)]) {
        for (k, ((r, y), (p, i, d, u))) in inputs.iter().zip(expected).enumerate() {
            let o = pid.update(*r, *y, 0.0);
            let ok = |a: f64, b: f64| (a - b).abs() < 1e-12;
            assert!(
                ok(o.p_v, *p) && ok(o.i_v, *i) && ok(o.d_v, *d) && ok(o.u_v, *u),
                "k={k}: got {o:?}, expected p={p} i={i} d={d} u={u}"
            );
        }
    }

    // Shared hand example: K_P = 2, K_I = 10, K_D = 0.5, T_s = 0.01; r = 1, y = 0, 0.1, 0.3, 0.6
    // so e = 1, 0.9, 0.7, 0.4.
    const INPUTS: [(f64, f64); 4] = [(1.0, 0.0), (1.0, 0.1), (1.0, 0.3), (1.0, 0.6)];

    #[test]
    fn backward_euler_filtered_derivative_on_error_by_hand() {
        // T_L = 0.01: a = T_L/(T_L+T_s) = 0.5, b = 1/(T_L+T_s) = 50 1/s.
        // k0: f = 0 (no kick on the first sample), I = 0.1 -> u = 2.1
        // k1: f = 50*(-0.1) = -5, D = -2.5, I = 0.19, P = 1.8 -> u = -0.51
        // k2: f = 0.5*(-5) + 50*(-0.2) = -12.5, D = -6.25, I = 0.26, P = 1.4 -> u = -4.59
        // k3: f = 0.5*(-12.5) + 50*(-0.3) = -21.25, D = -10.625, I = 0.30, P = 0.8 -> u = -9.525
        let mut pid = Pid::new(cfg(2.0, 10.0, 0.5, 0.01, 0.01)).unwrap();
        assert_seq(
            &mut pid,
            &INPUTS,
            &[
                (2.0, 0.1, 0.0, 2.1),
                (1.8, 0.19, -2.5, -0.51),
                (1.4, 0.26, -6.25, -4.59),
                (0.8, 0.30, -10.625, -9.525),
            ],
        );
    }

    #[test]
    fn tustin_filtered_derivative_on_error_by_hand() {
        // T_L = 0.01: a = (2T_L - T_s)/(2T_L + T_s) = 1/3, b = 2/(2T_L + T_s) = 200/3 1/s.
        // Integral: I_k = I_{k-1} + K_I T_s/2 (e_k + e_{k-1}) with e_{-1} = 0: 0.05, 0.145, 0.225.
        // k1: f = 200/3 * (-0.1) = -20/3, D = -10/3
        // k2: f = (1/3)(-20/3) + (200/3)(-0.2) = -140/9, D = -70/9
        let mut c = cfg(2.0, 10.0, 0.5, 0.01, 0.01);
        c.discretization = Discretization::Tustin;
        let mut pid = Pid::new(c).unwrap();
        assert_seq(
            &mut pid,
            &INPUTS[..3],
            &[
                (2.0, 0.05, 0.0, 2.05),
                (1.8, 0.145, -10.0 / 3.0, 1.8 + 0.145 - 10.0 / 3.0),
                (1.4, 0.225, -70.0 / 9.0, 1.4 + 0.225 - 70.0 / 9.0),
            ],
        );
    }

    #[test]
    fn derivative_on_measurement_pure_difference_by_hand() {
        // T_L = 0: f = (x_k - x_{k-1})/T_s with x = -y. The reference steps 1 -> 2 at k = 2
        // without a derivative kick.
        // k0: e = 1, f = 0, I = 0.1 -> u = 2.1
        // k1: e = 0.9, f = -10, D = -5, I = 0.19 -> u = -3.01
        // k2: e = 1.7, f = -20, D = -10, P = 3.4, I = 0.36 -> u = -6.24
        // k3: e = 1.4, f = -30, D = -15, P = 2.8, I = 0.50 -> u = -11.7
        let inputs = [(1.0, 0.0), (1.0, 0.1), (2.0, 0.3), (2.0, 0.6)];
        let expected = [
            (2.0, 0.1, 0.0, 2.1),
            (1.8, 0.19, -5.0, -3.01),
            (3.4, 0.36, -10.0, -6.24),
            (2.8, 0.50, -15.0, -11.7),
        ];
        for disc in [Discretization::BackwardEuler, Discretization::Tustin] {
            let mut c = cfg(2.0, 10.0, 0.5, 0.0, 0.01);
            c.derivative_on = DerivativeOn::Measurement;
            c.discretization = disc;
            let mut pid = Pid::new(c).unwrap();
            if disc == Discretization::BackwardEuler {
                assert_seq(&mut pid, &inputs, &expected);
            } else {
                // Tustin changes only the integral: 0.05, 0.145, 0.275, 0.43.
                let tustin_i = [0.05, 0.145, 0.275, 0.43];
                for (k, ((r, y), (p, _, d, _))) in inputs.iter().zip(expected).enumerate() {
                    let o = pid.update(*r, *y, 0.0);
                    assert!(
                        (o.d_v - d).abs() < 1e-12 && (o.p_v - p).abs() < 1e-12,
                        "k={k} {o:?}"
                    );
                    assert!((o.i_v - tustin_i[k]).abs() < 1e-12, "k={k} {o:?}");
                }
            }
        }
        // On the error instead, the same step kicks: f = (1.7 - 0.9)/0.01 = 80 -> D = 40 at k2.
        let mut pid = Pid::new(cfg(2.0, 10.0, 0.5, 0.0, 0.01)).unwrap();
        let d2 = inputs
            .iter()
            .map(|(r, y)| pid.update(*r, *y, 0.0).d_v)
            .nth(2)
            .unwrap();
        assert!((d2 - 40.0).abs() < 1e-9, "{d2}");
    }

    #[test]
    fn feedforward_is_added_before_the_limits() {
        let mut pid = Pid::new(cfg(1.0, 0.0, 0.0, 0.0, 0.01).with_symmetric_limit(5.0)).unwrap();
        let o = pid.update(1.0, 0.0, 3.0);
        assert_eq!(
            (o.u_v, o.ff_v, o.u_unsat_v, o.saturated),
            (4.0, 3.0, 4.0, false)
        );
        let o = pid.update(1.0, 0.0, 4.5);
        assert_eq!((o.u_v, o.u_unsat_v, o.saturated), (5.0, 5.5, true));
    }

    #[test]
    fn anti_windup_schemes_by_hand() {
        // K_P = 1, K_I = 100, T_s = 0.01, limits +-1 V, constant e = 2.
        let base = cfg(1.0, 100.0, 0.0, 0.0, 0.01).with_symmetric_limit(1.0);
        // None: I = 2, 4 -> v = 4, 6 while u = 1.
        let mut pid = Pid::new(base).unwrap();
        let o0 = pid.update(2.0, 0.0, 0.0);
        let o1 = pid.update(2.0, 0.0, 0.0);
        assert_eq!(
            (o0.i_v, o0.u_unsat_v, o0.u_v, o0.saturated),
            (2.0, 4.0, 1.0, true)
        );
        assert_eq!((o1.i_v, o1.u_unsat_v), (4.0, 6.0));
        // Clamping: the increment pushes into the limit -> I frozen at 0; a negative error
        // then integrates at once: I = -0.5, v = -1 (at the limit, not beyond).
        let mut pid = Pid::new(PidConfig {
            anti_windup: AntiWindup::Clamping,
            ..base
        })
        .unwrap();
        assert_eq!(pid.update(2.0, 0.0, 0.0).i_v, 0.0);
        assert_eq!(pid.update(2.0, 0.0, 0.0).i_v, 0.0);
        let o = pid.update(0.0, 0.5, 0.0);
        assert_eq!((o.i_v, o.u_v, o.saturated), (-0.5, -1.0, false));
        // Back-calculation K_w = 50 1/s (K_w T_s = 0.5): I_0 = (2 + 0.5 (1 - 2))/1.5 = 1,
        // I_1 = (1 + 2 + 0.5 (1 - 2))/1.5 = 5/3; fixed point K_I e + K_w (u - v) = 0 -> I = 3.
        let mut pid = Pid::new(PidConfig {
            anti_windup: AntiWindup::BackCalculation { kw: 50.0 },
            ..base
        })
        .unwrap();
        let o0 = pid.update(2.0, 0.0, 0.0);
        let o1 = pid.update(2.0, 0.0, 0.0);
        assert!((o0.i_v - 1.0).abs() < 1e-12 && o0.u_v == 1.0 && o0.saturated);
        assert!((o1.i_v - 5.0 / 3.0).abs() < 1e-12);
        let mut i = 0.0;
        for _ in 0..200 {
            i = pid.update(2.0, 0.0, 0.0).i_v;
        }
        assert!((i - 3.0).abs() < 1e-9, "{i}");
    }

    /// Closed loop on the reduced model theta_m'' = (k_m u - omega_m) / T_m (eq. 30, Table 2),
    /// theta_l = theta_m / N, integrated with 10 sub-steps per period. Returns the overshoot [%]
    /// of a 2 pi rad step and the time spent saturated [s].
    fn step_overshoot(anti_windup: AntiWindup) -> (f64, f64) {
        let p = crate::params::PlantParams::TABLE2;
        let (k_m, t_m, n) = (p.k_m(), p.t_m(), p.n);
        // The Bode gains measured on the real motor (realdata README), T_L = 1/(3 omega_gc).
        let ts = 1e-3;
        let c = PidConfig {
            anti_windup,
            ..cfg(
                7.5244,
                94.0379,
                0.1505,
                1.0 / (3.0 * 10.0 * crate::math::PI),
                ts,
            )
            .with_symmetric_limit(10.0)
        };
        let mut pid = Pid::new(c).unwrap();
        let (mut th, mut w) = (0.0f64, 0.0f64);
        let r = 2.0 * crate::math::PI;
        let (mut peak, mut t_sat) = (0.0f64, 0.0);
        for _ in 0..4000 {
            let o = pid.update(r, th / n, 0.0);
            if o.saturated {
                t_sat += ts;
            }
            let h = ts / 10.0;
            for _ in 0..10 {
                w += h * (k_m * o.u_v - w) / t_m;
                th += h * w;
            }
            peak = peak.max(th / n);
        }
        assert!((th / n - r).abs() < 1e-2 * r, "did not settle: {}", th / n);
        (100.0 * (peak - r) / r, t_sat)
    }

    #[test]
    fn anti_windup_bounds_overshoot_after_long_saturation() {
        let (os_none, sat_none) = step_overshoot(AntiWindup::None);
        let (os_clamp, _) = step_overshoot(AntiWindup::Clamping);
        let (os_back, _) = step_overshoot(AntiWindup::BackCalculation { kw: 50.0 });
        // The 360 deg step saturates the 10 V output for a long time (~0.2 s).
        assert!(sat_none > 0.1, "saturated only {sat_none} s");
        assert!(os_none > 20.0, "windup overshoot {os_none} %");
        assert!(
            os_clamp < 0.5 * os_none && os_clamp < 15.0,
            "clamping {os_clamp} % vs {os_none} %"
        );
        assert!(
            os_back < 0.5 * os_none && os_back < 15.0,
            "back-calculation {os_back} % vs {os_none} %"
        );
    }

    #[test]
    fn bumpless_gain_change() {
        // Constant error: after K_P 2 -> 10 the next output equals the one the old gains give.
        let c = cfg(2.0, 10.0, 0.0, 0.0, 0.01);
        let (mut a, mut b) = (Pid::new(c).unwrap(), Pid::new(c).unwrap());
        for _ in 0..5 {
            a.update(1.0, 0.5, 0.0);
            b.update(1.0, 0.5, 0.0);
        }
        b.set_gains(PidGains {
            kp: 10.0,
            ki: 10.0,
            kd: 0.0,
            tl_s: 0.0,
        })
        .unwrap();
        let (ua, ub) = (a.update(1.0, 0.5, 0.0).u_v, b.update(1.0, 0.5, 0.0).u_v);
        assert!((ua - ub).abs() < 1e-12, "{ua} vs {ub}");

        // With a moving measurement and a derivative, the output after the change moves from the
        // last one only by the increment of the new gains (velocity form):
        // u_{k+1} - u_k = K_P' (e_{k+1} - e_k) + K_I' T_s e_{k+1} + K_D' (f_{k+1} - f_k),
        // with f_{k+1} = a' f_k + b' (x_{k+1} - x_k), a' = T_L'/(T_L' + T_s), b' = 1/(T_L' + T_s).
        let mut c = cfg(2.0, 10.0, 0.2, 0.01, 0.01);
        c.derivative_on = DerivativeOn::Measurement;
        let new = PidGains {
            kp: 8.0,
            ki: 40.0,
            kd: 0.6,
            tl_s: 0.005,
        };
        let mut pid = Pid::new(c).unwrap();
        let y = |k: usize| 0.01 * k as f64;
        let mut last = PidOutput::default();
        for k in 0..20 {
            last = pid.update(1.0, y(k), 0.0);
        }
        pid.set_gains(new).unwrap();
        let after = pid.update(1.0, y(20), 0.0);
        let f_k = last.d_v / 0.2;
        let f_k1 = 0.005 / 0.015 * f_k + (-(y(20) - y(19))) / 0.015;
        let (e_k, e_k1) = (1.0 - y(19), 1.0 - y(20));
        let expected = new.kp * (e_k1 - e_k) + new.ki * 0.01 * e_k1 + new.kd * (f_k1 - f_k);
        assert!(
            (after.u_v - last.u_v - expected).abs() < 1e-9,
            "{} vs {expected}",
            after.u_v - last.u_v
        );
        // Without bumpless transfer the output would jump by the change of P + D at once.
        let raw_bump = (new.kp - 2.0) * e_k + (new.kd - 0.2) * f_k;
        assert!(raw_bump.abs() > 4.0, "{raw_bump}");
        assert!(pid.set_gains(PidGains { kp: -1.0, ..new }).is_err());
    }

    #[test]
    fn bumpless_start_from_an_open_loop_voltage() {
        // K_P = 2, K_I = 10, T_s = 0.01, e = 0.3: I = 1.5 - 0.6 - 0.1 = 0.8, then the update adds
        // K_I T_s e = 0.03 (both rules, since e_{k-1} = e_k): u = 0.6 + 0.83 + 0 + 0.1 = 1.53.
        for disc in [Discretization::BackwardEuler, Discretization::Tustin] {
            let mut pid = Pid::new(PidConfig {
                discretization: disc,
                ..cfg(2.0, 10.0, 0.5, 0.01, 0.01)
            })
            .unwrap();
            pid.update(5.0, 0.0, 0.0); // some unrelated history
            pid.bumpless_start(1.5, 1.0, 0.7, 0.1);
            let o = pid.update(1.0, 0.7, 0.1);
            assert!(
                (o.u_v - 1.53).abs() < 1e-12 && o.d_v == 0.0,
                "{disc:?}: {o:?}"
            );
        }
    }

    #[test]
    fn reset_and_invalid_inputs() {
        let mut pid = Pid::new(cfg(2.0, 10.0, 0.5, 0.01, 0.01)).unwrap();
        let first: [PidOutput; 3] = core::array::from_fn(|k| pid.update(1.0, 0.1 * k as f64, 0.0));
        let o = pid.update(f64::NAN, 0.0, 0.0);
        assert!(o.invalid_input && o.u_v == first[2].u_v);
        pid.reset();
        let again: [PidOutput; 3] = core::array::from_fn(|k| pid.update(1.0, 0.1 * k as f64, 0.0));
        assert_eq!(first, again);
    }

    #[test]
    fn validation_names_the_bad_value() {
        let e = Pid::new(cfg(-1.0, 0.0, 0.0, 0.0, 0.01)).unwrap_err();
        assert!(matches!(e, ControlError::Negative { key: "kp", .. }));
        let e = Pid::new(cfg(1.0, 0.0, 0.0, 0.0, 0.0)).unwrap_err();
        assert!(matches!(e, ControlError::NotPositive { key: "ts_s", .. }));
        let e = Pid::new(PidConfig {
            u_min_v: 1.0,
            u_max_v: -1.0,
            ..cfg(1.0, 0.0, 0.0, 0.0, 0.01)
        })
        .unwrap_err();
        assert!(matches!(e, ControlError::BadLimits { .. }));
        let e = Pid::new(PidConfig {
            anti_windup: AntiWindup::BackCalculation { kw: f64::NAN },
            ..cfg(1.0, 0.0, 0.0, 0.0, 0.01)
        })
        .unwrap_err();
        assert!(matches!(e, ControlError::NotFinite { key: "kw", .. }));
    }
}
