//! The simulation cost a joint model is tuned on: the trimmed output error over long fit
//! segments ([`Tuner`]), and the parameters tuned on it ([`Target`]). Used by the base fit (which
//! model predicts the motion better, [`motion_costs`]) and the backward elimination
//! ([`super::backward`]).

use super::kinds::on_simulation;
use crate::effects::{EffectKind, SearchScale, Span};
use crate::fit::oe::{self, Part};
use crate::fit::{search, set_effect, Dataset};
use crate::math;
use crate::plant::Plant;
use alloc::vec::Vec;

/// Horizon of the segments the joint model is tuned on [s]: long enough to hold several
/// reversals (a gap shows as an offset after each one, blurred on short segments started from
/// an uncertain contact state).
pub(super) const LONG_HORIZON_S: f64 = 0.75;
/// Grid points per parameter of the coarse two-parameter grid.
pub(super) const GRID_POINTS: usize = 6;
/// Share of the segments the tuning cost leaves out, the worst ones ([`trimmed`]).
pub(super) const TRIM: f64 = 0.2;
/// Starts of the joint refinement (the best grid points).
pub(super) const STARTS: usize = 3;
/// Golden-section steps after each coordinate's five-point grid in [`Tuner::refine`]: the
/// bracket (two grid intervals) shrinks to 0.15 of itself, 0.3 of a grid interval, a few per
/// cent of a parameter on the first pass (a gap, on a grid of 1.5^(1/2) steps: to about 3 %) and
/// half that on the second, finer than a gap varies with the noise of the logs (0.028-0.033 rad
/// for 0.030 over the three seeds of the three-effect test). Eight steps (0.02 of the bracket)
/// cost a third more simulations per coordinate and, on the Padova logs, ended in the same
/// verdict: 15.7 s against 12.6 s on the PID step logs.
pub(super) const GOLDEN_STEPS: usize = 4;
/// At most this many long segments (spread over the logs) for the joint fit (a play's own
/// refinement uses 90; each evaluation here is one of several hundred).
pub(super) const MAX_SEGMENTS: usize = 45;

/// A parameter tuned on the simulation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Target {
    Effect(EffectKind, &'static str),
    JEq,
    TauSf,
    /// The armature resistance: sized in the electrical balance before the delay (or a play)
    /// was in the model, it sets the torque a voltage produces in the simulation.
    RA,
    BEq,
}

pub(super) fn get(p: &Plant, t: Target) -> Option<f64> {
    match t {
        Target::Effect(k, key) => p.effects.value(k, key),
        Target::JEq => Some(p.params.j_eq()),
        Target::TauSf => Some(p.tau_sf()),
        Target::RA => Some(p.params.r_a),
        Target::BEq => Some(p.params.b_eq()),
    }
}

pub(super) fn with(p: &Plant, t: Target, x: f64) -> Option<Plant> {
    let mut q = *p;
    match t {
        Target::Effect(k, key) => q.effects.get_mut(k)?.set(key, x).ok()?,
        Target::JEq => q.params.j_eq = Some(x),
        Target::RA => q.params.r_a = x,
        Target::BEq => q.params.b_eq = Some(x),
        Target::TauSf => {
            q.params.tau_sf = Some(x);
            if q.effects.contains(EffectKind::Coulomb) {
                set_effect(&mut q, EffectKind::Coulomb, &[x]).ok()?;
            }
        }
    }
    Some(q)
}

/// The parameters of `p` tuned on the simulation, with how far they may move in the first
/// pass: those of the members judged on the simulation (no balance sees them: a gear play's
/// gap), those the other members declare sensitive in the motion
/// ([`crate::effects::EffectModel::polish`]: a breakaway's level and speed scale), J_eq and the
/// Coulomb level. The rest keep their equation-error values (a delay, which the electrical
/// balance resolves far more sharply than the motion does, is refitted there with the others in
/// the model, see [`search`]).
pub(super) fn targets(p: &Plant, members: &[EffectKind]) -> Vec<(Target, Span)> {
    let mut out = Vec::new();
    for &k in members {
        if !p.effects.contains(k) {
            continue;
        }
        if on_simulation(k) {
            for spec in k.params() {
                if k.model().fittable(spec.key) {
                    out.push((Target::Effect(k, spec.key), Span::Scale(1.5)));
                }
            }
        } else {
            for &(key, span) in k.model().polish() {
                out.push((Target::Effect(k, key), span));
            }
            // Its other searched parameters (a delay sized in the electrical balance to a
            // fraction of a sample only by the motion), within 40 %.
            for spec in k.params() {
                let searched = spec.nonlinear
                    && k.model().fittable(spec.key)
                    && k.model().search(spec.key).scale != SearchScale::Integer;
                if searched && !out.iter().any(|(t, _)| *t == Target::Effect(k, spec.key)) {
                    out.push((Target::Effect(k, spec.key), Span::Scale(1.4)));
                }
            }
        }
    }
    out.push((Target::JEq, Span::Scale(1.15)));
    // The armature resistance and the viscous coefficient, sized in their balances before the
    // members were in the model (a missing delay biases the electrical balance, a play the
    // torque balance): each sets the torque a voltage produces and the speed it holds.
    out.push((Target::RA, Span::Scale(1.05)));
    out.push((Target::BEq, Span::Scale(1.3)));
    if p.effects.contains(EffectKind::Coulomb) {
        out.push((Target::TauSf, Span::Scale(1.1)));
    }
    // The base first: a member tuned before it bends to absorb the base's bias (a play wider
    // and a breakaway broader for an inertia 3 % light and a resistance 1.5 % high).
    out.reverse();
    out
}

/// The simulation cost of the fit blocks over long segments.
pub(super) struct Tuner<'a> {
    ds: &'a Dataset,
    segs: Vec<(usize, usize)>,
    horizon_s: f64,
}

impl<'a> Tuner<'a> {
    /// The tuner over the long fit segments of `ds` ([`LONG_HORIZON_S`], at most
    /// [`MAX_SEGMENTS`]).
    pub(super) fn new(ds: &'a Dataset) -> Self {
        let horizon_s = LONG_HORIZON_S.max(ds.opts.oe_horizon_s);
        Tuner {
            ds,
            segs: oe::segments_with(ds, Part::Fit, horizon_s, 3, MAX_SEGMENTS),
            horizon_s,
        }
    }

    /// The trimmed simulation cost of `p` ([`trimmed`], [`TRIM`]) [rad].
    pub(super) fn cost(&self, p: &Plant) -> f64 {
        trimmed(self.ds, p, &self.segs, self.horizon_s, TRIM).unwrap_or(f64::INFINITY)
    }

    /// [`Self::cost`] simulated with the sub-steps of a search's grid
    /// ([`oe::SEARCH_SUBSTEP_S`]): for the joint search's coarse grid, which only chooses the
    /// starts the refinement then tunes on [`Self::cost`].
    pub(super) fn grid_cost(&self, p: &Plant) -> f64 {
        oe::segment_costs_stepped(self.ds, p, &self.segs, self.horizon_s, oe::SEARCH_SUBSTEP_S)
            .map_or(f64::INFINITY, |c| trimmed_of(c, TRIM))
    }

    /// How many segments the trimmed cost keeps.
    pub(super) fn kept(&self) -> usize {
        kept(self.segs.len(), TRIM)
    }

    /// Coordinate refinement of `ts` from `p`, `passes` times: per parameter a grid over its
    /// span (narrowed by `shrink` at each pass; a scale on a log axis) then a golden-section
    /// search, a change kept only when it lowers the cost.
    pub(super) fn refine(&self, p: &Plant, ts: &[(Target, Span)], passes: &[f64]) -> (Plant, f64) {
        let mut best = *p;
        let mut c_best = self.cost(&best);
        for &shrink in passes {
            for &(t, span) in ts {
                let Some(x0) = get(&best, t) else { continue };
                if !x0.is_finite() {
                    continue;
                }
                // Search coordinates: ln x for a scale, x for an additive span.
                let (grid, to_x): (Vec<f64>, fn(f64) -> f64) = match span {
                    Span::Scale(f) if x0 > 0.0 => {
                        let d = shrink * math::ln(f);
                        let l0 = math::ln(x0);
                        (search::linspace(l0 - d, l0 + d, 5), math::exp)
                    }
                    Span::Add(d) => {
                        let d = shrink * d;
                        (search::linspace(x0 - d, x0 + d, 5), |x| x)
                    }
                    Span::Scale(_) => continue,
                };
                let from = best;
                // The middle of the grid is the current value, whose cost is known.
                let here = grid[grid.len() / 2];
                let r = search::grid_then_golden_bounded(
                    &grid,
                    |l, _| {
                        if l == here {
                            return c_best;
                        }
                        with(&from, t, to_x(l)).map_or(f64::INFINITY, |q| self.cost(&q))
                    },
                    GOLDEN_STEPS,
                );
                if let Some((l, c)) = r {
                    if c < c_best {
                        if let Some(q) = with(&from, t, to_x(l)) {
                            best = q;
                            c_best = c;
                        }
                    }
                }
            }
        }
        (best, c_best)
    }
}

/// The trimmed simulation cost [rad]: the RMS error over the segments but the worst `trim`
/// share of them (a least-trimmed-squares cost).
///
/// With a gear play and a breakaway friction, a few segments cannot be predicted whatever the
/// parameters: their start state is fixed by no measurement (the motor somewhere inside the gap,
/// the load stuck or slipping near a set point, where the loop hunts). On seed 24 of the
/// three-effect test the true model's plain cost over the long fit segments is 0.33 rad (its
/// held-out cost on short segments 0.06 rad): those few segments carry most of it, and a wrong
/// model (gap 0.049 rad, breakaway speed 1.3 rad/s for 0.03 and 0.5) scores lower (0.32-0.38).
/// Without the worst fifth, the true model scores 0.086 rad against 0.148 for the wrong one.
pub(super) fn trimmed(
    ds: &Dataset,
    p: &Plant,
    segs: &[(usize, usize)],
    horizon_s: f64,
    trim: f64,
) -> Option<f64> {
    Some(trimmed_of(oe::segment_costs(ds, p, segs, horizon_s)?, trim))
}

/// The trimmed cost [rad] of the segment costs `c` (every segment's).
fn trimmed_of(mut c: Vec<f64>, trim: f64) -> f64 {
    c.sort_by(|a, b| a.total_cmp(b));
    let keep = kept(c.len(), trim);
    let s: f64 = c.iter().take(keep).map(|x| x * x).sum();
    math::sqrt(s / keep.max(1) as f64)
}

/// How many of `n` segments a cost trimmed by `trim` keeps (at least one).
pub(super) fn kept(n: usize, trim: f64) -> usize {
    (libm::ceil(n as f64 * (1.0 - trim)) as usize).clamp(1, n.max(1))
}

/// The cost a joint model is tuned on ([`Tuner`]) of each of `plants`: the trimmed simulation
/// error [rad] over the long fit segments of `ds`. `None` when nothing could be simulated.
pub(super) fn motion_costs<const N: usize>(ds: &Dataset, plants: [&Plant; N]) -> [Option<f64>; N] {
    let tuner = Tuner::new(ds);
    plants.map(|p| Some(tuner.cost(p)).filter(|c| c.is_finite()))
}
