//! Whole-period steps away from events ([`PlantSim::with_coarse_periods`]).
//!
//! The sub-steps of [`PlantSim::step`] exist for the events (a stop, a breakaway, a flank met or
//! left) and for nonlinear torques that change fast. Between events, with only dry friction
//! nonlinear (no angle-dependent or user torque), the linear part is discretised exactly over any
//! length and the friction torque of a body sliding one way changes only with its speed: the
//! first-order hold over a whole period then gives what ten sub-steps give, to the torque's
//! curvature. A coarse period is one exact step (a fractional delay's switch inside it is exact
//! too: the linear part superposes the responses to the two inputs), **accepted only when
//! nothing could have happened inside it**:
//!
//! - the friction body slides at both ends in its direction, with a speed larger than the
//!   period's speed change (it cannot have stopped and restarted in between); or it is stuck,
//!   and the torque driving it stays [`COARSE_EVENT_MARGIN`] below breakaway both ways along
//!   the cubic through its values and rates at both ends (with play, the contact's; without,
//!   the motor's through its armature current), so that no breakaway can fall inside (the
//!   load held while the motor crosses the gap or presses on a flank: most of the periods of
//!   closed-loop step logs);
//! - the contact state (free or pressed on a flank) is the same at both ends and, along the cubic
//!   through the motor's place in the gap and its rate at both ends, in between: pressed, the
//!   contact force stays positive with a margin ([`COARSE_EVENT_MARGIN`]), on a contact whose
//!   own oscillation is slow against the period ([`COARSE_MAX_CONTACT_PHASE`]); free, the motor
//!   stays clear of both flanks with that margin;
//! - the nonlinear torques change by at most [`COARSE_MAX_TORQUE_CHANGE`] of the friction's
//!   breakaway level over the period (the steep part of a friction curve is crossed in sub-steps).
//!
//! Otherwise the state is left as it was and the period runs in sub-steps as always. The torques
//! at a coarse period's end start the next one (as a sub-step's start the next sub-step). Every event is
//! therefore still resolved at sub-step resolution; only the stretches between events are
//! stepped whole. Used by the simulations the diagnosis tunes and judges models on
//! ([`crate::fit::oe`]), thousands per diagnosis, where the logs are mostly sliding motion.

use super::{advance, discretise, Disc, Period, PlantSim, CONTACT, NI, NS, STUCK, ZERO_DISC};
use crate::math;

/// Largest change of the nonlinear torques over a coarse period, as a share of the friction's
/// breakaway level [-]. The first-order hold is exact for a torque linear in time; its error
/// grows with the curvature, bounded by the change: at 1 % of the level the error of a period
/// is below 0.1 % of the level.
pub const COARSE_MAX_TORQUE_CHANGE: f64 = 0.01;

/// The discretisation of a whole period per mode, with the delayed input split exactly: the
/// input of the last period acts over the first part (up to the switch), this period's over the
/// rest.
#[derive(Debug, Clone)]
pub(super) struct CoarseTables {
    /// The whole period [mode], its input column the response to this period's input (acting
    /// after the switch).
    disc: [Disc; 4],
    /// The response to the last period's input (acting before the switch) [mode]; zero without
    /// a fractional delay.
    g_old: [[f64; NS]; 4],
    /// Whether a period in contact may be stepped whole: the contact's own oscillation is slow
    /// against the period ([`COARSE_MAX_CONTACT_PHASE`]), so that the cubic through the ends
    /// follows the motion in between.
    contact_whole: bool,
    /// 1 / N [-].
    inv_n: f64,
    /// The largest change of the nonlinear torques over a period [N m, load side], sliding
    /// backwards and forwards ([`COARSE_MAX_TORQUE_CHANGE`] of the breakaway level).
    torque_tol: [f64; 2],
    /// The largest driving torque a stuck friction body may feel inside a coarse period [N m,
    /// load side], backwards and forwards ([`COARSE_EVENT_MARGIN`] below breakaway).
    hold_tol: [f64; 2],
    /// Without play, the rate of the armature current [A/s] per unit of (u_drv [V], i_a [A],
    /// omega_m [rad/s]) (eq. 19), and k_t N [N m/A, load side]: the torque that drives a stuck
    /// rigid drivetrain.
    armature: ([f64; 3], f64),
}

/// Largest phase the contact's natural oscillation turns in one period for a period in contact
/// to be stepped whole [rad]: a quarter of its cycle, where the cubic through the values and
/// rates at both ends of a sine is within 2 % of its amplitude (less than the margin).
pub const COARSE_MAX_CONTACT_PHASE: f64 = 1.5;

/// Margin a contact force (pressed) or the distance to the flanks (free) must keep everywhere
/// inside a coarse period, as a share of the force's larger value at the ends (of the half gap)
/// [-].
pub const COARSE_EVENT_MARGIN: f64 = 0.05;

/// The end of a whole period, which starts the next one: the nonlinear torques there, the gap
/// state ([`gap_state`]) and its contact mode ([`PlantSim::contact_mode`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct Carry {
    torques: (f64, f64),
    gap: (f64, f64),
    mode: (usize, f64),
}

impl PlantSim {
    /// This simulator taking each control period in one exact step whenever no event can happen
    /// inside it (see the module docs of `sim::coarse`), and in sub-steps otherwise. Unchanged
    /// when the plant has an angle-dependent or a user torque (they change along the travel,
    /// not with a slowly varying speed) or takes one step per period anyway.
    pub fn with_coarse_periods(mut self) -> Self {
        let smooth = self.smooth_m.is_active() || self.smooth_l.is_active() || self.custom_torque;
        if self.substeps <= 1 || smooth || self.coarse.is_some() {
            return self;
        }
        // Where the delayed input switches inside the period [share of the period].
        let f = match self.switch_at {
            None => 0.0,
            Some((j, split)) => {
                let r = if split {
                    self.sub_len[1] / self.sub_len[0]
                } else {
                    0.0
                };
                (j as f64 + r) / self.substeps as f64
            }
        };
        let frac = self.play.map_or(0.3, |b| b.contact.load_inertia_fraction);
        let mut t = CoarseTables {
            disc: [ZERO_DISC; 4],
            g_old: [[0.0; NS]; 4],
            contact_whole: false,
            inv_n: 1.0 / self.n,
            torque_tol: [-1.0, 1.0]
                .map(|dir| COARSE_MAX_TORQUE_CHANGE * self.friction.breakaway_l(dir).abs()),
            hold_tol: [-1.0, 1.0]
                .map(|dir| (1.0 - COARSE_EVENT_MARGIN) * self.friction.breakaway_l(dir).abs()),
            armature: {
                let p = &self.plant.params;
                let inv_l = 1.0 / p.l_a;
                ([inv_l, -p.r_eq() * inv_l, -p.k_e * inv_l], p.k_t * self.n)
            },
        };
        if let Some(b) = &self.play {
            // The contact's natural frequency: the spring between the motor (J_eq (1 - f),
            // seen at the load) and the load (J_eq f N^2).
            let (n, j_eq) = (self.n, self.plant.params.j_eq());
            let (j1, j2) = (n * n * j_eq * (1.0 - frac), n * n * j_eq * frac);
            let omega_c = math::sqrt(b.stiffness * (1.0 / j1 + 1.0 / j2));
            t.contact_whole = omega_c * self.dt_s <= COARSE_MAX_CONTACT_PHASE;
        }
        let modes: &[usize] = if self.play.is_some() {
            &[0, STUCK, CONTACT, STUCK | CONTACT]
        } else {
            &[0, STUCK]
        };
        let play = self.play;
        let disc = |mode: usize, len: f64| discretise(&self.plant, frac, play.as_ref(), mode, len);
        for &mode in modes {
            let mut whole = disc(mode, self.dt_s);
            if f > 0.0 {
                // x(dt) = Phi(dt) x0 + Phi((1-f) dt) g_u(f dt) u_old + g_u((1-f) dt) u_new + the
                // torques over the whole period: the linear part is exact for any split.
                let (before, after) =
                    (disc(mode, f * self.dt_s), disc(mode, (1.0 - f) * self.dt_s));
                for i in 0..NS {
                    let mut acc = 0.0;
                    for j in 0..NS {
                        acc += after.phi_t[j][i] * before.g0_t[0][j];
                    }
                    t.g_old[mode][i] = acc;
                    whole.g0_t[0][i] = after.g0_t[0][i];
                }
            }
            t.disc[mode] = whole;
        }
        self.coarse = Some(t);
        self
    }

    /// Steps the period in one piece when nothing can happen inside it; false (state untouched)
    /// otherwise, or when coarse periods are off.
    #[inline]
    pub(super) fn coarse_period(&mut self, period: &Period) -> bool {
        // The torques at the end of the last coarse period, when it was the last thing done.
        let carry = self.coarse_carry.take();
        if self.coarse.is_none() {
            return false;
        }
        let u_old = if self.switch_at.is_some() {
            period.old
        } else {
            0.0
        };
        match self.coarse_step(period.new, u_old, carry) {
            Some(end) => {
                self.coarse_carry = Some(end);
                self.whole_periods += 1;
                true
            }
            None => false,
        }
    }

    /// One exact step over the period with the inputs `u_new` (after the switch) and `u_old`
    /// (before it) [V], kept in `self.x` and returning what its end starts the next period with
    /// ([`Carry`]) when no event can have happened inside it; `None` (state untouched)
    /// otherwise. `carry`: the last period's, when it was stepped whole.
    #[inline]
    fn coarse_step(&mut self, u_new: f64, u_old: f64, carry: Option<Carry>) -> Option<Carry> {
        let x0 = self.x;
        let (inv_n, tol) = {
            let t = self.coarse.as_ref()?;
            (t.inv_n, t.torque_tol[usize::from(self.dir > 0.0)])
        };
        let start = match carry {
            Some(c) => c,
            None => {
                let gap = gap_state(&x0, inv_n);
                Carry {
                    torques: self.nonlinear_torques(&x0),
                    gap,
                    mode: self.contact_mode(gap),
                }
            }
        };
        let (g0, (contact, tau_offset), (tm0, tl0)) = (start.gap, start.mode, start.torques);
        let stuck = self.stuck;
        let mode = contact | if stuck { STUCK } else { 0 };
        let t = self.coarse.as_ref()?;
        let d = &t.disc[mode];
        let inp: [f64; NI] = [u_new, tm0, tl0, tau_offset];
        let mut xp = if self.ns == 4 {
            advance::<4>(d, &x0, &inp)
        } else {
            advance::<6>(d, &x0, &inp)
        };
        for i in 0..self.ns {
            xp[i] += t.g_old[mode][i] * u_old;
        }
        let (tm1, tl1) = self.nonlinear_torques(&xp);
        let (dm, dl) = (tm1 - tm0, tl1 - tl0);
        if self.dry {
            if (dm * self.n).abs() + dl.abs() > tol {
                return None;
            }
        } else if dm != 0.0 || dl != 0.0 {
            return None;
        }
        let d = &self.coarse.as_ref()?.disc[mode];
        let mut x1 = xp;
        for i in 0..self.ns {
            x1[i] += d.g1[i][0] * dm + d.g1[i][1] * dl;
        }
        let w = self.fb_w();
        if stuck {
            // Held by dry friction: the friction body stays where it is (as in a stuck sub-step).
            x1[w] = 0.0;
            x1[w + 1] = x0[w + 1];
        } else if self.dry {
            let (w0, w1) = (x0[w] * self.dir, x1[w] * self.dir);
            if !(w0 > 0.0 && w1 > 0.0 && w0.min(w1) > (w1 - w0).abs()) {
                return None;
            }
        }
        let g1 = gap_state(&x1, inv_n);
        let end_mode = self.contact_mode(g1);
        if end_mode.0 != contact || !self.contact_unchanged(g0, g1, contact) {
            return None;
        }
        if stuck && !self.holds_over_period((&x0, g0), (&x1, g1), contact) {
            return None;
        }
        self.x = x1;
        Some(Carry {
            torques: (tm1, tl1),
            gap: g1,
            mode: end_mode,
        })
    }

    /// Whether dry friction holds the stuck friction body over a period from state `x0` to `x1`
    /// (gap states `g0`, `g1`, [`gap_state`]; contact mode `contact` at both ends): the torque
    /// driving it stays [`COARSE_EVENT_MARGIN`] below breakaway in either direction everywhere
    /// in between, read along the cubic through its values and rates at both ends. With play
    /// that torque is the contact's (none while the motor is free in the gap); without, the
    /// motor's, through the armature current (eq. 19 with the motor at rest). The smooth
    /// torques are zero (a plant with one is never stepped whole).
    #[inline(never)]
    fn holds_over_period(
        &self,
        (x0, g0): (&[f64; NS], (f64, f64)),
        (x1, g1): (&[f64; NS], (f64, f64)),
        contact: usize,
    ) -> bool {
        let Some(t) = &self.coarse else {
            return false;
        };
        let h = self.dt_s;
        let drive = match &self.play {
            Some(b) => {
                if contact & CONTACT == 0 {
                    return true;
                }
                // The spring-damper torque k (delta - offset) + c d(delta)/dt along the cubic
                // through the motor's place in the gap, the offset the flank in contact.
                let offset = if b.gap > 0.0 {
                    math::sign(g0.0) * 0.5 * b.gap
                } else {
                    0.0
                };
                let [a0, a1, a2, a3] = hermite_coefficients([g0.0, g0.1 * h, g1.0, g1.1 * h]);
                spring_damper_cubic(b.stiffness, b.damping / h, [a0 - offset, a1, a2, a3])
            }
            None => {
                let (rate, k_t_n) = t.armature;
                let di = |x: &[f64; NS]| rate[0] * x[0] + rate[1] * x[1] + rate[2] * x[2];
                let [a0, a1, a2, a3] = hermite_coefficients([x0[1], di(x0) * h, x1[1], di(x1) * h]);
                [a0 * k_t_n, a1 * k_t_n, a2 * k_t_n, a3 * k_t_n]
            }
        };
        let [back, fore] = t.hold_tol;
        let within = |(lo, hi): (f64, f64)| lo > -back && hi < fore;
        within(cubic_bounds(drive)) || within(cubic_range(drive))
    }

    /// Whether the contact can have kept mode `mode` (that of both ends) over a period between
    /// the gap states `(d0, r0)` and `(d1, r1)` ([`gap_state`]): always without a gap (the
    /// contact never opens); pressed, on a contact slow against the period, the force stays
    /// above [`COARSE_EVENT_MARGIN`] of its value at the ends everywhere in between; free, the
    /// motor stays clear of both flanks by that share of the half gap. Both read along the
    /// cubic through the motor's place in the gap and its rate at both ends.
    #[inline(never)]
    fn contact_unchanged(&self, (d0, r0): (f64, f64), (d1, r1): (f64, f64), mode: usize) -> bool {
        let (Some(b), Some(t)) = (&self.play, &self.coarse) else {
            return true;
        };
        if b.gap <= 0.0 {
            return true;
        }
        let h = self.dt_s;
        if mode & CONTACT != 0 {
            if !t.contact_whole || math::sign(d0) != math::sign(d1) {
                return false;
            }
            // The penetration [rad] along the cubic through its values and rates at both ends
            // (close to the motion for a contact slow against the period), and the force along
            // it: k p + c dp/dt, a cubic too, equal to the force at both ends.
            let side = math::sign(d0);
            let (p0, p1) = (side * d0 - 0.5 * b.gap, side * d1 - 0.5 * b.gap);
            let pen = hermite_coefficients([p0, side * r0 * h, p1, side * r1 * h]);
            let force = spring_damper_cubic(b.stiffness, b.damping / h, pen);
            // Both stay positive: the penetration (the motor on the flank) and the force.
            let above = |a: [f64; 4], ends: f64| {
                let ok = |(lo, _): (f64, f64)| lo > COARSE_EVENT_MARGIN * ends;
                ok(cubic_bounds(a)) || ok(cubic_range(a))
            };
            above(pen, p0.max(p1)) && above(force, force[0].max(force.iter().sum()))
        } else {
            let place = hermite_coefficients([d0, r0 * h, d1, r1 * h]);
            let inside = |(lo, hi): (f64, f64)| {
                lo.abs().max(hi.abs()) < (1.0 - COARSE_EVENT_MARGIN) * 0.5 * b.gap
            };
            inside(cubic_bounds(place)) || inside(cubic_range(place))
        }
    }
}

/// The motor's place in the gap [rad, load side] and its rate [rad/s] at state `x` (with play;
/// `inv_n` = 1 / N).
#[inline]
fn gap_state(x: &[f64; NS], inv_n: f64) -> (f64, f64) {
    (x[3] * inv_n - x[5], x[2] * inv_n - x[4])
}

/// The force k p + c dp/dt [N m] of a spring-damper (stiffness `k`, damping `c_per_h` = c / h)
/// along the cubic penetration `p` ([`hermite_coefficients`], time in periods h): a cubic too.
#[inline]
fn spring_damper_cubic(k: f64, c_per_h: f64, [a0, a1, a2, a3]: [f64; 4]) -> [f64; 4] {
    [
        k * a0 + c_per_h * a1,
        k * a1 + 2.0 * c_per_h * a2,
        k * a2 + 3.0 * c_per_h * a3,
        k * a3,
    ]
}

/// The coefficients [a0, a1, a2, a3] (a0 + a1 t + a2 t^2 + a3 t^3) of the cubic through `y0`
/// (slope `s0`) at t = 0 and `y1` (slope `s1`) at t = 1 (Hermite).
#[inline]
fn hermite_coefficients([y0, s0, y1, s1]: [f64; 4]) -> [f64; 4] {
    [
        y0,
        s0,
        3.0 * (y1 - y0) - 2.0 * s0 - s1,
        2.0 * (y0 - y1) + s0 + s1,
    ]
}

/// Bounds on the values of the cubic `a` ([`hermite_coefficients`]) on [0, 1] without solving
/// for its extremes: the cubic minus its chord is -(a2 + a3)(t - t^2) - a3 (t^2 - t^3), and on
/// [0, 1] t - t^2 <= 1/4, t^2 - t^3 <= 4/27 (taken as 1/4).
#[inline]
fn cubic_bounds([a0, a1, a2, a3]: [f64; 4]) -> (f64, f64) {
    let y1 = a0 + a1 + a2 + a3;
    let dev = 0.25 * ((a2 + a3).abs() + a3.abs());
    (a0.min(y1) - dev, a0.max(y1) + dev)
}

/// The smallest and largest values of the cubic `a` ([`hermite_coefficients`]) on [0, 1].
fn cubic_range([a0, a1, a2, a3]: [f64; 4]) -> (f64, f64) {
    let at = |t: f64| a0 + t * (a1 + t * (a2 + t * a3));
    let (y0, y1) = (a0, at(1.0));
    let (mut lo, mut hi) = (y0.min(y1), y0.max(y1));
    let mut visit = |t: f64| {
        if t > 0.0 && t < 1.0 {
            let v = at(t);
            lo = lo.min(v);
            hi = hi.max(v);
        }
    };
    // The derivative a1 + 2 a2 t + 3 a3 t^2 = 0.
    let (qa, qb, qc) = (3.0 * a3, 2.0 * a2, a1);
    if qa.abs() <= 1e-12 * (qb.abs() + qc.abs()) {
        if qb != 0.0 {
            visit(-qc / qb);
        }
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            let r = math::sqrt(disc);
            visit((-qb + r) / (2.0 * qa));
            visit((-qb - r) / (2.0 * qa));
        }
    }
    (lo, hi)
}
