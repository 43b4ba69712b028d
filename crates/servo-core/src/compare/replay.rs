//! Replaying a log on the model: the model is driven as the real motor was, sample by sample.
//!
//! An integrating plant (position = integral of speed) drifts without bound when it is driven
//! open loop with a logged voltage: a small friction error becomes a growing position error that
//! says nothing about where the model is wrong. The modes therefore are:
//!
//! * [`ReplayMode::ClosedLoop`]: the model with the logged reference and the real controller (PID
//!   gains known) in the loop, including the output limit of the board and the encoder
//!   quantisation. Position stays bounded, as on the real motor. The best mode for controller logs.
//! * [`ReplayMode::Speed`]: the logged u drives the model open loop and speed (not position) is
//!   compared: speed is a stable first-order-like response, it does not drift.
//! * [`ReplayMode::KStep`]: k-step-ahead prediction: every model sample is predicted from the
//!   measured state k samples earlier and the logged inputs in between (MATLAB's `compare(.., k)`).
//! * [`ReplayMode::Segments`]: the model is re-initialised from the measured state at the start
//!   of each segment of `len` samples and runs free within it.
//!
//! Log convention: row k holds measurements at t_k and the u applied from t_k to t_{k+1}; the
//! model output of row k is therefore the state *before* u_k is applied.

use super::measured::Measured;
use super::quantum::quantize;
use super::CompareError;
use crate::plant::Plant;
use crate::sim::{PlantSim, PlantState};
use alloc::vec::Vec;

/// How the model is driven with the log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReplayMode {
    /// Model plus the logged controller and reference, in closed loop.
    ClosedLoop,
    /// Open loop with the logged u; speed is compared.
    Speed,
    /// k-step-ahead prediction from the measured state.
    KStep { k: usize },
    /// Free run re-initialised from the measured state every `len` samples.
    Segments { len: usize },
}

impl ReplayMode {
    /// The name users type (`closed-loop`, `speed`, `k-step`, `segments`).
    pub fn name(&self) -> &'static str {
        match self {
            ReplayMode::ClosedLoop => "closed-loop",
            ReplayMode::Speed => "speed",
            ReplayMode::KStep { .. } => "k-step",
            ReplayMode::Segments { .. } => "segments",
        }
    }
}

/// The controller of a closed-loop replay: one output per sample.
pub trait Controller {
    /// Driver input u [V] for the sample with reference `reference_rad` and measured load angle
    /// `measured_rad` (before any output limit, which the replay applies).
    fn update(&mut self, reference_rad: f64, measured_rad: f64) -> f64;
}

impl<F: FnMut(f64, f64) -> f64> Controller for F {
    fn update(&mut self, reference_rad: f64, measured_rad: f64) -> f64 {
        self(reference_rad, measured_rad)
    }
}

/// servo's discrete PID ([`crate::control::Pid`]) as the controller of a replay (no feedforward).
impl Controller for crate::control::Pid {
    fn update(&mut self, reference_rad: f64, measured_rad: f64) -> f64 {
        crate::control::Pid::update(self, reference_rad, measured_rad, 0.0).u_v
    }
}

/// What closes the loop in [`ReplayMode::ClosedLoop`].
pub struct ClosedLoop<'a> {
    /// The controller as it ran on the board (fresh state at the start of the log).
    pub controller: &'a mut dyn Controller,
    /// Output limit of the board [V] (symmetric), e.g. the +/-10 V of the DAC.
    pub u_limit_v: Option<f64>,
    /// Encoder quantum [rad]: the model's angle is rounded down to this grid before the
    /// controller sees it.
    pub encoder_quantum_rad: Option<f64>,
}

/// The model's side of a comparison, on the time base of the log.
#[derive(Debug, Clone, PartialEq)]
pub struct Replay {
    pub mode: ReplayMode,
    /// Load angle theta_l of the model [rad].
    pub theta_l_rad: Vec<f64>,
    /// Load speed omega_l of the model [rad/s] (the simulator's state).
    pub omega_l_rad_s: Vec<f64>,
    /// Armature current i_a of the model [A].
    pub i_a_a: Vec<f64>,
    /// Driver input u that drove the model [V] (closed loop: the model's controller output after
    /// the limit; otherwise the logged u).
    pub u_v: Vec<f64>,
}

/// The measured state at row `k`, as a simulator state. The current, when not logged, is the
/// quasi-steady value of the armature circuit for the previous input (L_a / R_eq ~ 60 us).
pub fn measured_state(plant: &Plant, m: &Measured, k: usize) -> PlantState {
    let p = &plant.params;
    let n = p.n;
    let theta_l = m.theta_l_rad.as_ref().map_or(0.0, |t| t[k]);
    // A logged speed replaced for its lag still holds the start, where a zero-phase derivative
    // sees one side only: a causal estimate's first sample is the speed the log started from.
    let omega_l = match (m.logged_omega_l0_rad_s, k) {
        (Some(w0), 0) => w0,
        _ => m.omega_l_rad_s[k],
    };
    let u_prev = if k > 0 { m.u_v[k - 1] } else { m.u_v[0] };
    let u_drv = p.k_drv * u_prev;
    let i_a = match &m.i_a_a {
        Some(i) => i[k],
        None => (u_drv - p.k_e * omega_l * n) / p.r_eq(),
    };
    PlantState {
        time_s: m.time_s[k],
        u_in_v: u_prev,
        u_drv_v: u_drv,
        i_a_a: i_a,
        omega_m_rad_s: omega_l * n,
        theta_m_rad: theta_l * n,
        omega_l_rad_s: omega_l,
        theta_l_rad: theta_l,
        ..PlantState::default()
    }
}

/// Length of the start of a log over which the initial speed is estimated [s].
const INITIAL_WINDOW_S: f64 = 0.1;

/// The state the open-loop replay starts from: the measured state at row 0, with the speed
/// estimated when it was derived from the position.
///
/// A speed derived with a zero-phase filter is unreliable at the first samples of a log (the
/// filter sees only one side; a motor started hard from rest reads -4 rad/s instead of 0), and
/// a wrong initial speed puts the whole first transient of the model off. Like MATLAB's
/// `compare` with estimated initial conditions, the initial speed is the one whose free run with
/// the logged input best follows the measured position over the first 0.1 s (grid then golden
/// section over the measured value +- 2 |omega_0| + 1 rad/s).
pub fn initial_state(plant: &Plant, m: &Measured) -> PlantState {
    let s0 = measured_state(plant, m, 0);
    let n = plant.params.n;
    let with = |omega_l: f64| PlantState {
        omega_l_rad_s: omega_l,
        omega_m_rad_s: omega_l * n,
        ..s0
    };
    // A logged speed replaced for its lag gave the start ([`measured_state`]).
    let estimate = m.speed_derived && m.logged_omega_l0_rad_s.is_none();
    let Some(theta) = m.theta_l_rad.as_ref().filter(|_| estimate) else {
        return s0;
    };
    let w = ((INITIAL_WINDOW_S / m.dt_s) as usize).clamp(2, m.len().saturating_sub(1));
    if w < 2 {
        return s0;
    }
    let Ok(mut sim) = PlantSim::new(plant, m.dt_s) else {
        return s0;
    };
    let mut cost = |omega_l: f64| -> f64 {
        sim.reset(with(omega_l));
        let mut e2 = 0.0;
        for (th, u) in theta.iter().zip(&m.u_v).take(w) {
            let e = sim.state().theta_l_rad - th;
            e2 += e * e;
            sim.step(*u);
        }
        if e2.is_finite() {
            e2
        } else {
            f64::INFINITY
        }
    };
    let w0 = s0.omega_l_rad_s;
    let r = 2.0 * w0.abs() + 1.0;
    let grid = crate::fit::search::linspace(w0 - r, w0 + r, 21);
    match crate::fit::search::grid_then_golden(&grid, &mut cost, 20) {
        Some((omega_l, _)) => with(omega_l),
        None => s0,
    }
}

struct Out {
    th: Vec<f64>,
    w: Vec<f64>,
    i: Vec<f64>,
    u: Vec<f64>,
}

impl Out {
    fn new(n: usize) -> Out {
        Out {
            th: Vec::with_capacity(n),
            w: Vec::with_capacity(n),
            i: Vec::with_capacity(n),
            u: Vec::with_capacity(n),
        }
    }
    fn push(&mut self, s: &PlantState, u: f64) {
        self.th.push(s.theta_l_rad);
        self.w.push(s.omega_l_rad_s);
        self.i.push(s.i_a_a);
        self.u.push(u);
    }
}

#[allow(clippy::needless_range_loop)]
/// Replays `m` on `plant` in `mode`. `closed_loop` is required for [`ReplayMode::ClosedLoop`].
pub fn replay(
    plant: &Plant,
    m: &Measured,
    mode: ReplayMode,
    closed_loop: Option<ClosedLoop<'_>>,
) -> Result<Replay, CompareError> {
    let n = m.len();
    let mut sim = PlantSim::new(plant, m.dt_s).map_err(CompareError::Sim)?;
    let mut out = Out::new(n);
    match mode {
        ReplayMode::ClosedLoop => {
            let cl = closed_loop.ok_or(CompareError::NoController)?;
            let reference = m
                .ref_rad
                .as_ref()
                .ok_or(CompareError::Missing("ref (position reference)"))?;
            if m.theta_l_rad.is_none() {
                return Err(CompareError::Missing(
                    "theta_l (load angle) for a closed-loop replay",
                ));
            }
            let mut s0 = measured_state(plant, m, 0);
            // The log starts with the motor as measured; the driver state follows the first input.
            s0.time_s = 0.0;
            sim.reset(s0);
            for k in 0..n {
                let st = *sim.state();
                let y = match cl.encoder_quantum_rad {
                    Some(q) => quantize(st.theta_l_rad, q),
                    None => st.theta_l_rad,
                };
                let mut u = cl.controller.update(reference[k], y);
                if !u.is_finite() {
                    return Err(CompareError::ControllerDiverged { row: k });
                }
                if let Some(lim) = cl.u_limit_v {
                    u = u.clamp(-lim, lim);
                }
                out.push(&st, u);
                sim.step(u);
            }
        }
        ReplayMode::Speed => {
            sim.reset(initial_state(plant, m));
            for k in 0..n {
                let st = *sim.state();
                out.push(&st, m.u_v[k]);
                sim.step(m.u_v[k]);
            }
        }
        ReplayMode::Segments { len } => {
            let len = len.max(1);
            for k in 0..n {
                if k == 0 {
                    sim.reset(initial_state(plant, m));
                } else if k % len == 0 {
                    sim.reset(measured_state(plant, m, k));
                }
                let st = *sim.state();
                out.push(&st, m.u_v[k]);
                sim.step(m.u_v[k]);
            }
        }
        ReplayMode::KStep { k: kk } => {
            let kk = kk.max(1);
            for t in 0..n {
                if t < kk {
                    // Not enough history: the measured state itself (zero-step prediction).
                    let st = measured_state(plant, m, t);
                    out.push(&st, m.u_v[t]);
                    continue;
                }
                sim.reset(measured_state(plant, m, t - kk));
                for j in t - kk..t {
                    sim.step(m.u_v[j]);
                }
                let st = *sim.state();
                out.push(&st, m.u_v[t]);
            }
        }
    }
    if let Some(i) = out.th.iter().chain(&out.w).position(|v| !v.is_finite()) {
        return Err(CompareError::SimDiverged { row: i % n });
    }
    Ok(Replay {
        mode,
        theta_l_rad: out.th,
        omega_l_rad_s: out.w,
        i_a_a: out.i,
        u_v: out.u,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::PlantParams;
    use crate::record::Record;

    /// A motor started hard from rest: the speed derived from position reads a large speed at
    /// row 0 (one-sided filter); the estimated initial speed is the true one (0), and the speed
    /// replay of the true model matches the measurement from the first sample on.
    #[test]
    fn initial_speed_is_estimated_from_the_first_positions() {
        let plant = Plant::from_params(PlantParams::TABLE2).unwrap();
        let dt = 1e-3;
        let mut sim = PlantSim::new(&plant, dt).unwrap();
        let (mut t, mut th, mut u) = (vec![], vec![], vec![]);
        for k in 0..600 {
            let s = sim.state();
            t.push(k as f64 * dt);
            th.push(s.theta_l_rad);
            let v = if k < 300 { -6.5 } else { 4.0 };
            u.push(v);
            sim.step(v);
        }
        let rec = Record {
            source: "test".into(),
            time_s: t,
            theta_l_rad: Some(th),
            u_v: Some(u),
            ..Record::default()
        };
        let m = Measured::from_record(&rec, plant.params.n, 30.0).unwrap();
        assert!(m.speed_derived);
        let naive = measured_state(&plant, &m, 0).omega_l_rad_s;
        assert!(naive.abs() > 1.0, "derived speed at row 0: {naive}");
        let s0 = initial_state(&plant, &m);
        // Not exactly 0: without a logged current the replay starts the armature at the
        // quasi-steady current of u[0], ~60 us ahead of the real one; the estimate absorbs that.
        assert!(
            s0.omega_l_rad_s.abs() < 0.1 * naive.abs(),
            "estimated {}, derived {naive}",
            s0.omega_l_rad_s
        );
        let r = replay(&plant, &m, ReplayMode::Speed, None).unwrap();
        let e = r.theta_l_rad[..100]
            .iter()
            .zip(&m.theta_l_rad.as_ref().unwrap()[..100])
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(e < 1e-3, "position error over the first 0.1 s: {e}");
        // Started from the derived speed instead, the model is visibly off.
        let mut sim = PlantSim::new(&plant, dt).unwrap();
        sim.reset(measured_state(&plant, &m, 0));
        let mut e_naive: f64 = 0.0;
        for k in 0..100 {
            e_naive =
                e_naive.max((sim.state().theta_l_rad - m.theta_l_rad.as_ref().unwrap()[k]).abs());
            sim.step(m.u_v[k]);
        }
        assert!(e_naive > 5.0 * e, "naive {e_naive} vs estimated {e}");
    }
}
