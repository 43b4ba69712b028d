//! Everything `servo frf` computes from logs, in one call ([`analyze`]): the pooled plant
//! estimate (joint input-output in closed loop, H1 open loop), the loop L = C P (or T/(1 - T)
//! without a known controller) and the margins it achieved, the model's margins with the same
//! controller, the measured response against the model, the information content (coherence), and
//! whether the gain depends on the excitation's amplitude (friction).

use super::against::{
    against_model, amplitude_dependence, AmplitudeDependence, AtAmplitude, Comparison,
};
use super::{
    achieved_margins, estimate, loop_from_t, AchievedMargins, CrossSpectra, Frf, FrfError, Signals,
    WelchOptions,
};
use crate::control::pid::PidConfig;
use crate::design::controller::discrete_response;
use crate::design::margins::margins;
use crate::design::verify::sweep_for;
use crate::design::{c_expj, Complex, PidGains, PlantModel};
use crate::effects::EffectKind;
use crate::plant::Plant;
use alloc::format;
use alloc::string::{String, ToString};
use alloc::vec::Vec;

/// One log for [`analyze`]: the position reference [rad] (`None` or constant: open loop), the
/// driver input u [V] and the load angle theta_l [rad], sampled every `sample_period_s` [s].
#[derive(Debug, Clone, Copy)]
pub struct FrfLog<'a> {
    /// A name for messages and the amplitude comparison (the file name).
    pub name: &'a str,
    pub ref_rad: Option<&'a [f64]>,
    pub u_v: &'a [f64],
    pub theta_l_rad: &'a [f64],
    pub sample_period_s: f64,
}

/// The controller that ran, for L = C P: its configuration and a description of where it came
/// from (printed in the report).
#[derive(Debug, Clone, Copy)]
pub struct FrfController<'a> {
    pub config: &'a PidConfig,
    pub description: &'a str,
}

/// What to estimate.
#[derive(Debug, Clone, Copy)]
pub struct FrfRequest<'a> {
    /// At least one log; every log of one sample period, all closed loop or all open loop.
    pub logs: &'a [FrfLog<'a>],
    /// Averaging segment [s] (`None`: the largest power-of-two length giving ~16 averages).
    pub segment_s: Option<f64>,
    /// Coherence from which a bin counts for the achieved margins (e.g. 0.8).
    pub min_coherence: f64,
    pub controller: Option<FrfController<'a>>,
    /// The model to compare with: its discrete (ZOH) full linear model with its delay effect.
    pub model: Option<&'a Plant>,
}

/// Why [`analyze`] refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum FrfAnalysisError {
    #[error("no logs given")]
    NoLogs,
    #[error("{log}: sample period {period_s} s differs from the first log's {first_s} s; give logs of one period")]
    PeriodMismatch {
        log: String,
        period_s: f64,
        first_s: f64,
    },
    #[error("mix of closed-loop logs (a varying reference) and open-loop logs: estimate them separately")]
    MixedLoops,
    #[error("the averaging segment must be > 0 s, got {0}")]
    Segment(f64),
    #[error("estimating the frequency response")]
    Estimate(#[source] FrfError),
}

/// The margins of the model's loop (full plant with ZOH and delay, discrete controller).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelMargins {
    pub crossover_rad_s: f64,
    pub phase_margin_deg: f64,
    /// Infinite when the phase never crosses -180 deg.
    pub gain_margin_db: f64,
    /// Which loop, in words.
    pub loop_words: &'static str,
}

/// The result of [`analyze`].
#[derive(Debug, Clone)]
pub struct FrfAnalysis {
    /// Closed loop (a varying reference) or open loop.
    pub closed: bool,
    /// The sample period of the logs [s].
    pub ts_s: f64,
    /// The estimation method in words.
    pub method: &'static str,
    /// The plant P = theta_l / u [rad/V], pooled over the logs.
    pub plant: Frf,
    /// The complementary sensitivity T (closed loop).
    pub t: Option<Frf>,
    /// The loop L (C P with the controller, else T/(1 - T); none open loop without controller).
    pub loop_frf: Option<Frf>,
    /// How L was obtained, in words.
    pub loop_from: String,
    pub spectra: CrossSpectra,
    /// Welch settings used (the segment length fixed for the pooled and per-log estimates).
    pub welch: WelchOptions,
    /// Bin spacing [Hz].
    pub resolution_hz: f64,
    pub achieved: Option<AchievedMargins>,
    /// The model's margins with the same controller.
    pub design: Option<ModelMargins>,
    pub against_model: Option<Comparison>,
    /// The model's discrete response on the plant's bins (for plots).
    pub model_response: Option<Vec<Complex<f64>>>,
    /// RMS of u per log [V].
    pub u_rms_v: Vec<f64>,
    pub amplitude: Option<AmplitudeDependence>,
    /// Fraction of the excited bins (see [`excited_bins`]) with coherence >= 0.9, and the band
    /// they span [Hz].
    pub fraction_above_0_9: f64,
    pub band_hz_above_0_9: Option<(f64, f64)>,
    /// Number of bins the excitation reached (see [`excited_bins`]).
    pub excited_bins: usize,
    /// Ranges of excited bins with coherence < 0.5 [rad/s]: no information there.
    pub no_information_rad_s: Vec<(f64, f64)>,
    /// Caveats for the user.
    pub notes: Vec<String>,
}

/// Population standard deviation (0 for an empty slice).
pub fn std_dev(x: &[f64]) -> f64 {
    let m = x.iter().sum::<f64>() / x.len().max(1) as f64;
    libm::sqrt(x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / x.len().max(1) as f64)
}

/// The PID gains of a controller configuration.
fn gains_of(c: &PidConfig) -> PidGains {
    PidGains {
        kp: c.kp,
        ki: c.ki,
        kd: c.kd,
        tl_s: c.tl_s,
    }
}

/// Estimates the frequency response of the logs and everything derived from it (see the module).
///
/// ```
/// use servo_core::frf::analysis::{analyze, FrfLog, FrfRequest};
/// // An integrator with gain 5 rad/(V s) at 1 kHz, driven open loop by a pseudo-random u.
/// let ts = 1e-3;
/// let mut seed = 1u32;
/// let u: Vec<f64> = (0..20_000)
///     .map(|_| { seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223); (seed >> 8) as f64 / 8_388_608.0 - 1.0 })
///     .collect();
/// let mut th = vec![0.0; u.len()];
/// for k in 1..u.len() { th[k] = th[k - 1] + 5.0 * ts * u[k - 1]; }
/// let logs = [FrfLog { name: "sim", ref_rad: None, u_v: &u, theta_l_rad: &th, sample_period_s: ts }];
/// let a = analyze(&FrfRequest { logs: &logs, segment_s: None, min_coherence: 0.8, controller: None, model: None })?;
/// assert!(!a.closed);
/// // |P(j w)| = 5 / w at 10 rad/s, within 5 %.
/// let i = (0..a.plant.len()).min_by(|&i, &j| (a.plant.omega(i) - 10.0).abs().total_cmp(&(a.plant.omega(j) - 10.0).abs())).unwrap();
/// assert!((a.plant.mag(i) * a.plant.omega(i) / 5.0 - 1.0).abs() < 0.05);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn analyze(req: &FrfRequest) -> Result<FrfAnalysis, FrfAnalysisError> {
    let first = req.logs.first().ok_or(FrfAnalysisError::NoLogs)?;
    let ts = first.sample_period_s;
    let mut recs: Vec<Signals> = Vec::new();
    for l in req.logs {
        if ((l.sample_period_s - ts) / ts).abs() > 1e-3 {
            return Err(FrfAnalysisError::PeriodMismatch {
                log: l.name.to_string(),
                period_s: l.sample_period_s,
                first_s: ts,
            });
        }
        let rf = l.ref_rad.filter(|x| std_dev(x) > 1e-9);
        recs.push((rf, l.u_v, l.theta_l_rad));
    }
    let closed = recs[0].0.is_some();
    if recs.iter().any(|r| r.0.is_some() != closed) {
        return Err(FrfAnalysisError::MixedLoops);
    }
    let mut opts = WelchOptions::default();
    if let Some(s) = req.segment_s {
        if !(s.is_finite() && s > 0.0) {
            return Err(FrfAnalysisError::Segment(s));
        }
        opts.segment_len = Some((libm::round(s / ts) as usize).max(16));
    }
    // One segment length for the pooled and the per-log estimates.
    let total: usize = recs.iter().map(|r| r.1.len()).sum();
    let longest = recs.iter().map(|r| r.1.len()).max().unwrap_or(0);
    opts.segment_len = Some(opts.segment_for(total, longest));
    let est = |rs: &[Signals]| estimate(rs, closed, ts, &opts);
    let (plant, t, spectra) = est(&recs).map_err(FrfAnalysisError::Estimate)?;

    let mut notes = Vec::new();
    let controller = req.controller;
    let c_of = |w: f64| -> Option<Complex<f64>> {
        controller.map(|c| {
            discrete_response(
                &gains_of(c.config),
                c.config.ts_s,
                c.config.discretization,
                w,
            )
        })
    };
    let (loop_frf, loop_from) = match (&controller, &t) {
        (Some(c), _) => (
            Some(plant.times(|w| c_of(w).unwrap_or(Complex::new(f64::NAN, 0.0)))),
            format!("L = C P with C {}", c.description),
        ),
        (None, Some(t)) => {
            notes.push("no controller known (--gains): L = T/(1 - T), which assumes u = C (r - theta_l) without feedforward".to_string());
            (Some(loop_from_t(t)), "L = T/(1 - T)".to_string())
        }
        (None, None) => (None, "no loop (open-loop logs without --gains)".to_string()),
    };
    let achieved = loop_frf
        .as_ref()
        .map(|l| achieved_margins(l, req.min_coherence, -180.0));

    // The model: its full linear plant with ZOH and its delay.
    let model_resp = req.model.map(|m| {
        let lin = PlantModel::full(&m.linear_params());
        let d = lin.state_space().discretize_zoh(ts);
        let delay = m.effects.value(EffectKind::Delay, "delay").unwrap_or(0.0);
        (m, lin, move |w: f64| d.response(w) * c_expj(-w * delay))
    });
    let against = model_resp
        .as_ref()
        .map(|(_, _, pm)| against_model(&plant, pm));
    let design = match (&model_resp, &controller) {
        (Some((_, lin, pm)), Some(c)) => {
            let wc_guess = achieved
                .as_ref()
                .and_then(|a| a.crossover_rad_s)
                .map_or(30.0, |i| i.value);
            let m = margins(
                |w| c_of(w).unwrap_or_default() * pm(w),
                &sweep_for(wc_guess, lin, &gains_of(c.config), Some(ts)),
            );
            Some(ModelMargins {
                crossover_rad_s: m.omega_gc,
                phase_margin_deg: m.phase_margin_deg,
                gain_margin_db: m.gain_margin_db,
                loop_words:
                    "model's full plant with ZOH (and its delay) and the discrete controller",
            })
        }
        _ => None,
    };
    let model_response = model_resp
        .as_ref()
        .map(|(_, _, pm)| (0..plant.len()).map(|i| pm(plant.omega(i))).collect());

    // Friction against the excitation's amplitude.
    let u_rms_v: Vec<f64> = recs.iter().map(|r| std_dev(r.1)).collect();
    if let Some((m, _, _)) = &model_resp {
        let p = m.linear_params();
        let tau = m.tau_sf();
        if tau > 0.0 {
            let uf = tau / p.n * p.r_eq() / (p.k_t * p.k_drv);
            let umin = u_rms_v.iter().cloned().fold(f64::INFINITY, f64::min);
            if umin < 3.0 * uf {
                notes.push(format!("u is only {umin:.2} V rms against the model's Coulomb friction voltage {uf:.2} V: friction shapes this estimate (excite with a larger amplitude to see the linear plant)"));
            }
        }
    }
    // Amplitude dependence between logs.
    let per_log: Vec<Option<Frf>> = if recs.len() > 1 {
        recs.iter()
            .map(|r| est(core::slice::from_ref(r)).map(|e| e.0).ok())
            .collect()
    } else {
        Vec::new()
    };
    let ats: Vec<AtAmplitude> = per_log
        .iter()
        .zip(req.logs)
        .zip(&u_rms_v)
        .filter_map(|((e, l), u)| {
            e.as_ref().map(|e| AtAmplitude {
                name: l.name,
                u_rms_v: *u,
                estimate: e,
            })
        })
        .collect();
    let amplitude = amplitude_dependence(&ats);

    // Information content, over the bins the excitation reached (a multisine's lines, not the
    // gaps between them, where nothing was excited and nothing can be learnt).
    let excited = excited_bins(&spectra, &plant);
    let excited_count = excited.iter().filter(|&&e| e).count();
    let coh_hi: Vec<usize> = plant.coherent(0.9).filter(|&i| excited[i]).collect();
    let band_hz_above_0_9 = match (coh_hi.first(), coh_hi.last()) {
        (Some(&a), Some(&b)) => Some((plant.freq_hz[a], plant.freq_hz[b])),
        _ => None,
    };
    let fraction_above_0_9 = coh_hi.len() as f64 / excited_count.max(1) as f64;
    let no_information_rad_s = low_coherence_ranges_where(&plant, 0.5, &excited);
    let resolution_hz = plant.freq_hz.first().copied().unwrap_or(f64::NAN);
    let method = if closed {
        "joint input-output: P = G_{r,theta}/G_{r,u} (reference r as instrument; the direct u -> theta estimate is biased in closed loop)"
    } else {
        "open loop: P = H1(u -> theta_l)"
    };
    Ok(FrfAnalysis {
        closed,
        ts_s: ts,
        method,
        plant,
        t,
        loop_frf,
        loop_from,
        spectra,
        welch: opts,
        resolution_hz,
        achieved,
        design,
        against_model: against,
        model_response,
        u_rms_v,
        amplitude,
        fraction_above_0_9,
        band_hz_above_0_9,
        excited_bins: excited_count,
        no_information_rad_s,
        notes,
    })
}

/// Share of the largest input power from which a bin counts as excited.
pub const EXCITED_FRACTION: f64 = 1e-2;

/// The bins of `plant` the excitation reached: the input's (reference's in closed loop, u's open
/// loop) power G_xx at least [`EXCITED_FRACTION`] of its largest. All bins when the spectra do
/// not line up with the estimate's bins.
pub fn excited_bins(spectra: &CrossSpectra, plant: &Frf) -> Vec<bool> {
    if spectra.gxx.len() != plant.len() {
        return alloc::vec![true; plant.len()];
    }
    let max = spectra
        .gxx
        .iter()
        .copied()
        .filter(|g| g.is_finite())
        .fold(0.0f64, f64::max);
    spectra
        .gxx
        .iter()
        .map(|&g| max > 0.0 && g >= EXCITED_FRACTION * max)
        .collect()
}

/// Ranges [rad/s] of excited bins (`mask`) with coherence below `level`: a bin outside the mask
/// ends a range.
pub fn low_coherence_ranges_where(est: &Frf, level: f64, mask: &[bool]) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::new();
    let mut open: Option<(f64, f64)> = None;
    for i in 0..est.len() {
        let w = est.omega(i);
        if mask.get(i).copied().unwrap_or(true) && est.coherence[i] < level {
            open = Some(open.map_or((w, w), |(a, _)| (a, w)));
        } else if let Some(r) = open.take() {
            out.push(r);
        }
    }
    out.extend(open);
    out
}
