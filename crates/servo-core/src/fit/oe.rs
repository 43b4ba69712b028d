//! Output-error cost: the model simulated (with [`PlantSim`]) from measured states over short
//! horizons, driven by the logged input, compared with the measured motor angle.
//!
//! Re-initialising every segment from the measurement keeps an integrating plant from drifting
//! and works the same on open-loop and closed-loop logs (the logged u drives the model).

use super::dataset::{Dataset, RecData};
use crate::math;
use crate::plant::Plant;
use crate::sim::{PlantSim, PlantState};
use alloc::vec::Vec;

/// Control periods simulated by every output-error cost of this process so far (std builds;
/// `SERVO_DIAG_TIMING` prints each stage's share): the measure of a search's work that does not
/// depend on the machine.
#[cfg(feature = "std")]
pub fn simulated_periods() -> u64 {
    SIMULATED_PERIODS.load(core::sync::atomic::Ordering::Relaxed)
}

#[cfg(feature = "std")]
static SIMULATED_PERIODS: core::sync::atomic::AtomicU64 = core::sync::atomic::AtomicU64::new(0);

/// Adds `n` periods to [`simulated_periods`] (nothing without std).
#[inline]
fn count_periods(n: usize) {
    #[cfg(feature = "std")]
    SIMULATED_PERIODS.fetch_add(n as u64, core::sync::atomic::Ordering::Relaxed);
    #[cfg(not(feature = "std"))]
    let _ = n;
}

/// Which part of the data a cost is computed on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    /// Blocks used for fitting.
    Fit,
    /// Held-out blocks.
    Holdout,
    /// Everything.
    All,
}

/// Segment starts (record, row) of `part`, at most `opts.oe_max_segments`, spread evenly.
pub fn segments(ds: &Dataset, part: Part) -> Vec<(usize, usize)> {
    segments_with(ds, part, ds.opts.oe_horizon_s, 1, ds.opts.oe_max_segments)
}

/// As [`segments`] with a given horizon [s], segments starting every `horizon_s / overlap`
/// (`overlap` = 1: back to back), at most `max_segments`.
pub fn segments_with(
    ds: &Dataset,
    part: Part,
    horizon_s: f64,
    overlap: usize,
    max_segments: usize,
) -> Vec<(usize, usize)> {
    let o = &ds.opts;
    let mut all = Vec::new();
    // Records without a logged input cannot drive the model.
    for (ri, r) in ds.recs.iter().enumerate().filter(|(_, r)| r.has_u) {
        let fs = 1.0 / r.dt_s;
        let h = ((horizon_s * fs) as usize).max(2);
        let edge = libm::ceil((2.0 / o.filter_hz) * fs) as usize + 2;
        let block = ((o.holdout_block_s * fs) as usize).max(1);
        let n = r.u_v.len();
        let mut k = edge.max(1);
        while k + h + edge < n {
            let b = k / block;
            let fit = o.holdout_every == 0 || b % o.holdout_every != o.holdout_every - 1;
            let keep = match part {
                Part::All => true,
                Part::Fit => fit,
                Part::Holdout => !fit,
            };
            // Skip segments at rest: they carry no dynamics.
            let moving = r.omega_f[k..k + h]
                .iter()
                .any(|w| w.abs() > o.min_speed_rad_s);
            if keep && moving {
                all.push((ri, k));
            }
            k += (h / overlap.max(1)).max(1);
        }
    }
    let m = max_segments.max(1);
    if all.len() <= m {
        return all;
    }
    (0..m).map(|i| all[i * all.len() / m]).collect()
}

/// RMS error of the predicted motor angle [rad] over the segments of `part`; `None` when there
/// is no segment or the model cannot be simulated.
pub fn prediction_cost(ds: &Dataset, plant: &Plant, part: Part) -> Option<f64> {
    let segs = segments(ds, part);
    prediction_cost_on(ds, plant, &segs)
}

/// As [`prediction_cost`] on given segment starts.
pub fn prediction_cost_on(ds: &Dataset, plant: &Plant, segs: &[(usize, usize)]) -> Option<f64> {
    prediction_cost_over(ds, plant, segs, ds.opts.oe_horizon_s)
}

/// As [`prediction_cost_on`] with a given horizon [s].
pub fn prediction_cost_over(
    ds: &Dataset,
    plant: &Plant,
    segs: &[(usize, usize)],
    horizon_s: f64,
) -> Option<f64> {
    prediction_cost_bounded(ds, plant, segs, horizon_s, f64::INFINITY)
}

/// As [`prediction_cost_over`], stopping early with `Some(f64::INFINITY)` once the cost is
/// certain to exceed `bound_rad` (the squared errors summed so far already exceed `bound_rad`^2
/// times the number of samples): the searches only compare costs (see
/// [`super::search::grid_then_golden_bounded`]).
pub fn prediction_cost_bounded(
    ds: &Dataset,
    plant: &Plant,
    segs: &[(usize, usize)],
    horizon_s: f64,
    bound_rad: f64,
) -> Option<f64> {
    prediction_cost_stepped(
        ds,
        plant,
        segs,
        horizon_s,
        bound_rad,
        crate::sim::MAX_SUBSTEP_S,
    )
}

/// Largest internal sub-step [s] of the simulations that only *choose a grid cell* of a search
/// on the output error ([`prediction_cost_stepped`]): four sub-steps per millisecond instead of
/// ten.
///
/// The simulator discretises each contact and stick mode exactly and holds the nonlinear torques
/// to first order over a sub-step, so a longer sub-step only blurs the instants where a mode
/// switches (a stop, a breakaway, a flank met) by up to a sub-step. Too long a sub-step invents
/// play (at 1 ms a complete model's gap comes out 0.010 rad instead of 0.0002), so the values a
/// search returns are always refined and judged on the full-fidelity simulation
/// ([`prediction_cost_bounded`]) around the cell chosen here.
pub const SEARCH_SUBSTEP_S: f64 = 250e-6;

/// As [`prediction_cost_bounded`] with the simulator's largest internal sub-step
/// `max_substep_s` [s] (see [`crate::sim::PlantSim::with_max_substep`]; [`SEARCH_SUBSTEP_S`] for
/// the grid of a search).
///
/// The segments are independent simulations: with at least [`SPLIT_MIN_SAMPLES`] samples they
/// are summed in two halves, always (so the value never depends on the machine's load), and the
/// two halves run on two threads when a core is idle (std builds, see
/// [`crate::par::idle_core`]): the long simulations that end a diagnosis (a gear play's
/// refinement, the checks of a significant candidate) then use both cores.
pub fn prediction_cost_stepped(
    ds: &Dataset,
    plant: &Plant,
    segs: &[(usize, usize)],
    horizon_s: f64,
    bound_rad: f64,
    max_substep_s: f64,
) -> Option<f64> {
    let samples = |s: &[(usize, usize)]| simulated_samples(ds, s, horizon_s);
    let total = samples(segs);
    if segs.len() < 2 || total < SPLIT_MIN_SAMPLES {
        return cost_serial(ds, plant, segs, horizon_s, bound_rad, max_substep_s);
    }
    let (a, b) = segs.split_at(segs.len() / 2);
    // Each half stops early against the whole sum's limit (bound^2 times every sample): a half
    // alone above it puts the whole above it.
    let limit = bound_rad * bound_rad * total as f64;
    // A half's squared errors, as the whole cost weighs them (from its RMS), and its samples.
    let half = |s: &[(usize, usize)], limit: f64| -> Option<(f64, usize)> {
        let n = samples(s);
        let r = sum_serial(ds, plant, s, horizon_s, limit, max_substep_s)?;
        let rms = r.map_or(f64::INFINITY, |(sum, count)| rms_of(sum, count));
        Some((rms * rms * n as f64, n))
    };
    let (ra, rb) = match idle_core_guard() {
        Some(_held) => both(|| half(a, limit), || half(b, limit)),
        None => {
            // In turn: the second half stops as soon as both sums together exceed the limit (a
            // first half already above it decides alone).
            let ra = half(a, limit);
            let rb = match ra {
                Some((sa, _)) if sa.is_finite() => half(b, limit - sa),
                _ => Some((f64::INFINITY, samples(b))),
            };
            (ra, rb)
        }
    };
    let ((sa, na), (sb, nb)) = (ra?, rb?);
    if !(sa.is_finite() && sb.is_finite()) {
        return Some(f64::INFINITY);
    }
    Some(math::sqrt((sa + sb) / (na + nb).max(1) as f64))
}

/// Fewest simulated samples of one cost evaluation summed in two halves (possibly on two
/// threads, see [`prediction_cost_stepped`]): a thread costs tens of microseconds, a sample
/// about a microsecond.
pub const SPLIT_MIN_SAMPLES: usize = 4_000;

/// A core for the second half of a split cost, held while the guard lives (std builds, see
/// [`crate::par::idle_core`]); `None` when every core is taken (or without std).
fn idle_core_guard() -> Option<impl Sized> {
    #[cfg(feature = "std")]
    {
        crate::par::idle_core()
    }
    #[cfg(not(feature = "std"))]
    {
        None::<()>
    }
}

/// `(fa(), fb())` on two threads (std builds; the caller holds an idle core), else in turn.
fn both<A: Send, B: Send>(fa: impl FnOnce() -> A + Send, fb: impl FnOnce() -> B + Send) -> (A, B) {
    #[cfg(feature = "std")]
    {
        crate::par::on_two_threads(fa, fb)
    }
    #[cfg(not(feature = "std"))]
    {
        (fa(), fb())
    }
}

/// Samples simulated over the segments `segs` (record, start) of `horizon_s` [s] each: at least
/// 2 per segment.
fn simulated_samples(ds: &Dataset, segs: &[(usize, usize)], horizon_s: f64) -> usize {
    segs.iter()
        .map(|&(ri, _)| ((horizon_s / ds.recs[ri].dt_s) as usize).max(2))
        .sum()
}

/// The RMS prediction error [rad] of each segment of `segs` on its own (horizon `horizon_s`
/// [s]), in the order given: for robust costs that let a few unpredictable segments (a start
/// state no measurement fixes) weigh no more than the others. One simulator serves every
/// segment, as in [`prediction_cost_stepped`].
pub fn segment_costs(
    ds: &Dataset,
    plant: &Plant,
    segs: &[(usize, usize)],
    horizon_s: f64,
) -> Option<Vec<f64>> {
    segment_costs_stepped(ds, plant, segs, horizon_s, crate::sim::MAX_SUBSTEP_S)
}

/// As [`segment_costs`] with the simulator's largest internal sub-step `max_substep_s` [s]
/// ([`SEARCH_SUBSTEP_S`] for the grid of a search, as in [`prediction_cost_stepped`]).
pub fn segment_costs_stepped(
    ds: &Dataset,
    plant: &Plant,
    segs: &[(usize, usize)],
    horizon_s: f64,
    max_substep_s: f64,
) -> Option<Vec<f64>> {
    // Independent simulations: in two halves on two threads when a core is idle (the serial
    // refinements of the joint search), the same values either way.
    if segs.len() >= 2 && simulated_samples(ds, segs, horizon_s) >= SPLIT_MIN_SAMPLES {
        if let Some(_held) = idle_core_guard() {
            let (a, b) = segs.split_at(segs.len() / 2);
            let (ca, cb) = both(
                || segment_costs_serial(ds, plant, a, horizon_s, max_substep_s),
                || segment_costs_serial(ds, plant, b, horizon_s, max_substep_s),
            );
            let mut out = ca?;
            out.extend(cb?);
            return Some(out);
        }
    }
    segment_costs_serial(ds, plant, segs, horizon_s, max_substep_s)
}

/// [`segment_costs_stepped`] on one thread, sub-steps of at most `h` [s].
fn segment_costs_serial(
    ds: &Dataset,
    plant: &Plant,
    segs: &[(usize, usize)],
    horizon_s: f64,
    h: f64,
) -> Option<Vec<f64>> {
    let mut out = Vec::with_capacity(segs.len());
    let (mut sum, mut count) = (0.0, 0usize);
    simulate_segments(ds, plant, segs, horizon_s, h, |ev| {
        match ev {
            Sample::Error(e) => {
                sum += e * e;
                count += 1;
            }
            Sample::SegmentEnd => {
                out.push(math::sqrt(sum / count.max(1) as f64));
                (sum, count) = (0.0, 0);
            }
        }
        true
    })?;
    Some(out)
}

/// [`prediction_cost_stepped`] on one thread.
fn cost_serial(
    ds: &Dataset,
    plant: &Plant,
    segs: &[(usize, usize)],
    horizon_s: f64,
    bound_rad: f64,
    max_substep_s: f64,
) -> Option<f64> {
    let total = simulated_samples(ds, segs, horizon_s);
    let limit = bound_rad * bound_rad * total as f64;
    let r = sum_serial(ds, plant, segs, horizon_s, limit, max_substep_s)?;
    Some(r.map_or(f64::INFINITY, |(sum, count)| rms_of(sum, count)))
}

/// What [`sum_serial`] returns: `None` when the model cannot be simulated (or no segment),
/// `Some(None)` when it stopped above the limit, else the sum of the squared errors [rad^2]
/// and the number of samples.
type SumOrStop = Option<Option<(f64, usize)>>;

/// RMS [rad] of `count` errors whose squares sum to `sum` [rad^2].
fn rms_of(sum: f64, count: usize) -> f64 {
    math::sqrt(sum / count.max(1) as f64)
}

/// The squared prediction errors over `segs` summed on one thread, stopping as soon as the sum
/// exceeds `limit_rad2` [rad^2] (the squares only add up: a sum above the limit at any sample
/// stays above it at the end).
fn sum_serial(
    ds: &Dataset,
    plant: &Plant,
    segs: &[(usize, usize)],
    horizon_s: f64,
    limit_rad2: f64,
    max_substep_s: f64,
) -> SumOrStop {
    if segs.is_empty() {
        return None;
    }
    let (mut sum, mut count) = (0.0, 0usize);
    let ended = simulate_segments(ds, plant, segs, horizon_s, max_substep_s, |ev| match ev {
        Sample::Error(e) => {
            sum += e * e;
            count += 1;
            sum <= limit_rad2
        }
        Sample::SegmentEnd => sum <= limit_rad2,
    })?;
    Some(ended.then_some((sum, count)))
}

/// What [`simulate_segments`] reports, in order.
enum Sample {
    /// The prediction error of one sample [rad, measured angle].
    Error(f64),
    /// The end of a segment.
    SegmentEnd,
}

/// Simulates each segment of `segs` (record, start) over `horizon_s` [s] from its measured
/// state, one simulator per sample period, and reports each sample's error and each segment's
/// end, in order, to `visit`, which returns false (at a sample or a segment's end) to stop.
/// `Some(true)`: every segment ran; `Some(false)`: stopped; `None`: a non-finite error or a
/// simulator that cannot be built.
fn simulate_segments(
    ds: &Dataset,
    plant: &Plant,
    segs: &[(usize, usize)],
    horizon_s: f64,
    max_substep_s: f64,
    mut visit: impl FnMut(Sample) -> bool,
) -> Option<bool> {
    // Two simulators per sample period, reset at every segment: building one discretises every
    // contact mode (matrix exponentials), which costs as much as a segment's steps; the second
    // is a copy. Two segments on the same period are simulated side by side
    // ([`PlantSim::step_pair`]: each exactly as alone, the two chains of arithmetic overlapped)
    // and their errors then reported in order, as if one after the other.
    let mut sims: Option<(PlantSim, PlantSim)> = None;
    let mut errs: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
    let mut next = 0;
    while let Some(&first) = segs.get(next) {
        let dt_s = ds.recs[first.0].dt_s;
        if sims.as_ref().is_none_or(|(s, _)| s.dt_s() != dt_s) {
            let sim = PlantSim::with_max_substep(plant, dt_s, max_substep_s)
                .ok()?
                .with_coarse_periods();
            sims = Some((sim.clone(), sim));
        }
        let (a, b) = sims.as_mut()?;
        let second = segs
            .get(next + 1)
            .copied()
            .filter(|&(rj, _)| ds.recs[rj].dt_s == dt_s);
        let r = &ds.recs[first.0];
        let h = ((horizon_s / r.dt_s) as usize).max(2);
        for e in errs.iter_mut() {
            e.clear();
        }
        a.reset(start_state(ds, plant, first));
        let [ea, eb] = &mut errs;
        match second {
            Some(sb) => {
                let rb = &ds.recs[sb.0];
                b.reset(start_state(ds, plant, sb));
                for j in 0..h {
                    a.step_pair(b, r.u_v[first.1 + j], rb.u_v[sb.1 + j]);
                    ea.push(angle_error(plant, r, first.1 + j + 1, a.state()));
                    eb.push(angle_error(plant, rb, sb.1 + j + 1, b.state()));
                }
            }
            None => {
                for j in 0..h {
                    a.step(r.u_v[first.1 + j]);
                    ea.push(angle_error(plant, r, first.1 + j + 1, a.state()));
                }
            }
        }
        let done = if second.is_some() { 2 } else { 1 };
        count_periods(done * h);
        for seg_errs in errs.iter().take(done) {
            for &e in seg_errs {
                if !e.is_finite() {
                    return None;
                }
                if !visit(Sample::Error(e)) {
                    return Some(false);
                }
            }
            if !visit(Sample::SegmentEnd) {
                return Some(false);
            }
        }
        next += done;
    }
    Some(true)
}

/// The simulated angle's error [rad, as measured] against sample `k` of record `r`.
#[inline]
fn angle_error(plant: &Plant, r: &RecData, k: usize, s: &PlantState) -> f64 {
    let out = if r.angle_is_load {
        s.theta_l_rad * plant.params.n
    } else {
        s.theta_m_rad
    };
    out - r.theta_m_rad[k]
}

/// The state a segment (record, start row) is simulated from: the measured one, with a gear
/// play's motor side on the flank it presses on.
fn start_state(ds: &Dataset, plant: &Plant, (ri, k0): (usize, usize)) -> PlantState {
    let p = &plant.params;
    let r = &ds.recs[ri];
    let w = r.omega_f[k0];
    let u_prev = r.u_v[k0.saturating_sub(1)];
    let i = match &r.i_f {
        Some(i) => i[k0],
        None => (p.k_drv * u_prev - p.k_e * w) / p.r_eq(),
    };
    let th = r.theta_m_rad[k0];
    // With a gear play (a contact effect) and the load angle measured, start in contact on
    // the driving flank.
    let contact = plant_contact(plant);
    let half_gap = contact.map_or(0.0, |c| c.gap_rad) * 0.5;
    // With play, the motor side is put on the flank it presses on, the contact spring
    // compressed by the torque the load needs (load side [rad]); without play (a compliance)
    // the spring is wound up by that torque all the same.
    let offset_l = if contact.is_some() {
        let tau_c = contact_torque_l(plant, w, r.accel_f[k0], u_prev, ds.opts.min_speed_rad_s);
        let k_c = contact.map_or(f64::INFINITY, |c| c.stiffness_nm_per_rad);
        half_gap * math::sign(tau_c) + tau_c / k_c
    } else {
        0.0
    };
    let (th_m, th_l) = if r.angle_is_load {
        (th + p.n * offset_l, th / p.n)
    } else {
        (th, th / p.n - offset_l)
    };
    PlantState {
        time_s: r.time_s[k0],
        u_in_v: u_prev,
        u_drv_v: p.k_drv * u_prev,
        i_a_a: i,
        omega_m_rad_s: w,
        theta_m_rad: th_m,
        omega_l_rad_s: w / p.n,
        theta_l_rad: th_l,
        ..PlantState::default()
    }
}

/// The contact (gear play) of `plant`, if it has a contact effect.
fn plant_contact(plant: &Plant) -> Option<crate::effects::Contact> {
    let e = plant.effects.with_role(crate::effects::SimRole::Contact)?;
    e.kind.model().contact(e.values())
}

/// The torque the contact transmits to the load [N m, load side] at a segment start, from the
/// load body's balance: what it needs to accelerate at `accel` [rad/s^2, motor side] against its
/// share of the viscous friction and the dry friction at speed `omega` [rad/s, motor side]. Its
/// sign is the flank the motor presses on: moving at constant speed the motor drives the load;
/// braking harder than friction alone would, it holds the load back (the other flank). At rest
/// the sign of the last input `u_prev` [V] decides (torque 0).
fn contact_torque_l(plant: &Plant, omega: f64, accel: f64, u_prev: f64, min_speed: f64) -> f64 {
    let p = &plant.params;
    let f = plant_contact(plant).map_or(0.3, |c| c.load_inertia_fraction);
    if omega.abs() <= min_speed {
        return math::sign(u_prev) * f64::MIN_POSITIVE;
    }
    let tau_m = f * p.j_eq() * accel + f * plant.b_eq() * omega;
    tau_m * p.n + plant.tau_sf() * math::sign(omega)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::tests::{open_loop_log, truth};
    use crate::fit::FitOptions;

    /// Each segment's cost from the shared simulator is the cost of that segment alone, and
    /// the costs of all of them make up the whole cost.
    #[test]
    fn segment_costs_are_each_segment_alone() {
        let plant = truth();
        let rec = open_loop_log(&plant, 6.0, 3, true);
        let ds = Dataset::new(&[rec], &plant.params, &FitOptions::default()).unwrap();
        let segs = segments(&ds, Part::Fit);
        assert!(segs.len() >= 3, "{} segments", segs.len());
        let h = ds.opts.oe_horizon_s;
        let each = segment_costs(&ds, &plant, &segs, h).unwrap();
        assert_eq!(each.len(), segs.len());
        for (s, c) in segs.iter().zip(&each) {
            let alone = prediction_cost_over(&ds, &plant, core::slice::from_ref(s), h).unwrap();
            assert_eq!(*c, alone);
        }
        let n: Vec<f64> = segs
            .iter()
            .map(|&(ri, _)| ((h / ds.recs[ri].dt_s) as usize).max(2) as f64)
            .collect();
        let ms: f64 =
            each.iter().zip(&n).map(|(c, n)| c * c * n).sum::<f64>() / n.iter().sum::<f64>();
        let whole = prediction_cost_over(&ds, &plant, &segs, h).unwrap();
        assert!(
            (math::sqrt(ms) / whole - 1.0).abs() < 1e-9,
            "{} vs {whole}",
            math::sqrt(ms)
        );
    }
}
