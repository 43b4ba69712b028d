//! The whole `servo design` pipeline: synthesis on the design model, optional `--exact` solve,
//! and verification of what the user will get on the reduced model, the full model and the
//! discrete loop at T_s (margins, crossover, poles, stability, step metrics).

use super::bode::{synthesize, ControllerKind, DerivativeFilter, PidGains};
use super::closed_loop::{ClosedLoop, Stability};
use super::controller::{discrete_response, Discretization};
use super::margins::{margins, Margins, Sweep};
use super::ss::DiscreteStateSpace;
use super::step::{metrics, step_response, StepMetrics, StepResponse};
use super::{Complex, DesignError, LoopSpec, PlantModel};
use crate::math;
use alloc::vec::Vec;

/// What to design.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DesignRequest {
    pub kind: ControllerKind,
    pub spec: LoopSpec,
    /// T_I / T_D (PID only).
    pub alpha: f64,
    pub filter: DerivativeFilter,
    /// Sample period T_s [s] of the discrete controller.
    pub ts_s: f64,
    pub discretization: Discretization,
    /// Reduced model (eq. 29).
    pub reduced: PlantModel,
    /// Full model (eq. 27), when the parameters are known (not with a bare k_m, T_m).
    pub full: Option<PlantModel>,
    /// Design on the full model instead of the reduced one.
    pub design_on_full: bool,
    /// Solve for the gains whose achieved figures on the discrete loop equal the spec.
    pub exact: bool,
}

impl DesignRequest {
    /// The handout's example design (eqs. 44-53): a PID for w_gc = 30 rad/s and phi_m = 60 deg,
    /// alpha = T_I / T_D = 4, 1 / T_L = 5 w_gc, on the reduced model of `params`, verified on
    /// the full one, discretised by `discretization` at `ts_s` [s].
    pub fn handout(
        params: &crate::params::PlantParams,
        ts_s: f64,
        discretization: Discretization,
    ) -> DesignRequest {
        DesignRequest {
            kind: ControllerKind::Pid,
            spec: LoopSpec {
                omega_gc: 30.0,
                phase_margin: 60f64.to_radians(),
            },
            alpha: 4.0,
            filter: DerivativeFilter::Factor(5.0),
            ts_s,
            discretization,
            reduced: PlantModel::reduced(params),
            full: Some(PlantModel::full(params)),
            design_on_full: false,
            exact: false,
        }
    }
}

/// Achieved figures of one loop.
#[derive(Debug, Clone, PartialEq)]
pub struct Achieved {
    /// "reduced", "full" or "discrete".
    pub name: &'static str,
    /// Plant of the loop ("reduced" or "full").
    pub plant: &'static str,
    pub margins: Margins,
    /// Closed-loop poles: s [rad/s] (continuous) or z (discrete).
    pub poles: Vec<Complex<f64>>,
    pub stability: Stability,
    /// Step metrics; None when the loop is not stable.
    pub step: Option<StepMetrics>,
    /// Step response (empty when not stable).
    pub response: StepResponse,
}

/// Result of a design.
#[derive(Debug, Clone, PartialEq)]
pub struct DesignReport {
    pub request: DesignRequest,
    /// The handout's design (eqs. 44-53) on the design model.
    pub handout_gains: PidGains,
    /// The gains to use: the handout's, or the `--exact` solution.
    pub gains: PidGains,
    pub reduced: Achieved,
    pub full: Option<Achieved>,
    pub discrete: Achieved,
    /// Discrete plant (ZOH) used for the discrete verification.
    pub discrete_plant: DiscreteStateSpace,
}

impl DesignReport {
    /// Loop response L(jw) of the named loop ("reduced", "full", "discrete").
    pub fn loop_response(&self, which: &str, omega: f64) -> Option<Complex<f64>> {
        let g = &self.gains;
        match which {
            "reduced" => Some(g.response(omega) * self.request.reduced.response(omega)),
            "full" => self
                .request
                .full
                .map(|m| g.response(omega) * m.response(omega)),
            "discrete" => Some(
                discrete_response(
                    g,
                    self.discrete_plant.ts_s,
                    self.request.discretization,
                    omega,
                ) * self.discrete_plant.response(omega),
            ),
            _ => None,
        }
    }
}

/// Frequency sweep for the margins of a loop with crossover near `omega_gc`.
pub fn sweep_for(omega_gc: f64, plant: &PlantModel, gains: &PidGains, ts_s: Option<f64>) -> Sweep {
    let lo = omega_gc * 1e-3;
    let hi = match ts_s {
        Some(ts) => 0.9999 * math::PI / ts,
        None => {
            let filt = if gains.tl_s > 0.0 {
                10.0 / gains.tl_s
            } else {
                0.0
            };
            (1e3 * omega_gc).max(100.0 * plant.fastest_pole()).max(filt)
        }
    };
    Sweep {
        omega_lo: lo,
        omega_hi: hi.max(lo * 10.0),
        points: 2000,
        loop_type: 1 + i32::from(gains.ki != 0.0),
    }
}

fn step_of(
    cl: &ClosedLoop,
    poles: &[Complex<f64>],
    omega_gc: f64,
) -> (Option<StepMetrics>, StepResponse) {
    // horizon: 1.5 x the 1 % envelope of the slowest pole, within [10, 300] / w_gc
    let slowest = poles
        .iter()
        .map(|p| match cl.ts_s {
            Some(ts) => -math::ln(super::c_abs(*p)) / ts,
            None => -p.re,
        })
        .fold(f64::INFINITY, f64::min);
    let horizon = (1.5 * 4.6 / slowest).clamp(10.0 / omega_gc, 300.0 / omega_gc);
    let r = step_response(cl, horizon, 40_000);
    (Some(metrics(&r)), r)
}

/// Verifies `gains` on a continuous plant model.
pub fn verify_continuous(
    gains: &PidGains,
    model: &PlantModel,
    omega_gc: f64,
) -> Result<Achieved, DesignError> {
    let m = margins(
        |w| gains.response(w) * model.response(w),
        &sweep_for(omega_gc, model, gains, None),
    );
    let cl = ClosedLoop::continuous(&model.state_space(), gains).ok_or(DesignError::Invalid(
        "the derivative needs T_L > 0 to be simulated (use --tl-factor or --tl > 0)",
    ))?;
    finish(model.name(), model.name(), m, cl, omega_gc)
}

/// The loop of `gains` on `model` with a rotor-side stiffness `k_nm_per_rad` [N m/rad] added to
/// the mechanics (an angle-dependent torque linearised about an angle, [`crate::stiffness`]):
/// J_eq s^2 theta_m + B s theta_m + k theta_m = c u, so P_k = P / (1 + k N P / c) with
/// `drive_nm_per_v` = c = k_drv k_t / R_eq, the stall torque per volt [N m/V]: the plant with the
/// static output feedback k N / c. Exact for the reduced model (eq. 29 with the spring); on the
/// full model (eq. 27) the driver's and the armature's lags, far above w_gc, are left out of the
/// spring's path. The phase margin is the one at the crossover nearest the design's `omega_gc`
/// [rad/s] (within a decade: a spring adds a low-frequency crossover of its own, whose margin
/// says nothing about stability when the spring is negative); stability from the closed loop's
/// poles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpringLoop {
    /// Phase margin [deg] and crossover [rad/s] near the design's (NaN when none there).
    pub phase_margin_deg: f64,
    pub omega_gc: f64,
    /// `None` with an ideal derivative (T_L = 0), which has no state-space realisation.
    pub stability: Option<Stability>,
}

/// See [`SpringLoop`].
pub fn loop_with_stiffness(
    gains: &PidGains,
    model: &PlantModel,
    omega_gc: f64,
    k_nm_per_rad: f64,
    drive_nm_per_v: f64,
) -> SpringLoop {
    let n = match model {
        PlantModel::Reduced { n, .. } | PlantModel::Full { n, .. } => *n,
    };
    let spring = k_nm_per_rad * n / drive_nm_per_v;
    let m = margins(
        |w| {
            let p = model.response(w);
            gains.response(w) * p / (Complex::new(1.0, 0.0) + p * spring)
        },
        &Sweep {
            omega_lo: 0.1 * omega_gc,
            omega_hi: 10.0 * omega_gc,
            points: 2000,
            loop_type: 1 + i32::from(gains.ki != 0.0),
        },
    );
    let mut ss = model.state_space();
    ss.a -= (&ss.b * ss.c.transpose()) * spring;
    let stability = ClosedLoop::continuous(&ss, gains)
        .map(|cl| super::closed_loop::classify(&cl.poles(), false));
    SpringLoop {
        phase_margin_deg: m.phase_margin_deg,
        omega_gc: m.omega_gc,
        stability,
    }
}

/// Verifies `gains` on the discrete loop (ZOH plant + discrete PID).
pub fn verify_discrete(
    gains: &PidGains,
    model: &PlantModel,
    plant: &DiscreteStateSpace,
    method: Discretization,
    omega_gc: f64,
) -> Result<Achieved, DesignError> {
    let ts = plant.ts_s;
    let m = margins(
        |w| discrete_response(gains, ts, method, w) * plant.response(w),
        &sweep_for(omega_gc, model, gains, Some(ts)),
    );
    finish(
        "discrete",
        model.name(),
        m,
        ClosedLoop::discrete(plant, gains, method),
        omega_gc,
    )
}

fn finish(
    name: &'static str,
    plant: &'static str,
    m: Margins,
    cl: ClosedLoop,
    omega_gc: f64,
) -> Result<Achieved, DesignError> {
    let poles = cl.poles();
    let stability = super::closed_loop::classify(&poles, cl.ts_s.is_some());
    let (step, response) = if stability == Stability::Stable {
        step_of(&cl, &poles, omega_gc)
    } else {
        (
            None,
            StepResponse {
                time_s: Vec::new(),
                y_rad: Vec::new(),
            },
        )
    };
    Ok(Achieved {
        name,
        plant,
        margins: m,
        poles,
        stability,
        step,
        response,
    })
}

/// Designs and verifies.
///
/// A PID for the Table 2 plant at 30 rad/s crossover and 60 deg phase margin (handout eqs.
/// 44-53), verified on the reduced, full and discrete loops:
///
/// ```
/// use servo_core::design::bode::DerivativeFilter;
/// use servo_core::design::controller::Discretization;
/// use servo_core::design::verify::{design, DesignRequest};
/// use servo_core::design::{ControllerKind, LoopSpec, PlantModel};
/// use servo_core::PlantParams;
/// let p = PlantParams::TABLE2;
/// let report = design(&DesignRequest {
///     kind: ControllerKind::Pid,
///     spec: LoopSpec { omega_gc: 30.0, phase_margin: 60f64.to_radians() },
///     alpha: 4.0,
///     filter: DerivativeFilter::Factor(5.0),
///     ts_s: 1e-3,
///     discretization: Discretization::Tustin,
///     reduced: PlantModel::reduced(&p),
///     full: Some(PlantModel::full(&p)),
///     design_on_full: false,
///     exact: false,
/// })?;
/// assert!(report.gains.kp > 0.0 && report.gains.ki > 0.0 && report.gains.kd > 0.0);
/// assert!((report.reduced.margins.phase_margin_deg - 60.0).abs() < 1.0);
/// # Ok::<(), servo_core::design::DesignError>(())
/// ```
pub fn design(req: &DesignRequest) -> Result<DesignReport, DesignError> {
    req.spec.validate()?;
    if !(req.ts_s.is_finite() && req.ts_s > 0.0) {
        return Err(DesignError::OutOfRange {
            name: "--ts [s]",
            value: req.ts_s,
            why: "the sample period must be > 0",
        });
    }
    if req.spec.omega_gc * req.ts_s >= 0.5 * math::PI {
        return Err(DesignError::OutOfRange {
            name: "w_gc [rad/s]",
            value: req.spec.omega_gc,
            why: "the crossover must stay well below the Nyquist frequency pi/T_s (w_gc T_s < pi/2); \
                  lower --wc or shorten --ts",
        });
    }
    let design_model = match (req.design_on_full, req.full) {
        (true, Some(f)) => f,
        (true, None) => {
            return Err(DesignError::Invalid(
                "designing on the full model needs the plant parameters, not just k_m and T_m",
            ))
        }
        (false, _) => req.reduced,
    };
    let w = req.spec.omega_gc;
    let tl_s = if req.kind == ControllerKind::Pi {
        0.0
    } else {
        req.filter.tl_s(w)?
    };
    let handout_gains = synthesize(
        req.kind,
        &req.spec,
        req.alpha,
        design_model.response(w),
        tl_s,
    )?;
    let discrete_model = req.full.unwrap_or(req.reduced);
    let discrete_plant = discrete_model.state_space().discretize_zoh(req.ts_s);
    let gains = if req.exact {
        super::exact::solve(
            req.kind,
            &req.spec,
            req.alpha,
            tl_s,
            &discrete_plant,
            req.discretization,
            &handout_gains,
        )?
    } else {
        handout_gains
    };
    let reduced = verify_continuous(&gains, &req.reduced, w)?;
    let full = match req.full {
        Some(f) => Some(verify_continuous(&gains, &f, w)?),
        None => None,
    };
    let discrete = verify_discrete(
        &gains,
        &discrete_model,
        &discrete_plant,
        req.discretization,
        w,
    )?;
    if req.exact {
        let m = &discrete.margins;
        let (dw, dpm) = (
            (m.omega_gc - w).abs() / w,
            (m.phase_margin_deg - super::deg(req.spec.phase_margin)).abs(),
        );
        if !(dw <= 0.005 && dpm <= 0.1) {
            return Err(DesignError::NoSolution(
                "--exact: the gains put |L| = 1 at w_gc, but the loop has another gain crossover with a smaller phase \
                 margin; choose a lower w_gc or phase margin",
            ));
        }
    }
    Ok(DesignReport {
        request: *req,
        handout_gains,
        gains,
        reduced,
        full,
        discrete,
        discrete_plant,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::{c_abs, c_arg, deg, rad};
    use crate::params::PlantParams;

    fn request(w: f64, pm: f64, exact: bool) -> DesignRequest {
        let p = PlantParams::TABLE2;
        DesignRequest {
            kind: ControllerKind::Pid,
            spec: LoopSpec {
                omega_gc: w,
                phase_margin: rad(pm),
            },
            alpha: 4.0,
            filter: DerivativeFilter::Factor(5.0),
            ts_s: 1e-3,
            discretization: Discretization::Tustin,
            reduced: PlantModel::reduced(&p),
            full: Some(PlantModel::full(&p)),
            design_on_full: false,
            exact,
        }
    }

    /// Brute-force measurement of the discrete loop: dense linear sweep for |L| = 1, phase there.
    fn brute_force_discrete(r: &DesignReport) -> (f64, f64) {
        let mut best = (f64::NAN, f64::NAN);
        let n = 400_000;
        let (lo, hi) = (1.0, 300.0);
        let mut prev = f64::NAN;
        for k in 0..=n {
            let w = lo + (hi - lo) * k as f64 / n as f64;
            let l = r.loop_response("discrete", w).unwrap();
            let g = c_abs(l) - 1.0;
            if prev > 0.0 && g <= 0.0 {
                best = (w, 180.0 + deg(c_arg(l)));
            }
            prev = g;
        }
        best
    }

    #[test]
    fn handout_design_falls_short_and_exact_fixes_it() {
        let r = design(&request(30.0, 60.0, false)).unwrap();
        assert_eq!(r.gains, r.handout_gains);
        // The real derivative and the ZOH delay eat phase: the achieved margin is below the spec.
        assert!(
            r.discrete.margins.phase_margin_deg < 59.0,
            "{:?}",
            r.discrete.margins
        );
        assert!(r.reduced.margins.phase_margin_deg < 60.0);
        assert_eq!(r.discrete.stability, Stability::Stable);
        let e = design(&request(30.0, 60.0, true)).unwrap();
        let (wc, pm) = brute_force_discrete(&e);
        assert!((wc - 30.0).abs() / 30.0 < 0.005, "achieved w_gc {wc}");
        assert!((pm - 60.0).abs() < 0.1, "achieved pm {pm}");
    }

    #[test]
    fn exact_for_several_specs_and_structures() {
        for (w, pm, kind) in [
            (15.0, 45.0, ControllerKind::Pid),
            (50.0, 65.0, ControllerKind::Pid),
            (20.0, 70.0, ControllerKind::Pd),
            (8.0, 45.0, ControllerKind::Pi),
        ] {
            let mut q = request(w, pm, true);
            q.kind = kind;
            q.discretization = Discretization::BackwardEuler;
            let e = design(&q).unwrap();
            let (wc, pmx) = brute_force_discrete(&e);
            assert!((wc - w).abs() / w < 0.005, "{kind:?} w {w}: {wc}");
            assert!((pmx - pm).abs() < 0.1, "{kind:?} pm {pm}: {pmx}");
        }
    }

    /// The discrete loop analysed here is the loop `servo run` closes: the real `control::Pid`
    /// driving the ZOH plant gives the same step response (reference stepped at k = 1, because the
    /// Pid primes its derivative history on its first sample).
    #[test]
    fn discrete_loop_matches_the_running_pid() {
        use crate::control::pid::{Pid, PidConfig};
        for method in [Discretization::BackwardEuler, Discretization::Tustin] {
            let mut q = request(30.0, 60.0, false);
            q.discretization = method;
            let r = design(&q).unwrap();
            let plant = &r.discrete_plant;
            let mut cfg = PidConfig::new(r.gains, plant.ts_s);
            cfg.discretization = method;
            let mut pid = Pid::new(cfg).unwrap();
            let mut x = nalgebra::DVector::<f64>::zeros(plant.phi.nrows());
            let y_ref = &r.discrete.response.y_rad;
            let mut worst = 0.0f64;
            for k in 0..400 {
                let y = plant.c.dot(&x);
                if k >= 1 {
                    worst = worst.max((y - y_ref[k - 1]).abs());
                }
                let u = pid.update(if k >= 1 { 1.0 } else { 0.0 }, y, 0.0).u_v;
                x = &plant.phi * &x + &plant.gamma * u;
            }
            assert!(worst < 1e-9, "{method:?}: max deviation {worst}");
        }
    }

    #[test]
    fn step_metrics_plausible() {
        let r = design(&request(30.0, 60.0, false)).unwrap();
        let s = r.reduced.step.unwrap();
        // PID zeros add overshoot beyond the second-order estimate; rise ~ 1.8 / w_gc within 2x
        assert!(s.overshoot_pct > 5.0 && s.overshoot_pct < 40.0, "{s:?}");
        let tr = s.rise_time_s.unwrap();
        assert!(tr > 0.5 * 1.8 / 30.0 && tr < 2.0 * 1.8 / 30.0, "{tr}");
        assert!(s.settling_time_1pct_s.unwrap() >= s.settling_time_5pct_s.unwrap());
    }
}
