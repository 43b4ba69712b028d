//! `--meet-specs`: a search over the design's free parameters for a controller whose step
//! responses on the loop that runs (discrete PID with derivative filter, ZOH plant, voltage limit,
//! back-calculation anti-windup; see [`super::step_range`]) meet an overshoot and a settling (or
//! rise) time spec for every step size of a range.
//!
//! # Free parameters
//! The Bode design's w_gc and phase margin (eqs. 43-50; the handout's translation, eqs. 36-41,
//! is only the starting point), alpha = T_I/T_D, the derivative filter 1/T_L = f w_gc (eq. 53),
//! the derivative input (error or measurement) and the anti-windup gain K_w. The gains follow
//! from the handout's synthesis on the design model, so the integral action stays (K_I > 0).
//!
//! # Method
//! The figure of merit of a candidate is J, the worst ratio over the step sizes of achieved to
//! specified figure (overshoot / spec, settling time / spec): the specs are met when J <= 1.
//! Candidates are ranked first by J down to [`TARGET_RATIO`] (a margin inside the spec box for
//! model error), then, among those inside it, by the controller's noise gain |C(e^{j pi})|
//! (so the search does not return the fastest loop that meets the specs, which would amplify
//! encoder quantisation and noise, but the quietest). A coarse grid over the box of parameters
//! (for each derivative input) seeds a compass search (pattern search with step halving, robust
//! to the kinks of a max and of settling times) from the best few seeds. The search simulates
//! three step sizes (the ends and the middle of the range); the winner is then checked on a dense
//! grid of [`DENSE_STEPS`] sizes with a longer horizon, and when some size in between is worse it
//! joins the search set and the search resumes. The result meets the specs when J <= 1 on the
//! dense check; otherwise it is the design with the smallest J, whose worst (overshoot,
//! settling) pair is the closest achievable one in that sense.

// Small dense loops read best with explicit indices.
#![allow(clippy::needless_range_loop)]

use super::bode::{synthesize, ControllerKind, DerivativeFilter, PidGains};
use super::controller::{discrete_response, ControllerRealisation, Discretization};
use super::step_range::{
    check_report, check_steps, FastPlant, LoopStructure, RangeCheck, TimeSpecs,
};
use super::verify::{design, DesignReport, DesignRequest};
use super::{c_expj, rad, Complex, DesignError, LoopSpec};
use crate::control::pid::DerivativeOn;
use crate::math;
use alloc::vec::Vec;

/// Step sizes of the final (dense) check.
pub const DENSE_STEPS: usize = super::step_range::CHECK_STEPS;

/// The search first aims this far inside the specs (worst achieved / specified figure), then
/// lowers the controller's noise gain while staying there.
pub const TARGET_RATIO: f64 = 0.9;

/// Largest sensitivity peak Ms = max |1/(1 + L)| allowed (6 dB: gain margin >= 6 dB and phase
/// margin >= 29 deg); a robustness constraint of the search.
pub const MS_MAX: f64 = 2.0;

/// Frequencies of the sensitivity check.
const SENSITIVITY_POINTS: usize = 240;

/// Noise gain of the discrete controller |C(z = -1)| [V/rad]: the output change per unit of
/// alternating measurement noise (K_P plus the filtered derivative's high-frequency gain).
pub fn noise_gain(g: &PidGains, ts_s: f64, method: Discretization) -> f64 {
    super::c_abs(discrete_response(
        g,
        ts_s,
        method,
        0.999_999 * math::PI / ts_s,
    ))
}

/// A point of the search space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FreeParams {
    /// Design crossover w_gc [rad/s].
    pub omega_gc: f64,
    /// Design phase margin [rad].
    pub phase_margin: f64,
    /// T_I / T_D [-] (PID).
    pub alpha: f64,
    /// 1/T_L = tl_factor w_gc [-] (PID).
    pub tl_factor: f64,
    /// Derivative input.
    pub derivative_on: DerivativeOn,
    /// Back-calculation anti-windup gain K_w [1/s].
    pub kw_per_s: f64,
}

/// What to search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeetRequest {
    /// Structure (PID or PI), plant models, T_s, discretisation; its spec, alpha and filter are
    /// the starting point (the translation of the time specs). `exact` is ignored.
    pub base: DesignRequest,
    /// Overshoot and speed specs and the step range; both an overshoot and a speed spec are
    /// required.
    pub specs: TimeSpecs,
    /// Symmetric voltage limit [V].
    pub u_limit_v: f64,
    /// The derivative input asked for (the search may switch it when that is needed).
    pub derivative_on: DerivativeOn,
}

/// The outcome of the search.
#[derive(Debug, Clone, PartialEq)]
pub struct MeetResult {
    /// Whether every step size of the range meets both specs (on the dense check).
    pub feasible: bool,
    pub params: FreeParams,
    pub structure: LoopStructure,
    /// The design at the found parameters, verified (margins, poles) as `servo design` does.
    pub report: DesignReport,
    /// The dense check of the step range at the found gains.
    pub check: RangeCheck,
    /// Sensitivity peak Ms = max |1/(1 + L)| of the discrete loop at the found gains [-].
    pub sensitivity_peak: f64,
    /// Number of candidate designs simulated.
    pub evaluations: usize,
}

/// Bounds of the search box, relative to the translated w_gc.
#[derive(Debug, Clone, Copy)]
struct Box5 {
    lo: [f64; 5],
    hi: [f64; 5],
    /// Active dimensions (PI: w_gc, PM, K_w).
    active: [bool; 5],
}

/// Candidate in unit coordinates u in [0, 1]^5: (ln w_gc, PM deg, ln alpha, ln f, ln K_w).
type Unit = [f64; 5];

struct Search<'a> {
    req: &'a MeetRequest,
    plant: FastPlant,
    design_model: super::PlantModel,
    bx: Box5,
    /// The handout's design (the translation, the user's alpha and T_L) in unit coordinates.
    nominal: Unit,
    /// (z, P(z)) on a log grid of frequencies up to Nyquist, for the sensitivity peak.
    grid: Vec<(Complex<f64>, Complex<f64>)>,
    steps: Vec<f64>,
    horizon_s: f64,
    evaluations: usize,
}

impl Search<'_> {
    fn params(&self, u: &Unit, d: DerivativeOn) -> FreeParams {
        let v = |i: usize| self.bx.lo[i] + (self.bx.hi[i] - self.bx.lo[i]) * u[i].clamp(0.0, 1.0);
        FreeParams {
            omega_gc: math::exp(v(0)),
            phase_margin: rad(v(1)),
            alpha: math::exp(v(2)),
            tl_factor: math::exp(v(3)),
            derivative_on: d,
            kw_per_s: math::exp(v(4)),
        }
    }

    fn gains(&self, p: &FreeParams) -> Option<PidGains> {
        let spec = LoopSpec {
            omega_gc: p.omega_gc,
            phase_margin: p.phase_margin,
        };
        let tl_s = match self.req.base.kind {
            ControllerKind::Pi => 0.0,
            _ => 1.0 / (p.tl_factor * p.omega_gc),
        };
        let g = synthesize(
            self.req.base.kind,
            &spec,
            p.alpha,
            self.design_model.response(p.omega_gc),
            tl_s,
        )
        .ok()?;
        (g.kp > 0.0 && g.ki > 0.0 && g.kd >= 0.0).then_some(g)
    }

    fn structure(&self, p: &FreeParams) -> LoopStructure {
        LoopStructure {
            derivative_on: p.derivative_on,
            kw_per_s: Some(p.kw_per_s),
            u_limit_v: self.req.u_limit_v,
            discretization: self.req.base.discretization,
        }
    }

    /// The ranking of a candidate (lower is better; infinite when not designable or diverging):
    /// `1 + J` while the worst spec ratio J over the search step sizes exceeds [`TARGET_RATIO`],
    /// else `d / (1 + d)` < 1 with d the distance from the handout's design.
    fn cost(&mut self, u: &Unit, d: DerivativeOn) -> f64 {
        self.evaluations += 1;
        let p = self.params(u, d);
        let Some(g) = self.gains(&p) else {
            return f64::INFINITY;
        };
        let j = match check_steps(
            &self.plant,
            &g,
            &self.structure(&p),
            &self.req.specs,
            &self.steps,
            self.horizon_s,
        ) {
            Ok(c) => c.worst_ratio,
            Err(_) => return f64::INFINITY,
        };
        let ms = self.sensitivity_peak(&g);
        if ms.is_nan() || ms > MS_MAX {
            return 100.0 + ms.min(1e6);
        }
        if j > TARGET_RATIO {
            return 1.0 + j.min(98.0);
        }
        let dist = self.distance(u, d);
        dist / (1.0 + dist)
    }

    /// Peak of |1 / (1 + C P)| on the discrete loop over the precomputed frequency grid.
    fn sensitivity_peak(&self, g: &PidGains) -> f64 {
        let c = ControllerRealisation::discrete(g, self.plant.ts_s(), self.req.base.discretization);
        self.grid
            .iter()
            .map(|(z, p)| 1.0 / super::c_abs(Complex::new(1.0, 0.0) + c.eval(*z) * p))
            .fold(0.0, f64::max)
    }

    /// How far a candidate is from the handout's design (unit-box distance over w_gc, PM, alpha
    /// and T_L, plus 0.25 for the other derivative input; K_w is free).
    fn distance(&self, u: &Unit, d: DerivativeOn) -> f64 {
        let mut s = 0.0;
        for i in 0..4 {
            if self.bx.active[i] {
                let e = u[i] - self.nominal[i];
                s += e * e;
            }
        }
        math::sqrt(s)
            + if d == self.req.derivative_on {
                0.0
            } else {
                0.25
            }
    }

    /// Compass search from `u0` with initial step `h0` down to `h_min`.
    fn compass(&mut self, mut u: Unit, d: DerivativeOn, mut best: f64, h0: f64) -> (Unit, f64) {
        let mut h = h0;
        while h >= 1.0 / 256.0 {
            let mut improved = false;
            for i in 0..5 {
                if !self.bx.active[i] {
                    continue;
                }
                for sgn in [1.0, -1.0] {
                    let mut v = u;
                    v[i] = (v[i] + sgn * h).clamp(0.0, 1.0);
                    if v[i] == u[i] {
                        continue;
                    }
                    let c = self.cost(&v, d);
                    if c < best {
                        best = c;
                        u = v;
                        improved = true;
                        break;
                    }
                }
            }
            if !improved {
                h *= 0.5;
            }
        }
        (u, best)
    }
}

/// Searches the free parameters; see the module documentation.
pub fn meet_specs(req: &MeetRequest) -> Result<MeetResult, DesignError> {
    req.specs.validate()?;
    if req.specs.overshoot_max.is_none() || req.specs.speed.is_none() {
        return Err(DesignError::Invalid(
            "--meet-specs needs an overshoot spec and a settling or rise time spec",
        ));
    }
    if req.base.kind == ControllerKind::Pd {
        return Err(DesignError::Invalid(
            "--meet-specs keeps the integral action (K_I > 0): use --controller pid or pi, not pd",
        ));
    }
    if req.u_limit_v.is_nan() || req.u_limit_v <= 0.0 {
        return Err(DesignError::OutOfRange {
            name: "--u-limit [V]",
            value: req.u_limit_v,
            why: "the voltage limit must be > 0 V",
        });
    }
    let base = &req.base;
    if !(base.ts_s.is_finite() && base.ts_s > 0.0) {
        return Err(DesignError::OutOfRange {
            name: "--ts [s]",
            value: base.ts_s,
            why: "the sample period must be > 0",
        });
    }
    let w0 = base.spec.omega_gc;
    let design_model = match (base.design_on_full, base.full) {
        (true, Some(f)) => f,
        _ => base.reduced,
    };
    let plant_model = base.full.unwrap_or(base.reduced);
    let dplant = plant_model.state_space().discretize_zoh(base.ts_s);
    let plant = FastPlant::new(&dplant)?;
    // Crossover at most 0.3 / T_s (a decade below Nyquist) and within [0.3, 4] x the translation.
    let w_hi = (4.0 * w0).min(0.3 / base.ts_s);
    let w_lo = (0.3 * w0).min(0.5 * w_hi);
    let pi = base.kind == ControllerKind::Pi;
    let bx = Box5 {
        lo: [
            math::ln(w_lo),
            25.0,
            math::ln(2.0),
            math::ln(2.0),
            math::ln(0.5),
        ],
        hi: [
            math::ln(w_hi),
            85.0,
            math::ln(16.0),
            math::ln(10.0),
            math::ln(2000.0),
        ],
        active: [true, true, !pi, !pi, true],
    };
    let specs = req.specs;
    let mid = 0.5 * (specs.step_min_rad + specs.step_max_rad);
    let mut steps = alloc::vec![specs.step_min_rad];
    for s in [mid, specs.step_max_rad] {
        if s > steps[steps.len() - 1] {
            steps.push(s);
        }
    }
    let unit = |i: usize, v: f64| ((v - bx.lo[i]) / (bx.hi[i] - bx.lo[i])).clamp(0.0, 1.0);
    let f0 = match base.filter {
        DerivativeFilter::Factor(f) => f,
        DerivativeFilter::TimeConstant(t) => 1.0 / (t * w0),
    };
    let nominal = [
        unit(0, math::ln(w0)),
        unit(1, super::deg(base.spec.phase_margin)),
        unit(2, math::ln(base.alpha)),
        unit(3, math::ln(f0)),
        0.5,
    ];
    let (g_lo, g_hi) = (0.05 * w_lo, 0.999 * math::PI / base.ts_s);
    let grid = (0..SENSITIVITY_POINTS)
        .map(|k| {
            let w = g_lo
                * math::exp(math::ln(g_hi / g_lo) * k as f64 / (SENSITIVITY_POINTS - 1) as f64);
            let z = c_expj(w * base.ts_s);
            (z, dplant.eval(z))
        })
        .collect();
    let mut search = Search {
        req,
        plant,
        design_model,
        bx,
        nominal,
        grid,
        steps,
        horizon_s: specs.horizon_s(w0, 3.0, 0.0),
        evaluations: 0,
    };
    let inputs: &[DerivativeOn] = if pi {
        &[DerivativeOn::Error]
    } else {
        &[DerivativeOn::Error, DerivativeOn::Measurement]
    };

    // Coarse grid.
    let g0 = [0.1, 0.3, 0.5, 0.7, 0.9];
    let g1 = [0.2, 0.45, 0.7, 0.9];
    let g2: &[f64] = if pi { &[0.5] } else { &[0.1, 0.35, 0.6, 0.85] };
    let g3: &[f64] = if pi { &[0.5] } else { &[0.2, 0.6] };
    let g4 = [0.15, 0.5, 0.85];
    let mut seeds: Vec<(f64, Unit, DerivativeOn)> = Vec::new();
    for &d in inputs {
        let j = search.cost(&nominal, d);
        if j.is_finite() {
            seeds.push((j, nominal, d));
        }
        for &a in &g0 {
            for &b in &g1 {
                for &c in g2 {
                    for &e in g3 {
                        for &k in &g4 {
                            let u = [a, b, c, e, k];
                            let j = search.cost(&u, d);
                            if j.is_finite() {
                                seeds.push((j, u, d));
                            }
                        }
                    }
                }
            }
        }
    }
    if seeds.is_empty() {
        return Err(DesignError::NoSolution(
            "--meet-specs: no stable design in the search box (w_gc, phase margin, alpha, T_L, K_w); \
             check the plant parameters and T_s",
        ));
    }
    seeds.sort_by(|a, b| a.0.total_cmp(&b.0));

    // Compass search from the best seeds (at least one per derivative input when available).
    let mut starts: Vec<(f64, Unit, DerivativeOn)> = seeds.iter().take(4).copied().collect();
    for &d in inputs {
        if !starts.iter().any(|s| s.2 == d) {
            if let Some(s) = seeds.iter().find(|s| s.2 == d) {
                starts.push(*s);
            }
        }
    }
    let mut best = starts[0];
    for &(j, u, d) in &starts {
        let (u, j) = search.compass(u, d, j, 0.1);
        if j < best.0 {
            best = (j, u, d);
        }
    }

    // Dense check; a worse step size joins the search set (at most twice).
    let mut rounds = 0;
    let result = loop {
        let p = search.params(&best.1, best.2);
        let g = search
            .gains(&p)
            .ok_or(DesignError::NoSolution("--meet-specs: lost the design"))?;
        let structure = search.structure(&p);
        let dense = check_steps(
            &search.plant,
            &g,
            &structure,
            &specs,
            &specs.grid(DENSE_STEPS),
            specs.horizon_s(p.omega_gc, 10.0, 1.0),
        )?;
        // the worst ratio the search saw at this design (its rank is 1 + J above the target)
        let searched = if best.0 >= 1.0 {
            best.0 - 1.0
        } else {
            TARGET_RATIO
        };
        if dense.worst_ratio <= searched + 1e-3 || rounds >= 2 {
            break (p, g, structure, dense);
        }
        rounds += 1;
        if let Some(worst) = dense
            .outcomes
            .iter()
            .map(|o| {
                let (a, b) = super::step_range::spec_ratios(o, &specs);
                (a.max(b), o.step_rad)
            })
            .max_by(|a, b| a.0.total_cmp(&b.0))
        {
            search.steps.push(worst.1);
        }
        let j = search.cost(&best.1, best.2);
        let (u, j) = search.compass(best.1, best.2, j, 0.05);
        best = (j, u, best.2);
    };
    let (p, g, structure, _) = result;
    let mut request = *base;
    request.spec = LoopSpec {
        omega_gc: p.omega_gc,
        phase_margin: p.phase_margin,
    };
    request.alpha = p.alpha;
    request.filter = DerivativeFilter::Factor(p.tl_factor);
    request.exact = false;
    let report = design(&request)?;
    // the same check `servo design` prints for any design (identical to the dense check above)
    let check = check_report(&report, &structure, &specs)?;
    Ok(MeetResult {
        feasible: check.met(),
        params: p,
        structure,
        report,
        check,
        sensitivity_peak: search.sensitivity_peak(&g),
        evaluations: search.evaluations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::spec::{translate, DampingSpec, SpeedSpec};
    use crate::design::step_range::SpeedTarget;
    use crate::design::PlantModel;
    use crate::params::PlantParams;

    fn request(mp: f64, ts: f64) -> MeetRequest {
        let p = PlantParams::TABLE2;
        let t = translate(DampingSpec::Overshoot(mp), SpeedSpec::Settling5(ts)).unwrap();
        MeetRequest {
            base: DesignRequest {
                kind: ControllerKind::Pid,
                spec: t.spec,
                alpha: 4.0,
                filter: DerivativeFilter::Factor(5.0),
                ts_s: 1e-3,
                discretization: Discretization::BackwardEuler,
                reduced: PlantModel::reduced(&p),
                full: Some(PlantModel::full(&p)),
                design_on_full: false,
                exact: false,
            },
            specs: TimeSpecs {
                overshoot_max: Some(mp),
                speed: Some(SpeedTarget::Settling {
                    band: 0.05,
                    time_s: ts,
                }),
                step_min_rad: 0.2,
                step_max_rad: 1.0,
            },
            u_limit_v: 10.0,
            derivative_on: DerivativeOn::Error,
        }
    }

    #[test]
    fn meets_the_issue_example() {
        let r = meet_specs(&request(0.1, 0.15)).unwrap();
        assert!(r.feasible, "{:?} {:?}", r.params, r.check);
        assert!(r.report.gains.ki > 0.0);
        assert!(r.check.worst_overshoot_pct <= 10.0);
        assert!(r.check.worst_speed_s.unwrap() <= 0.15);
    }

    #[test]
    fn impossible_specs_are_infeasible_with_a_closest_pair() {
        // 1 % overshoot and 5 % settling in 20 ms for a 1 rad step at 10 V: the motor cannot even
        // reach 0.95 rad in that time (no-load speed ~ 10 V x 5.6 rad/(V s)).
        let r = meet_specs(&request(0.01, 0.02)).unwrap();
        assert!(!r.feasible);
        assert!(r.check.worst_ratio > 1.0);
        let s = r.check.worst_speed_s.unwrap_or(f64::INFINITY);
        assert!(s > 0.02, "{s}");
    }
}
