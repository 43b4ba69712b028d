//! One comparison of a model with one log: figures per signal, residual analysis, where the error
//! sits, and findings in plain language.

use super::figures::Figures;
use super::measured::{speed_from_position, Measured};
use super::periodic::{best_harmonic, effective_samples, AngleSource, PeriodicFinding};
use super::regimes::{
    classify, detect_u_limit, regime_stats, Classification, Regime, RegimeOptions, RegimeStats,
};
use super::replay::{Replay, ReplayMode};
use super::whiteness::{cross_correlation, whiteness, CrossCorrelation, Whiteness};
use super::windows::{worst_windows, Window};
use crate::math;
use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;

/// A compared signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SignalKind {
    /// Load angle theta_l [rad].
    Position,
    /// Load speed omega_l [rad/s].
    Speed,
    /// Armature current i_a [A].
    Current,
    /// Controller output u [V] (closed-loop replay only).
    Voltage,
}

impl SignalKind {
    /// Signal name (`theta_l`, `omega_l`, `i_a`, `u`).
    pub fn name(self) -> &'static str {
        match self {
            SignalKind::Position => "theta_l",
            SignalKind::Speed => "omega_l",
            SignalKind::Current => "i_a",
            SignalKind::Voltage => "u",
        }
    }
    /// SI unit.
    pub fn unit(self) -> &'static str {
        match self {
            SignalKind::Position => "rad",
            SignalKind::Speed => "rad/s",
            SignalKind::Current => "A",
            SignalKind::Voltage => "V",
        }
    }
    /// Signal name on a linear axis of travel `metres_per_rad` [m/rad] (`x`, `v_x` for the load
    /// position and speed; `None`: as [`SignalKind::name`]).
    pub fn name_on(self, metres_per_rad: Option<f64>) -> &'static str {
        match (self, metres_per_rad) {
            (SignalKind::Position, Some(_)) => "x",
            (SignalKind::Speed, Some(_)) => "v_x",
            _ => self.name(),
        }
    }
    /// SI unit on a linear axis (`m`, `m/s` for the load position and speed).
    pub fn unit_on(self, metres_per_rad: Option<f64>) -> &'static str {
        match (self, metres_per_rad) {
            (SignalKind::Position, Some(_)) => "m",
            (SignalKind::Speed, Some(_)) => "m/s",
            _ => self.unit(),
        }
    }
    /// The factor from this signal's SI unit to [`SignalKind::unit_on`]: the travel per radian
    /// for the load position and speed on a linear axis, else 1.
    pub fn scale_on(self, metres_per_rad: Option<f64>) -> f64 {
        match (self, metres_per_rad) {
            (SignalKind::Position | SignalKind::Speed, Some(m)) => m,
            _ => 1.0,
        }
    }
    /// Words for a student.
    pub fn words(self) -> &'static str {
        match self {
            SignalKind::Position => "load position",
            SignalKind::Speed => "load speed",
            SignalKind::Current => "armature current",
            SignalKind::Voltage => "controller voltage",
        }
    }
}

/// Options of the analysis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompareOptions {
    /// Cut-off of the zero-phase filter for speed derived from position [Hz].
    pub speed_filter_hz: f64,
    /// Regime thresholds.
    pub regimes: RegimeOptions,
    /// Lags of the whiteness test and of the cross-correlation (MATLAB's default 25).
    pub max_lag: usize,
    /// Length of the worst windows [s].
    pub window_s: f64,
    /// How many worst windows.
    pub worst_count: usize,
    /// Voltage limit for the regime "voltage near its limit" [V]; `None`: detected from the log.
    pub u_limit_v: Option<f64>,
    /// Largest harmonic of the motor angle searched (magnetic detents).
    pub max_motor_harmonic: u32,
    /// Largest harmonic of the load angle searched (an eccentric load).
    pub max_load_harmonic: u32,
    /// On a linear axis, the load shaft's travel per radian [m/rad]: the reports' positions and
    /// speeds are then in m and m/s (`None`: a rotary gear, in rad and rad/s). The analysis
    /// itself runs on the equivalent rotation either way.
    pub metres_per_rad: Option<f64>,
}

impl Default for CompareOptions {
    fn default() -> Self {
        CompareOptions {
            speed_filter_hz: 30.0,
            regimes: RegimeOptions::default(),
            max_lag: 25,
            window_s: 0.1,
            worst_count: 5,
            u_limit_v: None,
            max_motor_harmonic: 40,
            max_load_harmonic: 4,
            metres_per_rad: None,
        }
    }
}

/// Measurement and model of one signal.
#[derive(Debug, Clone, PartialEq)]
pub struct SignalComparison {
    pub kind: SignalKind,
    pub measured: Vec<f64>,
    pub model: Vec<f64>,
    pub figures: Figures,
}

impl SignalComparison {
    fn new(kind: SignalKind, measured: Vec<f64>, model: Vec<f64>) -> SignalComparison {
        let figures = Figures::of(&measured, &model);
        SignalComparison {
            kind,
            measured,
            model,
            figures,
        }
    }
    /// Residual e = measurement - model.
    pub fn residual(&self) -> Vec<f64> {
        self.measured
            .iter()
            .zip(&self.model)
            .map(|(a, b)| a - b)
            .collect()
    }
}

/// The comparison of a model with one log.
#[derive(Debug, Clone, PartialEq)]
pub struct CompareReport {
    pub mode: ReplayMode,
    pub time_s: Vec<f64>,
    pub dt_s: f64,
    /// Compared signals; `signals[headline]` is the headline.
    pub signals: Vec<SignalComparison>,
    pub headline: usize,
    /// Residual of the headline signal.
    pub residual: Vec<f64>,
    pub whiteness: Whiteness,
    /// Cross-correlation of the residual with the exogenous input (the reference in closed loop,
    /// u otherwise), and which one it is.
    pub input_xcorr: CrossCorrelation,
    pub input_name: &'static str,
    /// Measured load speed [rad/s] and position [rad] (for residual-vs-state plots).
    pub omega_l_rad_s: Vec<f64>,
    pub theta_l_rad: Option<Vec<f64>>,
    pub classification: Classification,
    pub regimes: Vec<RegimeStats>,
    /// Best periodic component per angle source (motor, load), significant or not.
    pub periodic: Vec<PeriodicFinding>,
    pub worst_windows: Vec<Window>,
    /// Findings in plain language, most important first.
    pub findings: Vec<String>,
}

impl CompareReport {
    /// The headline signal.
    pub fn headline_signal(&self) -> &SignalComparison {
        &self.signals[self.headline]
    }
}

/// Compares `replay` (the model) with `m` (the measurement); `n_gear` converts the load angle to
/// the motor angle for the position-periodic search.
///
/// The fit is MATLAB `compare`'s: 100 % when the model reproduces the measurement.
///
/// ```
/// # use servo_core::{record::Record, sim::{PlantSim, SensorConfig, Sensors}, Plant, PlantParams};
/// # fn simulate(plant: &Plant, seconds: f64) -> Record {
/// #     let (mut sim, mut sensors) = (PlantSim::new(plant, 1e-3).unwrap(), Sensors::new(SensorConfig::default()));
/// #     let mut rec = Record::default();
/// #     let (mut th, mut ia, mut uv) = (Vec::new(), Vec::new(), Vec::new());
/// #     for k in 0..(seconds * 1e3) as usize {
/// #         let u = [6.0, -3.0, 2.0, -7.0, 4.0][(k / 300) % 5];
/// #         let m = sensors.measure(sim.state());
/// #         rec.time_s.push(k as f64 * 1e-3);
/// #         th.push(m.theta_l_rad); ia.push(m.i_a_a); uv.push(u);
/// #         sim.step(u);
/// #     }
/// #     (rec.theta_l_rad, rec.i_a_a, rec.u_v) = (Some(th), Some(ia), Some(uv));
/// #     rec
/// # }
/// use servo_core::compare::{compare, replay, CompareOptions, Measured, ReplayMode};
/// let plant = Plant::from_params(PlantParams::TABLE2)?;
/// let log = simulate(&plant, 2.0);
/// let m = Measured::from_record(&log, plant.params.n, 50.0)?;
/// let model = replay(&plant, &m, ReplayMode::Speed, None)?;
/// let r = compare(&m, &model, plant.params.n, &CompareOptions::default());
/// assert!(r.headline_signal().figures.fit_percent > 90.0);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn compare(m: &Measured, replay: &Replay, n_gear: f64, opts: &CompareOptions) -> CompareReport {
    let n = m.len();
    let mode = replay.mode;
    let free_run = matches!(mode, ReplayMode::ClosedLoop | ReplayMode::Speed);
    let model_speed = if m.speed_derived && free_run {
        speed_from_position(&replay.theta_l_rad, m.dt_s, opts.speed_filter_hz)
    } else {
        replay.omega_l_rad_s.clone()
    };
    let mut signals = Vec::new();
    if let (Some(th), true) = (&m.theta_l_rad, mode != ReplayMode::Speed) {
        signals.push(SignalComparison::new(
            SignalKind::Position,
            th.clone(),
            replay.theta_l_rad.clone(),
        ));
    }
    signals.push(SignalComparison::new(
        SignalKind::Speed,
        m.omega_l_rad_s.clone(),
        model_speed,
    ));
    if let Some(i) = &m.i_a_a {
        signals.push(SignalComparison::new(
            SignalKind::Current,
            i.clone(),
            replay.i_a_a.clone(),
        ));
    }
    if mode == ReplayMode::ClosedLoop {
        signals.push(SignalComparison::new(
            SignalKind::Voltage,
            m.u_v.clone(),
            replay.u_v.clone(),
        ));
    }
    let headline = 0;
    let residual = signals[headline].residual();
    let wh = whiteness(&residual, opts.max_lag);
    let (input, input_name) = match (&m.ref_rad, mode) {
        (Some(r), ReplayMode::ClosedLoop) => (r.as_slice(), "ref"),
        _ => (m.u_v.as_slice(), "u"),
    };
    let input_xcorr = cross_correlation(&residual, input, opts.max_lag);
    let u_limit = opts.u_limit_v.or_else(|| detect_u_limit(&m.u_v));
    let classification = classify(&m.omega_l_rad_s, &m.u_v, u_limit, m.dt_s, &opts.regimes);
    let regimes = regime_stats(&residual, &classification);
    let mut periodic = Vec::new();
    if let Some(th) = &m.theta_l_rad {
        let ne = effective_samples(&residual);
        let th_m: Vec<f64> = th.iter().map(|v| v * n_gear).collect();
        if let Some(f) = best_harmonic(
            &residual,
            &th_m,
            AngleSource::Motor,
            opts.max_motor_harmonic,
            ne,
        ) {
            periodic.push(f);
        }
        if let Some(f) = best_harmonic(&residual, th, AngleSource::Load, opts.max_load_harmonic, ne)
        {
            periodic.push(f);
        }
    }
    let win = ((opts.window_s / m.dt_s) as usize).max(1);
    let worst = worst_windows(
        &residual,
        &m.time_s,
        &m.omega_l_rad_s,
        &m.u_v,
        &classification,
        win,
        opts.worst_count,
    );
    let mut r = CompareReport {
        mode,
        time_s: m.time_s.clone(),
        dt_s: m.dt_s,
        signals,
        headline,
        residual,
        whiteness: wh,
        input_xcorr,
        input_name,
        omega_l_rad_s: m.omega_l_rad_s.clone(),
        theta_l_rad: m.theta_l_rad.clone(),
        classification,
        regimes,
        periodic,
        worst_windows: worst,
        findings: Vec::new(),
    };
    r.findings = findings(&r, opts);
    let _ = n;
    r
}

/// Where a regime is, in words.
pub fn regime_phrase(r: Regime, c: &Classification, opts: &RegimeOptions) -> String {
    regime_phrase_on(r, c, opts, None)
}

/// [`regime_phrase`] on a linear axis of travel `metres_per_rad` [m/rad] (speeds in m/s).
pub fn regime_phrase_on(
    r: Regime,
    c: &Classification,
    opts: &RegimeOptions,
    metres_per_rad: Option<f64>,
) -> String {
    match (r, metres_per_rad) {
        (Regime::Standstill, Some(m)) => {
            return format!(
                "at standstill (|v_x| < {:.2} mm/s)",
                1e3 * m * c.standstill_rad_s
            )
        }
        (Regime::Acceleration, Some(m)) => {
            return format!(
                "while the motor accelerates or brakes (|a_x| > {:.3} m/s^2)",
                m * c.acceleration_rad_s2
            )
        }
        _ => {}
    }
    match r {
        Regime::Reversal => format!(
            "within {:.0} ms of a velocity reversal",
            1e3 * opts.reversal_window_s
        ),
        Regime::Standstill => format!(
            "at standstill (|omega_l| < {:.2} rad/s)",
            c.standstill_rad_s
        ),
        Regime::VoltageLimit => match c.u_limit_v {
            Some(l) => format!(
                "while the voltage is at its limit (|u| >= {:.2} V)",
                opts.limit_fraction * l
            ),
            None => String::from("while the voltage is at its limit"),
        },
        Regime::Acceleration => {
            format!(
                "while the motor accelerates or brakes (|alpha_l| > {:.0} rad/s^2)",
                c.acceleration_rad_s2
            )
        }
        Regime::ConstantSpeed => String::from("at roughly constant speed"),
    }
}

/// Formats a value with its unit, adding degrees for angles.
pub fn with_unit(v: f64, kind: SignalKind) -> String {
    with_unit_on(v, kind, None)
}

/// [`with_unit`] on a linear axis of travel `metres_per_rad` [m/rad]: a load position (given in
/// rad of the equivalent rotation) in m and mm, a load speed in m/s.
pub fn with_unit_on(v: f64, kind: SignalKind, metres_per_rad: Option<f64>) -> String {
    match (kind, metres_per_rad) {
        (SignalKind::Position, Some(m)) => {
            return format!("{:.4e} m ({:.4} mm)", v * m, v * m * 1e3)
        }
        (SignalKind::Speed, Some(m)) => return format!("{:.4e} m/s", v * m),
        _ => {}
    }
    match kind {
        SignalKind::Position => format!("{:.4} rad ({:.2} deg)", v, v * 180.0 / math::PI),
        SignalKind::Speed => format!("{v:.3} rad/s"),
        SignalKind::Current => format!("{v:.4} A"),
        SignalKind::Voltage => format!("{v:.3} V"),
    }
}

/// One line describing a worst window.
pub fn describe_window(w: &Window, r: &CompareReport, opts: &CompareOptions) -> String {
    let kind = r.headline_signal().kind;
    let time_pct = 100.0 * (w.end - w.start + 1) as f64 / r.time_s.len().max(1) as f64;
    let sign = if w.mean >= 0.0 { "above" } else { "below" };
    let lin = opts.metres_per_rad;
    let speed = match lin {
        Some(m) => format!(
            "{:.4} to {:.4} m/s",
            w.omega_min_rad_s * m,
            w.omega_max_rad_s * m
        ),
        None => format!("{:.2} to {:.2} rad/s", w.omega_min_rad_s, w.omega_max_rad_s),
    };
    format!(
        "t = {:.3}-{:.3} s: {:.1} % of the squared error in {:.1} % of the time; mostly {}; speed from {speed}, |u| up to {:.2} V; the measurement is {} the model by {} on average",
        w.t_start_s,
        w.t_end_s,
        w.error_share_pct,
        time_pct,
        regime_phrase_on(w.regime, &r.classification, &opts.regimes, lin),
        w.u_abs_max_v,
        sign,
        with_unit_on(libm::fabs(w.mean), kind, lin)
    )
}

fn mode_words(mode: ReplayMode, dt_s: f64) -> String {
    match mode {
        ReplayMode::ClosedLoop => String::from("closed-loop replay (the model with the logged reference and controller)"),
        ReplayMode::Speed => String::from("open-loop speed simulation (the model driven by the logged u; position would drift, so speed is compared)"),
        ReplayMode::KStep { k } => format!("{k}-step-ahead prediction ({:.0} ms from the measured state)", 1e3 * k as f64 * dt_s),
        ReplayMode::Segments { len } => format!("segment-wise simulation (re-initialised from the measured state every {:.3} s)", len as f64 * dt_s),
    }
}

fn findings(r: &CompareReport, opts: &CompareOptions) -> Vec<String> {
    let mut out = Vec::new();
    let h = r.headline_signal();
    let f = &h.figures;
    let lin = opts.metres_per_rad;
    let with_unit = |v: f64, k: SignalKind| with_unit_on(v, k, lin);
    let regime_phrase =
        |g: Regime, c: &Classification, o: &RegimeOptions| regime_phrase_on(g, c, o, lin);
    out.push(format!(
        "{}: {} fit {:.1} %, RMSE {}, max error {} at t = {:.3} s.",
        mode_words(r.mode, r.dt_s),
        h.kind.words(),
        f.fit_percent,
        with_unit(f.rmse, h.kind),
        with_unit(f.max_abs_error, h.kind),
        r.time_s.get(f.max_error_index).copied().unwrap_or(0.0)
    ));
    let mut reg: Vec<&RegimeStats> = r.regimes.iter().filter(|s| s.samples > 0).collect();
    reg.sort_by(|a, b| b.error_share_pct.total_cmp(&a.error_share_pct));
    let hot: Vec<&&RegimeStats> = reg
        .iter()
        .filter(|s| s.concentration >= 1.5 && s.error_share_pct >= 15.0)
        .collect();
    for s in &hot {
        let sign = if s.mean >= 0.0 { "above" } else { "below" };
        out.push(format!(
            "{:.0} % of the squared error sits {}, which covers {:.0} % of the time; there the measurement is on average {} the model by {}. Typical causes: {}.",
            s.error_share_pct,
            regime_phrase(s.regime, &r.classification, &opts.regimes),
            s.time_share_pct,
            sign,
            with_unit(libm::fabs(s.mean), h.kind),
            s.regime.suspects()
        ));
    }
    if hot.is_empty() && f.fit_percent.is_finite() {
        out.push(String::from(
            "The error is spread over the operating regimes roughly in proportion to their time: no local effect stands out; suspect a parameter (gain, inertia, viscous friction) rather than a missing mechanism.",
        ));
    }
    for p in r.periodic.iter().filter(|p| p.significant) {
        let what = periodic_suspects(match p.source {
            AngleSource::Motor => crate::effects::ActsOn::MotorTorque,
            AngleSource::Load => crate::effects::ActsOn::LoadTorque,
        });
        out.push(format!(
            "{:.0} % of the residual variance follows the {} angle with {} cycle(s) per revolution (amplitude {}): a sign of {}.",
            p.share_pct,
            p.source.name(),
            p.harmonic,
            with_unit(p.amplitude, h.kind),
            what
        ));
    }
    let w = &r.whiteness;
    if w.white {
        out.push(format!(
            "The residual is white (Ljung-Box Q = {:.1} with {} lags, p = {:.3}): what is left looks like noise.",
            w.ljung_box_q, w.ljung_box_dof, w.ljung_box_p
        ));
    } else {
        out.push(format!(
            "The residual is not white (Ljung-Box Q = {:.3e} with {} lags, p = {:.2e}; {} of {} autocorrelation lags outside the 99 % bounds, correlated over about {:.0} ms): the model misses dynamics, it is not just noise.",
            w.ljung_box_q,
            w.ljung_box_dof,
            w.ljung_box_p,
            w.lags_outside,
            w.ljung_box_dof,
            1e3 * w.correlation_lags as f64 * r.dt_s
        ));
    }
    let x = &r.input_xcorr;
    if x.lags_outside > 0 {
        out.push(format!(
            "The residual is correlated with the input `{}` (peak {:.2} at lag {:+} samples = {:+.0} ms; {} lags outside the 99 % bound): part of the response to {} is not modelled.",
            r.input_name,
            x.peak,
            x.peak_lag,
            1e3 * x.peak_lag as f64 * r.dt_s,
            x.lags_outside,
            r.input_name
        ));
    }
    out
}

/// The registered effects a residual periodic in the angle of `side` suggests (smooth torques
/// that depend on that angle only), in words.
fn periodic_suspects(side: crate::effects::ActsOn) -> String {
    let names: Vec<&str> = crate::effects::EffectKind::registered()
        .filter(|k| {
            k.sim_role() == crate::effects::SimRole::Smooth
                && k.acts_on() == side
                && k.model().depends_on_angle_only()
        })
        .map(|k| k.name())
        .collect();
    if names.is_empty() {
        String::from("a torque periodic in that angle")
    } else {
        format!("a torque periodic in that angle ({})", names.join(" or "))
    }
}
