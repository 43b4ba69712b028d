//! Smart servos: a gearmotor whose firmware closes its own position loop (Dynamixel, Feetech,
//! Herkulex). The host commands a goal position; the firmware computes a PWM duty from the
//! error between the goal and its encoder, clips it, and switches the supply across the motor.
//!
//! * [`PositionLoop`]: the firmware's loop as a drive: duty = kp_fw x duty_per_rad_per_kp x
//!   (goal(t - latency) - theta_q), theta_q the angle on the encoder's grid, |duty| <=
//!   duty_limit, the bridge voltage duty x V_supply (the supply from the log's column, else a
//!   value). The latency is the firmware's and the bus's: the goal reaches the loop that much
//!   later than the log says it was written.
//! * [`SmartParams`]: everything at the output shaft: J_eq, B_eq, the Coulomb friction tau_sf,
//!   the motor constant ratio k_t / R (N m per V across the motor) and k_e (the back-EMF
//!   damping is k_t k_e / R), the gravity amplitude m g L and its phase (the resisting torque
//!   amplitude sin(theta + phase), as the catalogue's gravity effect, `effects::GRAVITY`), and the latency.
//! * [`replay`]: the closed-loop replay of a log from its goal positions. Where the log's
//!   torque-enable column reads 0, the bridge is open: no drive torque and no back-EMF braking,
//!   only friction and gravity act (an arm dropped with the torque off swings freely).
//! * [`fit`]: the output-error fit on whole trajectories: the parameters that make the replayed
//!   position follow the measured one (one known torque, k_t / R or m g L, sets the torques'
//!   scale, which positions alone do not determine), searched by Nelder-Mead from the equation-error estimate
//!   ([`equation_error`]), with the user's lower bound on the inertia (a known load's m L^2)
//!   respected. It keeps the fit that predicts held-out logs better, and says so.

use crate::math;
use alloc::{string::String, vec::Vec};

/// The firmware's position loop (the drive of a smart servo).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionLoop {
    /// The firmware's proportional gain in the vendor's units (e.g. Dynamixel's Position P Gain).
    pub kp_fw: f64,
    /// Duty per rad of error per unit of kp_fw (XL330: 4096 / (2 pi 256 885) = 2.877378e-3).
    pub duty_per_rad_per_kp: f64,
    /// The largest duty magnitude (1: the whole supply).
    pub duty_limit: f64,
    /// The supply [V] where the log has no supply column.
    pub v_supply_v: f64,
    /// Use the log's supply column when it has one (false: always `v_supply_v`).
    pub supply_from_log: bool,
    /// Counts per turn of the firmware's encoder (its angle is on this grid); `None`: exact.
    pub encoder_counts: Option<u32>,
    /// The firmware's loop period [s] (the replay's integration step, at most the log's period).
    pub period_s: f64,
}

impl PositionLoop {
    /// Dynamixel XL330's loop: ERROR_GAIN = 4096 / (2 pi 256 885) duty per rad per kp unit, a
    /// 7.4 V supply, a 4096-count encoder, a 1 ms loop.
    pub fn xl330(kp_fw: f64) -> PositionLoop {
        PositionLoop {
            kp_fw,
            duty_per_rad_per_kp: 4096.0 / (math::TAU * 256.0 * 885.0),
            duty_limit: 1.0,
            v_supply_v: 7.4,
            supply_from_log: false,
            encoder_counts: Some(4096),
            period_s: 1e-3,
        }
    }

    /// The loop's duty for a goal and a measured angle (clipped).
    pub fn duty(&self, goal_rad: f64, theta_rad: f64) -> f64 {
        let th = match self.encoder_counts {
            Some(n) if n > 0 => {
                let q = math::TAU / n as f64;
                libm::round(theta_rad / q) * q
            }
            _ => theta_rad,
        };
        (self.kp_fw * self.duty_per_rad_per_kp * (goal_rad - th))
            .clamp(-self.duty_limit, self.duty_limit)
    }

    /// Checks the values (positive, finite; duty limit in (0, 1]).
    pub fn validate(&self) -> Result<(), SmartError> {
        let checks = [
            ("kp_fw", self.kp_fw, self.kp_fw >= 0.0),
            (
                "duty_per_rad_per_kp",
                self.duty_per_rad_per_kp,
                self.duty_per_rad_per_kp > 0.0,
            ),
            (
                "duty_limit",
                self.duty_limit,
                self.duty_limit > 0.0 && self.duty_limit <= 1.0,
            ),
            ("v_supply_v", self.v_supply_v, self.v_supply_v > 0.0),
            ("period_s", self.period_s, self.period_s > 0.0),
        ];
        for (key, v, ok) in checks {
            if !(ok && v.is_finite()) {
                return Err(SmartError::BadValue { key, value: v });
            }
        }
        Ok(())
    }
}

/// The model of a smart servo and its load, at the output shaft.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SmartParams {
    /// Inertia at the output [kg m^2] (rotor through the gear plus the load).
    pub j_eq: f64,
    /// Viscous friction [N m s/rad].
    pub b_eq: f64,
    /// Coulomb friction [N m].
    pub tau_sf: f64,
    /// Load-dependent gearbox friction: the Coulomb friction grows by this fraction of the
    /// motor's torque (a gear efficiency of 1 - load_friction; 0: none).
    pub load_friction: f64,
    /// Motor constant ratio k_t / R [N m/V]: torque per volt across the motor at stall.
    pub k_t_per_r: f64,
    /// Back-EMF constant [V s/rad] at the output.
    pub k_e: f64,
    /// Gravity amplitude m g L [N m] (resisting torque amplitude x sin(theta + phase)).
    pub gravity_nm: f64,
    /// Gravity phase [rad] (the bottom at theta = -phase).
    pub phase_rad: f64,
    /// The firmware's and the bus's latency between the logged goal and the loop [s].
    pub latency_s: f64,
}

/// Why a smart-servo computation was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SmartError {
    #[error("smart servo: `{key}` must be a positive finite number, got {}", math::Num(*.value))]
    BadValue { key: &'static str, value: f64 },
    #[error("{log}: {why}")]
    Log { log: String, why: String },
    #[error("{log}: the replay diverged at row {row} (the model's parameters are not physical)")]
    Diverged { log: String, row: usize },
    #[error("no log to fit on: give at least one log with a goal position and the measured angle")]
    NoLogs,
}

/// A smart servo's log on a uniform grid.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SmartLog {
    /// The log's name (for messages).
    pub name: String,
    pub time_s: Vec<f64>,
    /// The goal position the host wrote [rad].
    pub goal_rad: Vec<f64>,
    /// The measured output angle [rad].
    pub theta_rad: Vec<f64>,
    /// The servo's speed estimate [rad/s], when logged.
    pub omega_rad_s: Option<Vec<f64>>,
    /// The logged duty (the firmware's PWM, signed fraction), when logged.
    pub duty: Option<Vec<f64>>,
    /// The measured supply [V], when logged.
    pub v_supply_v: Option<Vec<f64>>,
    /// Torque enable (false: the bridge is open), when logged.
    pub torque_enable: Option<Vec<bool>>,
    /// The firmware gain the log was taken at (vendor units), when the log says it.
    pub kp_fw: Option<f64>,
}

impl SmartLog {
    /// Checks lengths, a uniform increasing time and finite values.
    pub fn validate(&self) -> Result<(), SmartError> {
        let err = |why: String| SmartError::Log {
            log: self.name.clone(),
            why,
        };
        let n = self.time_s.len();
        if n < 3 {
            return Err(err(alloc::format!("{n} rows: a replay needs at least 3")));
        }
        let lens = [
            ("goal", Some(self.goal_rad.len())),
            ("theta", Some(self.theta_rad.len())),
            ("omega", self.omega_rad_s.as_ref().map(Vec::len)),
            ("duty", self.duty.as_ref().map(Vec::len)),
            ("v_supply", self.v_supply_v.as_ref().map(Vec::len)),
            ("torque_enable", self.torque_enable.as_ref().map(Vec::len)),
        ];
        for (name, l) in lens {
            if let Some(l) = l {
                if l != n {
                    return Err(err(alloc::format!(
                        "column `{name}` has {l} rows, the time {n}"
                    )));
                }
            }
        }
        let dt = self.dt_s();
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(err(String::from("the time does not increase")));
        }
        for (k, w) in self.time_s.windows(2).enumerate() {
            let d = w[1] - w[0];
            if !(d > 0.5 * dt && d < 1.5 * dt) {
                return Err(err(alloc::format!(
                    "row {}: the time step {} s is not the log's period {} s (resample the log onto a uniform grid)",
                    k + 1,
                    math::Num(d),
                    math::Num(dt)
                )));
            }
        }
        let finite = |v: &[f64]| v.iter().position(|x| !x.is_finite());
        for (name, v) in [("goal", &self.goal_rad), ("theta", &self.theta_rad)] {
            if let Some(k) = finite(v) {
                return Err(err(alloc::format!(
                    "row {k}: `{name}` is not a finite number"
                )));
            }
        }
        Ok(())
    }

    /// The mean sample period [s].
    pub fn dt_s(&self) -> f64 {
        let n = self.time_s.len();
        if n < 2 {
            return f64::NAN;
        }
        (self.time_s[n - 1] - self.time_s[0]) / (n - 1) as f64
    }

    fn enabled(&self, k: usize) -> bool {
        match &self.torque_enable {
            Some(e) => e[k],
            None => true,
        }
    }
}

/// The replayed trajectory.
#[derive(Debug, Clone, PartialEq)]
pub struct SmartReplay {
    /// The model's angle at each row [rad].
    pub theta_rad: Vec<f64>,
    /// The model's speed at each row [rad/s].
    pub omega_rad_s: Vec<f64>,
    /// The firmware's duty at each row (0 with the torque off).
    pub duty: Vec<f64>,
}

/// Position errors of a replay against the log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionError {
    /// Mean absolute error [rad].
    pub mae_rad: f64,
    /// Root-mean-square error [rad].
    pub rmse_rad: f64,
    /// Rows compared.
    pub rows: usize,
}

impl PositionError {
    /// The error of `model` against `measured`.
    pub fn of(model: &[f64], measured: &[f64]) -> PositionError {
        let (mut a, mut s) = (0.0, 0.0);
        let n = model.len().min(measured.len());
        for (m, y) in model.iter().zip(measured) {
            let e = m - y;
            a += e.abs();
            s += e * e;
        }
        let d = n.max(1) as f64;
        PositionError {
            mae_rad: a / d,
            rmse_rad: libm::sqrt(s / d),
            rows: n,
        }
    }

    /// The errors of several logs pooled (each row weighs the same).
    pub fn pooled(parts: &[PositionError]) -> PositionError {
        let n: usize = parts.iter().map(|p| p.rows).sum();
        let d = n.max(1) as f64;
        PositionError {
            mae_rad: parts.iter().map(|p| p.mae_rad * p.rows as f64).sum::<f64>() / d,
            rmse_rad: libm::sqrt(
                parts
                    .iter()
                    .map(|p| p.rmse_rad * p.rmse_rad * p.rows as f64)
                    .sum::<f64>()
                    / d,
            ),
            rows: n,
        }
    }
}

/// The goal the firmware holds at time `t`: the last one written at or before `t` (the host
/// writes a goal at each poll and the firmware keeps it until the next; held before the start
/// and after the end).
fn goal_at(log: &SmartLog, t0: f64, dt: f64, t: f64) -> f64 {
    let g = &log.goal_rad;
    let x = (t - t0) / dt + 1e-9;
    if x <= 0.0 {
        return g[0];
    }
    g[(x as usize).min(g.len() - 1)]
}

/// The mean of the held goal over [t, t + h] (h at most the log's period): a goal written
/// within the loop's step weighs by the part of the step after it, so the replay moves
/// continuously with the latency.
fn goal_over(log: &SmartLog, t0: f64, dt: f64, t: f64, h: f64) -> f64 {
    let g = &log.goal_rad;
    let at = |x: f64| g[(libm::floor(x).max(0.0) as usize).min(g.len() - 1)];
    let x0 = (t - t0) / dt + 1e-9;
    let x1 = x0 + h / dt;
    let b = libm::floor(x0) + 1.0;
    if x1 <= b || x1 <= x0 {
        return at(x0);
    }
    let f = (x1 - b) / (x1 - x0);
    at(x0) * (1.0 - f) + at(b) * f
}

/// Replays `log` on the model in closed loop through the firmware's loop, from the measured
/// angle and speed at row 0 and the logged goals. Row k of the replay is the state at t_k.
///
/// The mechanics are integrated at the loop's period with the viscous and back-EMF damping
/// implicit and the Coulomb friction as a stick/slip step (the speed stops at zero when the
/// other torques cannot overcome tau_sf), stable at any step.
pub fn replay(
    p: &SmartParams,
    drive: &PositionLoop,
    log: &SmartLog,
) -> Result<SmartReplay, SmartError> {
    drive.validate()?;
    log.validate()?;
    let n = log.time_s.len();
    let dt = log.dt_s();
    let t0 = log.time_s[0];
    let subs = libm::ceil(dt / drive.period_s).max(1.0) as usize;
    let h = dt / subs as f64;
    let mut th = log.theta_rad[0];
    let mut w = log.omega_rad_s.as_ref().map_or(0.0, |o| o[0]);
    let mut out = SmartReplay {
        theta_rad: Vec::with_capacity(n),
        omega_rad_s: Vec::with_capacity(n),
        duty: Vec::with_capacity(n),
    };
    let j = p.j_eq;
    let damping_on = p.b_eq + p.k_t_per_r * p.k_e;
    for k in 0..n {
        let on = log.enabled(k);
        let v = match (&log.v_supply_v, drive.supply_from_log) {
            (Some(vs), true) if vs[k].is_finite() && vs[k] > 0.0 => vs[k],
            _ => drive.v_supply_v,
        };
        out.theta_rad.push(th);
        out.omega_rad_s.push(w);
        let mut d_row = 0.0;
        for s in 0..subs {
            let t = log.time_s[k] + s as f64 * h;
            let (drive_nm, c, motor_nm) = if on {
                let d = drive.duty(goal_over(log, t0, dt, t - p.latency_s, h), th);
                if s == 0 {
                    d_row = d;
                }
                let u = p.k_t_per_r * d * v;
                (u, damping_on, u - p.k_t_per_r * p.k_e * w)
            } else {
                (0.0, p.b_eq, 0.0)
            };
            let ext = drive_nm - p.gravity_nm * libm::sin(th + p.phase_rad);
            let den = j + h * c;
            let w_free = (j * w + h * ext) / den;
            let stop = h * (p.tau_sf + p.load_friction * motor_nm.abs()) / den;
            w = if w_free.abs() <= stop {
                0.0
            } else {
                w_free - stop * w_free.signum()
            };
            th += h * w;
        }
        if !(th.is_finite() && w.is_finite()) {
            return Err(SmartError::Diverged {
                log: log.name.clone(),
                row: k,
            });
        }
        out.duty.push(d_row);
    }
    Ok(out)
}

/// The position error of the model on each log (closed-loop replay from the goals).
pub fn errors(
    p: &SmartParams,
    drive_of: &dyn Fn(&SmartLog) -> PositionLoop,
    logs: &[SmartLog],
) -> Result<Vec<PositionError>, SmartError> {
    logs.iter()
        .map(|l| replay(p, &drive_of(l), l).map(|r| PositionError::of(&r.theta_rad, &l.theta_rad)))
        .collect()
}

/// What the user knows before fitting.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SmartPrior {
    /// A starting value of k_t / R [N m/V] (the datasheet's k_t over R).
    pub k_t_per_r: f64,
    /// k_e [V s/rad] at the output (kept: the back-EMF damping scales with the fitted k_t / R).
    pub k_e: f64,
    /// The least inertia the model may have [kg m^2] (a known load's m L^2; 0 when unknown).
    pub j_min: f64,
    /// The latency's search range [s] (0 to this).
    pub latency_max_s: f64,
    /// The gravity amplitude m g L when known [N m] (a pendulum bench's mass and length): it
    /// sets the torques' scale and k_t / R is fitted; `None`: k_t / R sets it.
    pub gravity_nm: Option<f64>,
    /// Fit a load-dependent gearbox friction (the Coulomb friction growing with the motor's
    /// torque) beside the Coulomb and viscous ones.
    pub load_friction: bool,
}

/// The equation-error estimate: least squares of the torque balance
/// J alpha + B omega + (tau_sf + l |m|) sign(omega) + a sin(theta) + b cos(theta) = m,
/// m = (k_t/R)(V d - k_e omega) the motor's torque, with k_t / R from the prior, on the rows with
/// the torque on (l, the load-dependent friction, when the prior fits it). The duty d is the
/// logged one; a log without it gets the firmware's duty rebuilt from its goals and angles
/// (the latency then chosen on a grid by the smallest residual). The speed is the logged one
/// (else the central difference of the angle) and the acceleration its central difference.
/// `None` when no log gives rows or the system is singular.
pub fn equation_error(
    prior: &SmartPrior,
    drive_of: &dyn Fn(&SmartLog) -> PositionLoop,
    logs: &[SmartLog],
) -> Option<SmartParams> {
    let rebuilt = logs.iter().any(|l| l.duty.is_none());
    let grid = if rebuilt { 12 } else { 0 };
    let mut best: Option<(f64, SmartParams)> = None;
    for i in 0..=grid {
        let lat = prior.latency_max_s * i as f64 / grid.max(1) as f64;
        if let Some((sse, mut p)) = equation_error_at(prior, drive_of, logs, lat) {
            if rebuilt {
                p.latency_s = lat;
            }
            if best.as_ref().is_none_or(|b| sse < b.0) {
                best = Some((sse, p));
            }
        }
    }
    best.map(|b| b.1)
}

/// [`equation_error`] at one latency of the rebuilt duty: the residual's sum of squares and the
/// estimate.
fn equation_error_at(
    prior: &SmartPrior,
    drive_of: &dyn Fn(&SmartLog) -> PositionLoop,
    logs: &[SmartLog],
    latency_s: f64,
) -> Option<(f64, SmartParams)> {
    use nalgebra::{DMatrix, DVector};
    let cols = if prior.load_friction { 6 } else { 5 };
    let mut rows: Vec<[f64; 7]> = Vec::new();
    for l in logs {
        let dt = l.dt_s();
        let n = l.time_s.len();
        let t0 = l.time_s[0];
        let drive = drive_of(l);
        let w: Vec<f64> = match &l.omega_rad_s {
            Some(o) => o.clone(),
            None => (0..n)
                .map(|k| {
                    let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
                    (l.theta_rad[b] - l.theta_rad[a]) / ((b - a).max(1) as f64 * dt)
                })
                .collect(),
        };
        for k in 1..n.saturating_sub(1) {
            if !(l.enabled(k) && l.enabled(k - 1) && l.enabled(k + 1)) {
                continue;
            }
            let v = match (&l.v_supply_v, drive.supply_from_log) {
                (Some(vs), true) if vs[k].is_finite() && vs[k] > 0.0 => vs[k],
                _ => drive.v_supply_v,
            };
            let th = l.theta_rad[k];
            let d = match &l.duty {
                Some(d) => d[k],
                None => drive.duty(goal_at(l, t0, dt, l.time_s[k] - latency_s), th),
            };
            let alpha = (w[k + 1] - w[k - 1]) / (2.0 * dt);
            let m = prior.k_t_per_r * (v * d - prior.k_e * w[k]);
            let sg = if w[k].abs() > 1e-3 {
                w[k].signum()
            } else {
                0.0
            };
            let r = [
                alpha,
                w[k],
                sg,
                sg * m.abs(),
                libm::sin(th),
                libm::cos(th),
                m,
            ];
            if r.iter().all(|x| x.is_finite()) {
                rows.push(r);
            }
        }
    }
    if rows.len() < 10 {
        return None;
    }
    // The regressors (the load-dependent column only when fitted) and the motor's torque.
    let pick = |i: usize, j: usize| -> f64 {
        let r = &rows[i];
        match (cols, j) {
            (5, 3..) => r[j + 1],
            _ => r[j],
        }
    };
    let a = DMatrix::from_fn(rows.len(), cols, pick);
    let y = DVector::from_fn(rows.len(), |i, _| rows[i][6]);
    let x = (a.transpose() * &a).lu().solve(&(a.transpose() * &y))?;
    let sse = (&a * &x - &y).norm_squared();
    let (ga, gb) = (x[cols - 2], x[cols - 1]);
    Some((
        sse,
        SmartParams {
            j_eq: x[0],
            b_eq: x[1],
            tau_sf: x[2],
            load_friction: if cols == 6 { x[3] } else { 0.0 },
            k_t_per_r: prior.k_t_per_r,
            k_e: prior.k_e,
            gravity_nm: libm::hypot(ga, gb),
            phase_rad: libm::atan2(gb, ga),
            latency_s: 0.0,
        },
    ))
}

/// A Nelder-Mead simplex search of `f` from `x0` with initial steps `step`, at most `max_evals`
/// evaluations; returns the best point and its value.
pub fn nelder_mead(
    f: &mut dyn FnMut(&[f64]) -> f64,
    x0: &[f64],
    step: &[f64],
    max_evals: usize,
    f_tol: f64,
) -> (Vec<f64>, f64) {
    let n = x0.len();
    let mut pts: Vec<Vec<f64>> = Vec::with_capacity(n + 1);
    pts.push(x0.to_vec());
    for i in 0..n {
        let mut p = x0.to_vec();
        p[i] += step[i];
        pts.push(p);
    }
    let mut vals: Vec<f64> = pts.iter().map(|p| f(p)).collect();
    let mut evals = n + 1;
    let sane = |v: f64| if v.is_finite() { v } else { f64::INFINITY };
    for v in vals.iter_mut() {
        *v = sane(*v);
    }
    while evals < max_evals {
        let mut idx: Vec<usize> = (0..=n).collect();
        idx.sort_by(|&a, &b| vals[a].total_cmp(&vals[b]));
        pts = idx.iter().map(|&i| pts[i].clone()).collect();
        vals = idx.iter().map(|&i| vals[i]).collect();
        if (vals[n] - vals[0]).abs() <= f_tol * (vals[0].abs() + 1e-300) {
            break;
        }
        let mut c = alloc::vec![0.0; n];
        for p in &pts[..n] {
            for (ci, pi) in c.iter_mut().zip(p) {
                *ci += pi / n as f64;
            }
        }
        let along = |t: f64| -> Vec<f64> {
            c.iter()
                .zip(&pts[n])
                .map(|(ci, wi)| ci + t * (wi - ci))
                .collect()
        };
        let xr = along(-1.0);
        let fr = sane(f(&xr));
        evals += 1;
        if fr < vals[0] {
            let xe = along(-2.0);
            let fe = sane(f(&xe));
            evals += 1;
            if fe < fr {
                pts[n] = xe;
                vals[n] = fe;
            } else {
                pts[n] = xr;
                vals[n] = fr;
            }
        } else if fr < vals[n - 1] {
            pts[n] = xr;
            vals[n] = fr;
        } else {
            let (xc, fc) = if fr < vals[n] {
                let x = along(-0.5);
                let v = sane(f(&x));
                (x, v)
            } else {
                let x = along(0.5);
                let v = sane(f(&x));
                (x, v)
            };
            evals += 1;
            if fc < vals[n].min(fr) {
                pts[n] = xc;
                vals[n] = fc;
            } else {
                for i in 1..=n {
                    let p: Vec<f64> = pts[0]
                        .iter()
                        .zip(&pts[i])
                        .map(|(b, x)| b + 0.5 * (x - b))
                        .collect();
                    vals[i] = sane(f(&p));
                    pts[i] = p;
                }
                evals += n;
            }
        }
    }
    let best = (0..=n)
        .min_by(|&a, &b| vals[a].total_cmp(&vals[b]))
        .unwrap_or(0);
    (pts[best].clone(), vals[best])
}

/// Which fit [`fit`] kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FitKind {
    /// The equation-error least squares on the logged duty.
    EquationError,
    /// The output-error fit on the replayed trajectories.
    OutputError,
}

impl FitKind {
    pub const fn name(self) -> &'static str {
        match self {
            FitKind::EquationError => "equation error",
            FitKind::OutputError => "output error",
        }
    }
}

/// One candidate fit and how it predicts.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    pub kind: FitKind,
    pub params: SmartParams,
    /// Why the candidate is not physical (an inertia below the known part, a negative
    /// friction), empty when it is.
    pub unphysical: Vec<String>,
    /// The pooled position error on the logs it was fitted on.
    pub fit_error: PositionError,
    /// The pooled position error on the held-out logs (`None` without held-out logs).
    pub held_out_error: Option<PositionError>,
}

/// The result of [`fit`].
#[derive(Debug, Clone, PartialEq)]
pub struct SmartFit {
    /// The candidate kept (its index in `candidates`).
    pub kept: usize,
    pub candidates: Vec<Candidate>,
    /// Replays run by the output-error search.
    pub evaluations: usize,
    /// Whether the logs determine the gravity amplitude (when it was fitted).
    pub gravity: GravityFit,
}

/// The gravity amplitude's standing after [`fit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GravityFit {
    /// Given by the prior (it set the torques' scale), not fitted.
    Given,
    /// Fitted and determined by the logs: `rel_se` is its relative standard error (from the
    /// output-error fit's curvature, the residuals' correlation counted).
    Determined { rel_se: f64 },
    /// Fitted, but the logs do not determine it (the angle does not move the gravity torque
    /// enough, or it trades with another parameter): its value is not to be used.
    NotDetermined { rel_se: f64 },
}

impl GravityFit {
    /// Whether a fitted amplitude may be reported as a value.
    pub fn determined(self) -> bool {
        matches!(self, GravityFit::Given | GravityFit::Determined { .. })
    }
}

/// The largest relative standard error of a fitted gravity amplitude reported as determined
/// [-] (10 %: an amplitude known to within a few tenths of itself is not a value a user should
/// design on; the error is the fit's curvature with the residuals' lag-1 correlation counted).
pub const GRAVITY_MAX_REL_SE: f64 = 0.10;

/// The outcome of [`levenberg_marquardt`].
#[derive(Debug, Clone)]
struct LmResult {
    x: Vec<f64>,
    /// Mean squared residual.
    cost: f64,
    /// The covariance of the free coordinates (full-size, zero for fixed ones), the residuals'
    /// variance and correlation counted; `None` when singular.
    cov: Option<nalgebra::DMatrix<f64>>,
}

impl LmResult {
    fn std_error(&self, i: usize) -> Option<f64> {
        let c = self.cov.as_ref()?;
        let v = c[(i, i)];
        (v.is_finite() && v > 0.0).then(|| libm::sqrt(v))
    }
}

/// Levenberg-Marquardt on the residuals `res(x)` over the coordinates marked `free`, the
/// Jacobian by forward differences of steps `fd`, at most `max_evals` evaluations of `res`.
/// `None` when the start does not evaluate.
fn levenberg_marquardt(
    res: &mut dyn FnMut(&[f64]) -> Option<Vec<f64>>,
    x0: &[f64],
    fd: &[f64],
    free: &[bool],
    max_evals: usize,
) -> Option<LmResult> {
    use nalgebra::{DMatrix, DVector};
    let idx: Vec<usize> = (0..x0.len()).filter(|&i| free[i]).collect();
    let k = idx.len();
    let mut x = x0.to_vec();
    let mut r = res(&x)?;
    let m = r.len().max(1);
    let ss = |r: &[f64]| r.iter().map(|e| e * e).sum::<f64>();
    let mut cost = ss(&r);
    let mut evals = 1usize;
    let mut lambda = 1e-2;
    let mut jac = DMatrix::<f64>::zeros(m, k);
    let mut jac_ok = false;
    while evals + k < max_evals {
        if !jac_ok {
            for (c, &i) in idx.iter().enumerate() {
                let mut xp = x.clone();
                xp[i] += fd[i];
                evals += 1;
                let rp = res(&xp)?;
                for row in 0..m {
                    jac[(row, c)] = (rp[row] - r[row]) / fd[i];
                }
            }
            jac_ok = true;
        }
        let jt = jac.transpose();
        let jtj = &jt * &jac;
        let g = &jt * DVector::from_column_slice(&r);
        let mut a = jtj.clone();
        for d in 0..k {
            a[(d, d)] += lambda * jtj[(d, d)].max(1e-12);
        }
        let Some(step) = a.lu().solve(&(-g)) else {
            lambda *= 10.0;
            if lambda > 1e8 {
                break;
            }
            continue;
        };
        let mut xn = x.clone();
        for (c, &i) in idx.iter().enumerate() {
            xn[i] += step[c];
        }
        evals += 1;
        let rn = res(&xn);
        let cn = rn.as_ref().map_or(f64::INFINITY, |r| ss(r));
        if cn < cost {
            let gain = (cost - cn) / cost.max(1e-300);
            x = xn;
            cost = cn;
            r = rn.unwrap_or_default();
            jac_ok = false;
            lambda = (lambda / 3.0).max(1e-9);
            if gain < 1e-6 {
                break;
            }
        } else {
            lambda *= 4.0;
            if lambda > 1e8 {
                break;
            }
        }
    }
    // The covariance at the optimum: s^2 (J'J)^-1 with the residuals' lag-1 correlation rho
    // shrinking the rows to an effective m (1 - rho) / (1 + rho).
    if !jac_ok {
        jac_ok = true;
        for (c, &i) in idx.iter().enumerate() {
            let mut xp = x.clone();
            xp[i] += fd[i];
            let Some(rp) = res(&xp) else {
                jac_ok = false;
                break;
            };
            for row in 0..m {
                jac[(row, c)] = (rp[row] - r[row]) / fd[i];
            }
        }
    }
    let cov = (|| {
        if !jac_ok {
            return None;
        }
        // Scaled to unit columns (the coordinates differ by orders of magnitude); a column of
        // zero (a parameter pinned at a bound, or without effect) leaves the fit's curvature
        // singular: nothing is determined by it.
        let jtj = jac.transpose() * &jac;
        let d: Vec<f64> = (0..k).map(|i| libm::sqrt(jtj[(i, i)])).collect();
        if d.iter().any(|x| !(x.is_finite() && *x > 0.0)) {
            return None;
        }
        let c = DMatrix::from_fn(k, k, |i, j| jtj[(i, j)] / (d[i] * d[j]));
        let ci = c.try_inverse()?;
        let inv = DMatrix::from_fn(k, k, |i, j| ci[(i, j)] / (d[i] * d[j]));
        let mean = r.iter().sum::<f64>() / m as f64;
        let var = r.iter().map(|e| (e - mean) * (e - mean)).sum::<f64>();
        let lag: f64 = r.windows(2).map(|w| (w[0] - mean) * (w[1] - mean)).sum();
        let rho = if var > 0.0 {
            (lag / var).clamp(0.0, 0.999)
        } else {
            0.0
        };
        let m_eff = (m as f64 * (1.0 - rho) / (1.0 + rho)).max(k as f64 + 1.0);
        let s2 = cost / (m as f64 - k as f64).max(1.0);
        let mut full = DMatrix::<f64>::zeros(x.len(), x.len());
        for (a, &i) in idx.iter().enumerate() {
            for (b, &j) in idx.iter().enumerate() {
                full[(i, j)] = inv[(a, b)] * s2 * m as f64 / m_eff;
            }
        }
        Some(full)
    })();
    Some(LmResult {
        x,
        cost: cost / m as f64,
        cov,
    })
}

impl SmartFit {
    /// The parameters kept.
    pub fn params(&self) -> SmartParams {
        self.candidates[self.kept].params
    }
}

/// The unphysical parts of a parameter set (empty: physical).
pub fn unphysical(p: &SmartParams, prior: &SmartPrior) -> Vec<String> {
    let mut why = Vec::new();
    if p.j_eq.is_nan() || p.j_eq <= 0.0 || p.j_eq < prior.j_min {
        why.push(alloc::format!(
            "J_eq = {} kg m^2 is below the known inertia {} kg m^2",
            math::Num(p.j_eq),
            math::Num(prior.j_min)
        ));
    }
    for (name, v) in [("B_eq", p.b_eq), ("tau_sf", p.tau_sf)] {
        if v.is_nan() || v < 0.0 {
            why.push(alloc::format!("{name} = {} is negative", math::Num(v)));
        }
    }
    why
}

/// The physical parameters nearest to `p` (inertia at least the known part, frictions >= 0),
/// where an output-error search can start.
fn physical(p: &SmartParams, prior: &SmartPrior) -> SmartParams {
    let j_floor = (prior.j_min * 1.2).max(1e-9);
    SmartParams {
        j_eq: if p.j_eq.is_finite() {
            p.j_eq.max(j_floor)
        } else {
            j_floor
        },
        b_eq: p.b_eq.max(1e-4),
        tau_sf: p.tau_sf.max(1e-4),
        gravity_nm: p.gravity_nm.max(1e-4),
        latency_s: p.latency_s.clamp(0.0, prior.latency_max_s),
        load_friction: if prior.load_friction {
            p.load_friction.clamp(0.02, 0.9)
        } else {
            0.0
        },
        ..*p
    }
}

/// The search coordinates of the output-error fit: J_eq = J_min + e^x0, B_eq = e^x1,
/// tau_sf = e^x2, k_t/R = e^x3, m g L = e^x4, phase = x5, latency = L_max (1 + sin x6) / 2
/// (no flat end where the search could stall), the load friction 1 / (1 + e^-x7).
fn to_x(p: &SmartParams, prior: &SmartPrior) -> [f64; 8] {
    // Off the ends, where the sine's slope vanishes and a search would stall.
    let lat = (p.latency_s / prior.latency_max_s).clamp(0.02, 0.98);
    [
        libm::log((p.j_eq - prior.j_min).max(1e-4 * p.j_eq.max(1e-9))),
        libm::log(p.b_eq.max(1e-6)),
        libm::log(p.tau_sf.max(1e-6)),
        libm::log(p.k_t_per_r.max(1e-9)),
        libm::log(p.gravity_nm.max(1e-6)),
        p.phase_rad,
        libm::asin(2.0 * lat - 1.0),
        {
            let m = p.load_friction.clamp(0.01, 0.99);
            libm::log(m / (1.0 - m))
        },
    ]
}

fn from_x(x: &[f64], prior: &SmartPrior, k_e: f64) -> SmartParams {
    SmartParams {
        j_eq: prior.j_min + libm::exp(x[0]),
        b_eq: libm::exp(x[1]),
        tau_sf: libm::exp(x[2]),
        load_friction: if prior.load_friction {
            1.0 / (1.0 + libm::exp(-x[7]))
        } else {
            0.0
        },
        // The scale: one of the two is known and not searched (its step is 0), see [`fit`].
        k_t_per_r: if prior.gravity_nm.is_some() {
            libm::exp(x[3])
        } else {
            prior.k_t_per_r
        },
        k_e,
        gravity_nm: prior.gravity_nm.unwrap_or(libm::exp(x[4])),
        phase_rad: x[5],
        latency_s: prior.latency_max_s * 0.5 * (1.0 + libm::sin(x[6])),
    }
}

/// Fits the model on `fit_logs` (equation error, then output error on the whole trajectories
/// from its physical neighbour) and keeps the candidate that predicts `held_out` best (the
/// output-error one when nothing is held out or the equation-error one is unphysical).
///
/// A log of positions driven by the firmware's loop cannot tell the scale of the torques from
/// the inertia (every torque and J_eq times the same factor give the same trajectory): one
/// known torque sets it. With a known gravity amplitude (`prior.gravity_nm`, a bench's m g L)
/// k_t / R is searched and the gravity kept; otherwise k_t / R stays the prior's.
pub fn fit(
    prior: &SmartPrior,
    drive_of: &dyn Fn(&SmartLog) -> PositionLoop,
    fit_logs: &[SmartLog],
    held_out: &[SmartLog],
    max_evals: usize,
) -> Result<SmartFit, SmartError> {
    if fit_logs.is_empty() {
        return Err(SmartError::NoLogs);
    }
    for l in fit_logs.iter().chain(held_out) {
        l.validate()?;
    }
    let pooled = |p: &SmartParams, logs: &[SmartLog]| -> Result<PositionError, SmartError> {
        Ok(PositionError::pooled(&errors(p, drive_of, logs)?))
    };
    let default_start = SmartParams {
        j_eq: (prior.j_min * 1.5).max(1e-6),
        b_eq: 0.01,
        tau_sf: 0.01,
        load_friction: 0.0,
        k_t_per_r: prior.k_t_per_r,
        k_e: prior.k_e,
        gravity_nm: 0.1,
        phase_rad: 0.0,
        latency_s: 0.0,
    };
    let ee = equation_error(prior, drive_of, fit_logs);
    let start = physical(ee.as_ref().unwrap_or(&default_start), prior);
    let mut evals = 0usize;
    let mut residuals = |x: &[f64]| -> Option<Vec<f64>> {
        evals += 1;
        let p = from_x(x, prior, prior.k_e);
        let mut r = Vec::new();
        for l in fit_logs {
            let rep = replay(&p, &drive_of(l), l).ok()?;
            r.extend(rep.theta_rad.iter().zip(&l.theta_rad).map(|(a, b)| a - b));
        }
        Some(r)
    };
    // The coordinates searched (see [`to_x`]) and their finite-difference steps; one of k_t / R
    // and m g L is known and not searched.
    let mut free = [
        true,
        true,
        true,
        false,
        true,
        true,
        true,
        prior.load_friction,
    ];
    if prior.gravity_nm.is_some() {
        free[3] = true;
        free[4] = false;
    }
    let fd = [0.01, 0.01, 0.01, 0.005, 0.005, 0.002, 0.02, 0.02];
    // Several starts that split the friction differently between the Coulomb and the
    // load-dependent parts (a search from one split can stop in a local minimum), each refined
    // by Levenberg-Marquardt on the whole trajectories; the best kept.
    // The first start is the equation-error estimate's own split and latency (mid-range when
    // it has none); the others move the friction's split.
    let splits: &[(f64, Option<f64>)] = if prior.load_friction {
        &[
            (1.0, None),
            (1.0, Some(0.02)),
            (0.5, Some(0.15)),
            (0.2, Some(0.4)),
        ]
    } else {
        &[(1.0, None)]
    };
    let per = (max_evals / splits.len()).max(30);
    let mut best: Option<LmResult> = None;
    for &(coulomb_share, lf) in splits {
        let lat = if start.latency_s > 0.0 {
            start.latency_s
        } else {
            0.5 * prior.latency_max_s
        };
        let x0 = to_x(
            &SmartParams {
                latency_s: lat,
                load_friction: lf.unwrap_or(start.load_friction),
                tau_sf: start.tau_sf * coulomb_share,
                ..start
            },
            prior,
        );
        let Some(r) = levenberg_marquardt(&mut residuals, &x0, &fd, &free, per) else {
            continue;
        };
        if best.as_ref().is_none_or(|b| r.cost < b.cost) {
            best = Some(r);
        }
    }
    let Some(best) = best else {
        return Err(SmartError::Diverged {
            log: fit_logs[0].name.clone(),
            row: 0,
        });
    };
    let x = best.x.clone();
    let gravity = if prior.gravity_nm.is_some() {
        GravityFit::Given
    } else {
        // x4 = ln(m g L): its standard error is the relative one of the amplitude.
        match best.std_error(4) {
            Some(se) if se <= GRAVITY_MAX_REL_SE => GravityFit::Determined { rel_se: se },
            se => GravityFit::NotDetermined {
                rel_se: se.unwrap_or(f64::INFINITY),
            },
        }
    };
    let oe = from_x(&x, prior, prior.k_e);
    let mut candidates = Vec::new();
    if let Some(p) = ee {
        let why = unphysical(&p, prior);
        // An unphysical estimate may not even replay: its errors are then infinite.
        let e = pooled(&p, fit_logs).unwrap_or(PositionError {
            mae_rad: f64::INFINITY,
            rmse_rad: f64::INFINITY,
            rows: 0,
        });
        let h = if held_out.is_empty() {
            None
        } else {
            Some(pooled(&p, held_out).unwrap_or(PositionError {
                mae_rad: f64::INFINITY,
                rmse_rad: f64::INFINITY,
                rows: 0,
            }))
        };
        candidates.push(Candidate {
            kind: FitKind::EquationError,
            params: p,
            unphysical: why,
            fit_error: e,
            held_out_error: h,
        });
    }
    candidates.push(Candidate {
        kind: FitKind::OutputError,
        params: oe,
        unphysical: unphysical(&oe, prior),
        fit_error: pooled(&oe, fit_logs)?,
        held_out_error: if held_out.is_empty() {
            None
        } else {
            Some(pooled(&oe, held_out)?)
        },
    });
    let score = |c: &Candidate| -> f64 {
        if !c.unphysical.is_empty() {
            return f64::INFINITY;
        }
        c.held_out_error.unwrap_or(c.fit_error).rmse_rad
    };
    // Ties (both unphysical) keep the output-error fit: the later candidate.
    let kept = (0..candidates.len())
        .rev()
        .min_by(|&a, &b| score(&candidates[a]).total_cmp(&score(&candidates[b])))
        .unwrap_or(candidates.len() - 1);
    Ok(SmartFit {
        kept,
        candidates,
        evaluations: evals,
        gravity,
    })
}

impl SmartParams {
    /// The output-shaft parameters of a servo model (eqs. 10-20 at the load: J_eq N^2,
    /// B_eq N^2, k_t N / (R_a + R_s), k_e N) with the catalogue's gravity effect (`effects::GRAVITY`) as the gravity
    /// (amplitude and phase; none when absent) and the given latency.
    pub fn from_model(
        p: &crate::params::PlantParams,
        effects: &crate::effects::Effects,
        latency_s: f64,
    ) -> SmartParams {
        let n = p.n;
        SmartParams {
            j_eq: p.j_eq() * n * n,
            b_eq: p.b_eq() * n * n,
            tau_sf: p.tau_sf(),
            load_friction: 0.0,
            k_t_per_r: p.k_t * n / (p.r_a + p.r_s),
            k_e: p.k_e * n,
            gravity_nm: effects
                .value(crate::effects::GRAVITY, "amplitude")
                .unwrap_or(0.0),
            phase_rad: effects
                .value(crate::effects::GRAVITY, "phase")
                .unwrap_or(0.0),
            latency_s,
        }
    }
}
