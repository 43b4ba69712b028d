//! The closed-loop driver shared by `servo run`, `servo demo` and the identification
//! experiments: sample -> control -> apply, once per control period, on any [`Backend`].
//!
//! Each period k: `sample()` gives the sensors at t_k; the speed estimator updates; the program
//! gives the setpoint (a position reference for the PID, with optional feedforward from the
//! reference's speed and acceleration, an open-loop voltage, or a speed reference for the speed
//! controller [`SpeedLoop`], e.g. the identification staircase); the output is clipped to the
//! voltage limit and applied with `apply(u_k)`, held until t_{k+1}. Row k of the record and of
//! the log holds the measurements at t_k and u_k (servo's log convention). Behind a current or
//! duty drive ([`RunConfig::drive`]) u_k is the drive's command (i_ref [A], a duty), logged
//! under its own name, and the backend gets its equivalent chain's input.
//!
//! The pure parts (PID, speed estimator and controller, programs, step metrics) are in
//! servo-core; this module only drives them on a backend. Samples stream to a [`LogSink`]; a
//! [`RunMonitor`] may stop the loop early (`servo` does on Ctrl-C) and show its progress.
//! Whatever happens, the backend is stopped at 0 V and the sink flushed before
//! [`run_loop`] returns; on an error the returned [`RunError`] says whether 0 V was confirmed.
//!
//! ```
//! use servo_core::control::{PidConfig, PidGains, Program, Reference};
//! use servo_hw::run::{run_loop, RunConfig, StopReason};
//! use servo_hw::SimBackend;
//!
//! // The handout's Table 2 gearmotor on the simulator at T_s = 1 ms.
//! let plant = servo_core::Plant::from_params(servo_core::PlantParams::TABLE2)?;
//! let mut backend = SimBackend::new(&plant, Default::default(), 1e-3)?;
//! let pid = PidConfig::new(PidGains { kp: 7.0476, ki: 86.121, kd: 0.14418, tl_s: 1.0 / 150.0 }, 1e-3);
//! let program = Program::Position(Reference::parse("step:0.2")?);
//! // Two seconds of a 0.2 rad step; samples into a Vec (an McapLog is also a sink).
//! let mut samples = Vec::new();
//! let out = run_loop(&mut backend, &RunConfig::closed_loop(program, pid, 2.0), Some(&mut samples))?;
//! assert_eq!((out.stop, out.samples, samples.len()), (StopReason::Completed, 2000, 2000));
//! // The 60 deg phase-margin design: 20-30 % overshoot, settled (5 % band) well within 2 s.
//! let step = &out.summary.steps[0];
//! assert!((10.0..40.0).contains(&step.overshoot_pct), "{step:?}");
//! assert!(step.settling_time_s.is_some_and(|t| t < 1.0), "{step:?}");
//! let theta = out.record.theta_l_rad.as_ref().unwrap();
//! assert!((theta[1999] - 0.2).abs() < 0.01);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use crate::backend::{Backend, HwError};
use servo_core::control::program::Setpoint;
use servo_core::control::{
    ControlError, LoopCompensation, Pid, PidConfig, Program, SpeedEstimator, SpeedLoop,
    SpeedLoopConfig, SpeedProfile,
};
use servo_core::drive::{Drive, DriveKind};
use servo_core::metrics::{RunSummary, SummaryAccumulator};
use servo_core::record::Record;
use servo_io::{LoopMsg, McapLog};

pub mod compensation_check;
pub mod experiments;
pub mod logged;
pub mod step_cases;

/// The error a [`LogSink`] returns (any error type).
pub type SinkError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Where each sample goes while the loop runs (an MCAP log, a test's buffer, ...).
///
/// Contract, as [`run_loop`] calls it:
/// * [`LogSink::write_loop`] once per sample, in time order, after that sample's u was applied
///   to the backend; the message is only borrowed for the call. An error stops the run: the
///   backend is stopped at 0 V, then [`LogSink::flush`] is still called, and the run returns
///   [`RunError::Sink`] (inside [`RunError::Aborted`]).
/// * [`LogSink::flush`] exactly once, at the end of every run (completed, stopped early or
///   failed), after the backend was stopped: everything written so far must then be durable.
/// * The loop never finishes or closes the sink: a caller that wants a summary record or a
///   finished file does that after the run (see [`logged`]).
/// * Both methods are called from the loop's thread, between two control periods: a slow sink
///   delays the next sample (boards count that as missed deadlines).
pub trait LogSink {
    /// Records one sample.
    fn write_loop(&mut self, msg: &LoopMsg) -> Result<(), SinkError>;
    /// Makes everything written so far durable (called once, at the end of the run).
    fn flush(&mut self) -> Result<(), SinkError>;
}

impl LogSink for McapLog {
    fn write_loop(&mut self, msg: &LoopMsg) -> Result<(), SinkError> {
        Ok(McapLog::write_loop(self, msg)?)
    }
    fn flush(&mut self) -> Result<(), SinkError> {
        Ok(McapLog::flush(self)?)
    }
}

impl LogSink for Vec<LoopMsg> {
    fn write_loop(&mut self, msg: &LoopMsg) -> Result<(), SinkError> {
        self.push(*msg);
        Ok(())
    }
    fn flush(&mut self) -> Result<(), SinkError> {
        Ok(())
    }
}

/// Watches a run from the loop's thread (all methods have do-nothing defaults).
///
/// Contract, as [`run_loop_monitored`] calls it: [`RunMonitor::warning`] before the first
/// sample for each warning (also kept in [`RunOutput::warnings`]);
/// [`RunMonitor::stop_requested`] before each sample (true: the loop stops there with
/// [`StopReason::Interrupted`], the backend at 0 V); [`RunMonitor::sample`] after each sample
/// was applied and logged; [`RunMonitor::finished`] once after the last sample, before the
/// backend is stopped. Each call delays the loop by its own duration: keep them cheap.
pub trait RunMonitor {
    /// True to stop the run at the next sample (e.g. after Ctrl-C).
    fn stop_requested(&mut self) -> bool {
        false
    }
    /// After sample k at run time `t_s` [s] of `planned_s` [s].
    fn sample(&mut self, t_s: f64, planned_s: f64, backend: &dyn Backend) {
        let _ = (t_s, planned_s, backend);
    }
    /// A warning about the run's configuration (e.g. gains designed for another period).
    fn warning(&mut self, text: &str) {
        let _ = text;
    }
    /// After the last sample.
    fn finished(&mut self) {}
}

/// The monitor that watches nothing: the run goes to its end.
impl RunMonitor for () {}

/// What to run.
#[derive(Debug, Clone)]
pub struct RunConfig {
    /// Setpoints over time.
    pub program: Program,
    /// Run length [s]; the loop takes ceil(duration / T_s) samples.
    pub duration_s: f64,
    /// The PID (required when the program has closed-loop parts). Its output limits are
    /// narrowed to +-`u_limit_v`.
    pub pid: Option<PidConfig>,
    /// Feedforward from the reference's speed and acceleration and the compensation of the
    /// model's effects ([`LoopCompensation`]), added to the PID's output before the limit; an
    /// inverted input map (a dead band) acts on the whole command after the PID.
    pub feedforward: Option<LoopCompensation>,
    /// Limit of the driver input [V] (symmetric); the board's own limit applies on top.
    pub u_limit_v: f64,
    /// Bandwidth of the speed estimator [rad/s].
    pub speed_bandwidth_rad_s: f64,
    /// Keep every sample in [`RunOutput::record`]. Without it the record stays empty and the
    /// run's memory does not depend on its length: samples go only to the log sink and to the
    /// running summary ([`RunOutput::summary`]).
    pub keep_record: bool,
    /// The speed controller (required when the program has speed parts, [`Program::Speed`]).
    pub speed_loop: Option<SpeedLoopConfig>,
    /// The drive between the loop and the motor (a linear voltage amplifier by default). The
    /// controllers compute in the drive's equivalent chain ([`Drive::equivalent`]: volts, amps
    /// on a current drive), where `u_limit_v` bounds them; the drive receives, and the record
    /// and the log hold, its command: [`Drive::command_per_input`] times the controller's
    /// output (u [V], i_ref [A] or a duty), and an open-loop segment's value is that command,
    /// clipped at `u_limit_v`'s equivalent. The backend gets the command's chain input
    /// ([`Drive::input`]: the current clipped at its limit, the duty times the supply less the
    /// dead time), so that a simulator of the equivalent chain runs the drive, and a log of
    /// the run replays through the same [`Drive::input`]. A duty drive needs its supply
    /// (`v_supply_v`). A board takes volts: a serial run uses [`Drive::VOLTAGE`].
    pub drive: Drive,
}

impl RunConfig {
    /// A closed-loop run with defaults: no feedforward, 10 V limit, 50 Hz speed estimator,
    /// every sample kept.
    pub fn closed_loop(program: Program, pid: PidConfig, duration_s: f64) -> RunConfig {
        RunConfig {
            program,
            duration_s,
            pid: Some(pid),
            feedforward: None,
            u_limit_v: 10.0,
            speed_bandwidth_rad_s: DEFAULT_SPEED_BANDWIDTH_RAD_S,
            keep_record: true,
            speed_loop: None,
            drive: Drive::VOLTAGE,
        }
    }
    /// An open-loop run (voltage program) with the same defaults.
    pub fn open_loop(program: Program, duration_s: f64) -> RunConfig {
        RunConfig {
            pid: None,
            ..RunConfig::closed_loop(
                program,
                PidConfig::new(Default::default(), 1e-3),
                duration_s,
            )
        }
    }
    /// A speed-controlled run (the identification experiments) with the same defaults.
    pub fn speed(profile: SpeedProfile, speed_loop: SpeedLoopConfig) -> RunConfig {
        RunConfig {
            duration_s: profile.duration_s(),
            speed_loop: Some(speed_loop),
            ..RunConfig::open_loop(Program::Speed(profile), 1.0)
        }
    }
}

/// Default bandwidth of the speed estimator: 2 pi 50 Hz [rad/s].
pub const DEFAULT_SPEED_BANDWIDTH_RAD_S: f64 = 2.0 * std::f64::consts::PI * 50.0;

/// Why the loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// The whole duration ran.
    Completed,
    /// The monitor asked to stop ([`RunMonitor::stop_requested`]; Ctrl-C in `servo`).
    Interrupted,
}

impl StopReason {
    /// As the log's summary records it (`completed`, `interrupted by Ctrl-C`).
    pub fn describe(self) -> &'static str {
        match self {
            StopReason::Completed => "completed",
            StopReason::Interrupted => "interrupted by Ctrl-C",
        }
    }
}

/// What a run produced.
#[derive(Debug, Clone)]
pub struct RunOutput {
    /// Every sample: time, u (applied), theta_l, omega_l (estimate), i_a, ref (closed loop);
    /// empty unless [`RunConfig::keep_record`].
    pub record: Record,
    /// Per sample: the output was clipped at the limit (empty unless `keep_record`).
    pub saturated: Vec<bool>,
    /// The voltage limit in force [V].
    pub u_limit_v: f64,
    pub stop: StopReason,
    /// Samples that ran and the run time of the last one [s].
    pub samples: usize,
    pub last_time_s: f64,
    /// The figures of merit (5 % settling band), computed while the loop ran.
    pub summary: RunSummary,
    /// Warnings about the configuration (also given to the monitor before the run).
    pub warnings: Vec<String>,
}

impl RunOutput {
    /// The figures of merit (5 % settling band).
    pub fn summary(&self) -> RunSummary {
        self.summary.clone()
    }
    /// Run time that really ran [s] (samples x T_s; less than planned after Ctrl-C).
    pub fn ran_s(&self) -> f64 {
        self.summary.duration_s
    }
}

/// How stopping the board went after the loop failed ([`RunError::Aborted`]): `servo run`
/// claims 0 V only for [`StopOutcome::Acknowledged`] (the backend sent 0 V and the board
/// confirmed, or the simulator applied it).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum StopOutcome {
    #[error("run stopped, board at 0 V (acknowledged)")]
    Acknowledged,
    #[error("run stopped; 0 V NOT confirmed ({0})")]
    Failed(String),
}

/// Why a run failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RunError {
    /// The configuration cannot run (checked before anything moves).
    #[error("{0}")]
    Config(String),
    /// The PID configuration is invalid.
    #[error("controller")]
    Controller(#[source] ControlError),
    /// The backend failed to give sample `k`.
    #[error("sampling the board at sample {k}")]
    Sample {
        k: usize,
        #[source]
        source: Box<HwError>,
    },
    /// The backend failed to apply a voltage.
    #[error("applying u = {u_v} V at t = {t_s} s")]
    Apply {
        u_v: f64,
        t_s: f64,
        #[source]
        source: Box<HwError>,
    },
    /// A measurement or reference the controller cannot use.
    #[error("non-finite measurement or reference at t = {t_s} s (theta_l = {theta_l_rad} rad)")]
    NonFinite { t_s: f64, theta_l_rad: f64 },
    /// The log sink refused a sample.
    #[error("writing the log")]
    Sink(#[source] SinkError),
    /// The run went to its end (or was stopped) but stopping the board failed.
    #[error("stopping the board (0 V)")]
    Stop(#[source] Box<HwError>),
    /// The run went to its end but the log sink could not flush.
    #[error("flushing the log")]
    Flush(#[source] SinkError),
    /// The loop failed with `cause`; the board was then stopped with outcome `stop`.
    #[error("{stop}")]
    Aborted {
        stop: StopOutcome,
        #[source]
        cause: Box<RunError>,
    },
}

impl RunError {
    /// How stopping the board went, for an error that stopped a running loop.
    pub fn stop_outcome(&self) -> Option<&StopOutcome> {
        match self {
            RunError::Aborted { stop, .. } => Some(stop),
            _ => None,
        }
    }
}

/// Longest run the loop accepts, in samples (about 3.2 years at 1 kHz): beyond, the sample
/// index loses precision as a time.
pub const MAX_SAMPLES: f64 = 1e11;

/// Most samples a run keeps in memory when [`RunConfig::keep_record`] asks for every sample
/// (about 2.8 hours at 1 kHz, at most ~1 GB with the vectors' growth): beyond, the caller must
/// stream them (a [`LogSink`]) instead. Checked before the run starts.
pub const MAX_KEPT_SAMPLES: f64 = 1e7;

/// The PID configuration that actually runs on a loop at period `ts_s` [s] with the voltage
/// limit `u_limit_v` [V] (the tighter of the run's and the board's): `pid` with its output limits
/// narrowed to +-`u_limit_v` and its period set to the loop's.
pub fn effective_pid_config(pid: &PidConfig, u_limit_v: f64, ts_s: f64) -> PidConfig {
    let mut c = *pid;
    c.u_min_v = c.u_min_v.max(-u_limit_v);
    c.u_max_v = c.u_max_v.min(u_limit_v);
    if (c.ts_s - ts_s).abs() > 1e-9 * ts_s {
        c.ts_s = ts_s;
    }
    c
}

/// The PID `servo run --gains` runs from the gains file `gains` (named `label` in messages),
/// with the file's defaults (T_s, limit, anti-windup, discretisation) and its limits as in
/// force ([`effective_pid_config`]); and the voltage limit [V].
pub fn pid_from_gains(
    gains: &servo_io::gains_file::GainsFile,
    label: &str,
) -> Result<(PidConfig, f64), RunError> {
    let ctl = servo_io::controller::run_controller(
        Some((gains, label)),
        &servo_io::controller::PidOptions::default(),
        None,
        None,
    )
    .map_err(|e| RunError::Config(format!("{label}: {e:#}")))?;
    let pid = ctl
        .pid
        .ok_or_else(|| RunError::Config(format!("{label} give no controller")))?;
    Ok((
        effective_pid_config(&pid, ctl.u_limit_v, ctl.ts_s),
        ctl.u_limit_v,
    ))
}

/// Runs the loop on `backend` to its end, streaming samples to `sink`.
pub fn run_loop(
    backend: &mut dyn Backend,
    cfg: &RunConfig,
    sink: Option<&mut dyn LogSink>,
) -> Result<RunOutput, RunError> {
    run_loop_monitored(backend, cfg, sink, &mut ())
}

/// The error text of `e` and its sources, `: `-separated.
fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut src = e.source();
    while let Some(c) = src {
        s.push_str(&format!(": {c}"));
        src = c.source();
    }
    s
}

/// Runs the loop on `backend`, streaming samples to `sink`, watched by `monitor`.
pub fn run_loop_monitored(
    backend: &mut dyn Backend,
    cfg: &RunConfig,
    mut sink: Option<&mut dyn LogSink>,
    monitor: &mut dyn RunMonitor,
) -> Result<RunOutput, RunError> {
    let bad = |text: String| Err(RunError::Config(text));
    let info = backend.info();
    let ts = info.sample_period_s;
    if !(ts.is_finite() && ts > 0.0) {
        return bad(format!("backend reports a sample period of {ts} s"));
    }
    if !(cfg.duration_s.is_finite() && cfg.duration_s > 0.0) {
        return bad(format!("--duration must be > 0 s, got {}", cfg.duration_s));
    }
    if !(cfg.u_limit_v.is_finite() && cfg.u_limit_v > 0.0) {
        return bad(format!(
            "the voltage limit must be > 0 V, got {}",
            cfg.u_limit_v
        ));
    }
    let u_limit = cfg.u_limit_v.min(info.voltage_limit_v);
    let drive = &cfg.drive;
    // The drive's command per unit of the controller's output, and the supply of a duty drive.
    let per_input = drive.command_per_input();
    let v_supply_v = drive.v_supply_v.unwrap_or(f64::NAN);
    if drive.kind == DriveKind::Duty && !(v_supply_v.is_finite() && v_supply_v > 0.0) {
        return bad(format!(
            "a duty drive needs its supply voltage to run ([drive] v_supply_v), got {v_supply_v} V"
        ));
    }
    if !(per_input.is_finite() && per_input > 0.0) {
        return bad(format!(
            "the {} drive's command per controller output is {per_input}: check [drive]",
            drive.kind.name()
        ));
    }
    let command_limit = u_limit * per_input;
    let mut warnings = Vec::new();
    let mut pid = match (&cfg.pid, cfg.program.needs_controller()) {
        (Some(p), _) => {
            if (p.ts_s - ts).abs() > 1e-9 * ts {
                warnings.push(format!(
                    "the gains were designed for T_s = {} s but the loop runs at {} s; using the loop's period",
                    p.ts_s, ts
                ));
            }
            // A compensation's inverted input map (a dead band) and a compensated saturation
            // narrow the PID's own limit, so that its anti-windup sees the drive's bound.
            let pid_limit = cfg
                .feedforward
                .as_ref()
                .map_or(u_limit, |c| c.pid_limit_v(u_limit));
            Some(Pid::new(effective_pid_config(p, pid_limit, ts)).map_err(RunError::Controller)?)
        }
        (None, true) => return bad(
            "the program has closed-loop (position) parts but no controller was given (--gains)"
                .into(),
        ),
        (None, false) => None,
    };
    let mut speed_ctl = match (&cfg.speed_loop, cfg.program.needs_speed_loop()) {
        (Some(c), _) => Some(SpeedLoop::new(*c, ts)),
        (None, true) => {
            return bad("the program has speed-controlled parts but no speed controller".into())
        }
        (None, false) => None,
    };
    let n_f = ((cfg.duration_s / ts) - 1e-9).ceil().max(1.0);
    if n_f > MAX_SAMPLES {
        return bad(format!(
            "--duration {} s at T_s = {ts} s is {n_f:e} samples; servo runs at most {MAX_SAMPLES:e}",
            cfg.duration_s
        ));
    }
    if cfg.keep_record && n_f > MAX_KEPT_SAMPLES {
        return bad(format!(
            "keeping every sample in memory (for a CSV or a plot) of {} s at T_s = {ts} s is \
             {n_f:e} samples, more than the {MAX_KEPT_SAMPLES:e} servo keeps (~1 GB); log to \
             MCAP instead (it streams to disk) and convert with `servo export`",
            cfg.duration_s
        ));
    }
    for w in &warnings {
        monitor.warning(w);
    }
    let n = n_f as usize;
    // Memory grows with the run only when the caller keeps the samples; then it grows as they
    // come (no allocation sized by the planned duration).
    let keep = cfg.keep_record;
    let some_if = |keep: bool| keep.then(Vec::new);
    // The log signal of the command (u for a current drive commanded by an analog voltage).
    let command_is = |kind: DriveKind| drive.command_kind() == kind;
    // The command in the log field of `kind` (null in the other drives' fields).
    let only_for = |kind: DriveKind, u: f64| if command_is(kind) { u } else { f64::NAN };
    let mut rec = Record {
        source: format!("servo run on {}", info.firmware),
        time_s: Vec::new(),
        u_v: some_if(keep && command_is(DriveKind::Voltage)),
        i_ref_a: some_if(keep && command_is(DriveKind::Current)),
        duty: some_if(keep && command_is(DriveKind::Duty)),
        theta_l_rad: some_if(keep),
        omega_l_rad_s: some_if(keep),
        i_a_a: some_if(keep),
        ref_rad: some_if(keep),
        ..Record::default()
    };
    let mut saturated = Vec::new();
    let mut acc = SummaryAccumulator::new(ts, 0.05);
    let mut last_t = 0.0;
    let mut any_ref = false;
    let mut speed = SpeedEstimator::new(cfg.speed_bandwidth_rad_s, ts);
    let mut stop = StopReason::Completed;
    let mut was_open_loop = false;
    let result: Result<(), RunError> = (|| {
        for k in 0..n {
            if monitor.stop_requested() {
                stop = StopReason::Interrupted;
                break;
            }
            let s = backend.sample().map_err(|source| RunError::Sample {
                k,
                source: Box::new(source),
            })?;
            // Run time from the sample index: the board clock may start anywhere.
            let t = k as f64 * ts;
            let omega = speed.update(s.theta_l_rad);
            let mut w_ref = f64::NAN;
            let (u, r, terms, sat) = match cfg.program.at(t) {
                Setpoint::Position(r) => {
                    let pid = pid.as_mut().ok_or_else(|| {
                        RunError::Config("closed-loop segment without a controller".into())
                    })?;
                    if was_open_loop {
                        pid.reset();
                        was_open_loop = false;
                    }
                    let comp = cfg.feedforward.as_ref();
                    let ff = comp.map_or(0.0, |c| {
                        // The reference read ahead by the compensated delays (same segment).
                        let ahead = match c.lead_s() {
                            l if l > 0.0 => match cfg.program.at(t + l) {
                                Setpoint::Position(ra) => ra,
                                _ => r,
                            },
                            _ => r,
                        };
                        c.feedforward(&ahead, t, s.theta_l_rad, omega).total_v
                    });
                    let o = pid.update(r.pos_rad, s.theta_l_rad, ff);
                    if o.invalid_input {
                        return Err(RunError::NonFinite {
                            t_s: t,
                            theta_l_rad: s.theta_l_rad,
                        });
                    }
                    let u = comp.map_or(o.u_v, |c| c.command_v(o.u_v, t, u_limit));
                    // ff_v: the feedforward plus what an inverted input map added after the
                    // PID (the replay adds it as logged).
                    let ff_v = o.ff_v + (u - o.u_v);
                    let sat = o.saturated || (u != o.u_v && u.abs() >= u_limit);
                    (u * per_input, r.pos_rad, [o.p_v, o.i_v, o.d_v, ff_v], sat)
                }
                Setpoint::Voltage { u_v: command } => {
                    // Open loop: the drive's command itself.
                    was_open_loop = true;
                    let u = command.clamp(-command_limit, command_limit);
                    (u, f64::NAN, [0.0, 0.0, 0.0, 0.0], u != command)
                }
                Setpoint::Speed {
                    omega_l_rad_s,
                    alpha_l_rad_s2,
                } => {
                    was_open_loop = true;
                    let c = speed_ctl.as_mut().ok_or_else(|| {
                        RunError::Config("speed segment without a speed controller".into())
                    })?;
                    let o = c.update(omega_l_rad_s, alpha_l_rad_s2, omega, u_limit);
                    w_ref = omega_l_rad_s;
                    let u = o.u_v * per_input;
                    (u, f64::NAN, [o.p_v, o.i_v, 0.0, o.ff_v], o.saturated)
                }
            };
            // `u` is the drive's command; the backend gets its chain's input (u on a voltage
            // drive).
            let chain_in = drive.input(u, v_supply_v);
            backend.apply(chain_in).map_err(|source| RunError::Apply {
                u_v: chain_in,
                t_s: t,
                source: Box::new(source),
            })?;
            acc.push(t, r, s.theta_l_rad, u, sat);
            last_t = t;
            any_ref |= !r.is_nan();
            if keep {
                rec.time_s.push(t);
                push(&mut rec.u_v, u);
                push(&mut rec.i_ref_a, u);
                push(&mut rec.duty, u);
                push(&mut rec.theta_l_rad, s.theta_l_rad);
                push(&mut rec.omega_l_rad_s, omega);
                push(&mut rec.i_a_a, s.i_a_a);
                push(&mut rec.ref_rad, r);
                saturated.push(sat);
            }
            if let Some(sink) = sink.as_deref_mut() {
                sink.write_loop(&LoopMsg {
                    time_s: t,
                    ref_rad: r,
                    theta_l_rad: s.theta_l_rad,
                    omega_l_rad_s: omega,
                    err_rad: r - s.theta_l_rad,
                    u_v: only_for(DriveKind::Voltage, u),
                    i_ref_a: only_for(DriveKind::Current, u),
                    duty: only_for(DriveKind::Duty, u),
                    ff_v: terms[3],
                    p_v: terms[0],
                    i_v: terms[1],
                    d_v: terms[2],
                    i_a_a: s.i_a_a,
                    saturated: sat,
                    ref_omega_l_rad_s: w_ref,
                })
                .map_err(RunError::Sink)?;
            }
            monitor.sample(t, n as f64 * ts, &*backend);
        }
        Ok(())
    })();
    monitor.finished();
    // Always: 0 V, then make the log durable.
    let stopped = backend.stop();
    let flushed = sink.map_or(Ok(()), |s| s.flush());
    if let Err(e) = result {
        return Err(RunError::Aborted {
            stop: match stopped {
                Ok(()) => StopOutcome::Acknowledged,
                Err(se) => StopOutcome::Failed(format!("stopping the board (0 V): {}", chain(&se))),
            },
            cause: Box::new(e),
        });
    }
    stopped.map_err(|e| RunError::Stop(Box::new(e)))?;
    flushed.map_err(RunError::Flush)?;
    if !any_ref {
        rec.ref_rad = None;
    }
    Ok(RunOutput {
        record: rec,
        saturated,
        u_limit_v: u_limit,
        stop,
        samples: acc.samples(),
        last_time_s: last_t,
        summary: RunSummary {
            command: drive.command_kind(),
            ..acc.finish()
        },
        warnings,
    })
}

#[inline]
fn push(v: &mut Option<Vec<f64>>, x: f64) {
    if let Some(v) = v {
        v.push(x);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BoardInfo, Sample};
    use servo_core::control::{PidConfig, Reference};

    /// A board whose angle is the integral of u (theta' = u), recording what it was told.
    struct Integrator {
        theta: f64,
        k: u64,
        applied: Vec<f64>,
        stopped: u32,
        fail_at: Option<u64>,
    }

    impl Backend for Integrator {
        fn info(&self) -> BoardInfo {
            BoardInfo {
                firmware: "test",
                counts_per_rev: 0,
                voltage_limit_v: 5.0,
                sample_period_s: 1e-3,
            }
        }
        fn sample(&mut self) -> Result<Sample, HwError> {
            if Some(self.k) == self.fail_at {
                return Err(HwError::Timeout { timeout_ms: 10 });
            }
            Ok(Sample {
                time_s: self.k as f64 * 1e-3,
                theta_l_rad: self.theta,
                ..Sample::default()
            })
        }
        fn apply(&mut self, u_v: f64) -> Result<(), HwError> {
            self.applied.push(u_v);
            self.theta += u_v * 1e-3;
            self.k += 1;
            Ok(())
        }
        fn stop(&mut self) -> Result<(), HwError> {
            self.stopped += 1;
            Ok(())
        }
    }

    fn board() -> Integrator {
        Integrator {
            theta: 0.0,
            k: 0,
            applied: Vec::new(),
            stopped: 0,
            fail_at: None,
        }
    }

    #[test]
    fn row_convention_limits_and_p_control() {
        let mut b = board();
        let pid = PidConfig::new(
            servo_core::control::PidGains {
                kp: 20.0,
                ki: 0.0,
                kd: 0.0,
                tl_s: 0.0,
            },
            1e-3,
        );
        let cfg = RunConfig::closed_loop(Program::Position(Reference::step(1.0, 0.0)), pid, 0.5);
        let mut msgs: Vec<LoopMsg> = Vec::new();
        let out = run_loop(&mut b, &cfg, Some(&mut msgs)).unwrap();
        assert_eq!(out.record.len(), 500);
        assert_eq!(msgs.len(), 500);
        assert_eq!(b.stopped, 1);
        // Board limit 5 V < RunConfig's 10 V: the tighter one wins.
        assert_eq!(out.u_limit_v, 5.0);
        let u = out.record.u_v.as_ref().unwrap();
        let th = out.record.theta_l_rad.as_ref().unwrap();
        assert_eq!(u[0], 5.0);
        assert!(out.saturated[0] && !out.saturated[499]);
        // Row k: u_k applied after theta_k was measured; theta_{k+1} = theta_k + u_k T_s.
        for k in 0..499 {
            assert_eq!(u[k], b.applied[k]);
            assert!((th[k + 1] - th[k] - u[k] * 1e-3).abs() < 1e-15);
            assert_eq!(msgs[k].u_v, u[k]);
            assert_eq!(msgs[k].p_v, 20.0 * (1.0 - th[k]));
        }
        // Unsaturated P loop on an integrator: first-order, tau = 1/20 s.
        assert!((th[499] - 1.0).abs() < 1e-3, "{}", th[499]);
        // The speed estimate follows the true speed (u) with the tracking loop's lag of about
        // 2/w_b = 6.4 ms.
        let w = out.record.omega_l_rad_s.as_ref().unwrap();
        assert!(
            (w[300] - u[294]).abs() < 0.03 * u[294],
            "{} vs {}",
            w[300],
            u[294]
        );
    }

    #[test]
    fn open_loop_needs_no_controller_and_error_stops_the_board() {
        let mut b = board();
        let p = Program::open_loop(Reference::step(7.0, 0.0), 0.1).unwrap();
        let cfg = RunConfig::open_loop(p.clone(), 0.2);
        let out = run_loop(&mut b, &cfg, None).unwrap();
        let u = out.record.u_v.as_ref().unwrap();
        assert_eq!(u[10], 5.0); // clipped at the board's 5 V
        assert!(out.saturated[10]);
        assert_eq!(u[150], 0.0); // after the program: 0 V
        assert!(out.record.ref_rad.is_none());
        // A closed-loop program without a controller is refused before anything moves.
        let cfg2 = RunConfig {
            pid: None,
            ..RunConfig::closed_loop(
                Program::Position(Reference::step(1.0, 0.0)),
                PidConfig::new(Default::default(), 1e-3),
                1.0,
            )
        };
        let mut b2 = board();
        assert!(chain(&run_loop(&mut b2, &cfg2, None).unwrap_err()).contains("--gains"));
        assert!(b2.applied.is_empty());
        // A board error mid-run: the board is stopped, the error says where.
        let mut b3 = Integrator {
            fail_at: Some(42),
            ..board()
        };
        let mut msgs: Vec<LoopMsg> = Vec::new();
        let e = run_loop(&mut b3, &cfg, Some(&mut msgs)).unwrap_err();
        assert_eq!(e.stop_outcome(), Some(&StopOutcome::Acknowledged));
        let e = chain(&e);
        assert!(e.contains("sample 42") && e.contains("10 ms"), "{e}");
        assert_eq!(b3.stopped, 1);
        assert_eq!(msgs.len(), 42);
    }

    /// Stops after `after` samples and counts what it was told.
    #[derive(Default)]
    struct Stopper {
        after: usize,
        seen: usize,
        warnings: Vec<String>,
        finished: u32,
    }

    impl RunMonitor for Stopper {
        fn stop_requested(&mut self) -> bool {
            self.seen >= self.after
        }
        fn sample(&mut self, _t_s: f64, planned_s: f64, _backend: &dyn Backend) {
            assert!((planned_s - 0.5).abs() < 1e-12);
            self.seen += 1;
        }
        fn warning(&mut self, text: &str) {
            self.warnings.push(text.to_string());
        }
        fn finished(&mut self) {
            self.finished += 1;
        }
    }

    #[test]
    fn a_monitor_stops_the_run_and_hears_the_warnings() {
        let mut b = board();
        // Gains designed for 2 ms on a 1 ms board: a warning, the loop's period wins.
        let pid = PidConfig::new(
            servo_core::control::PidGains {
                kp: 5.0,
                ..Default::default()
            },
            2e-3,
        );
        let cfg = RunConfig::closed_loop(Program::Position(Reference::step(1.0, 0.0)), pid, 0.5);
        let mut mon = Stopper {
            after: 120,
            ..Stopper::default()
        };
        let mut msgs: Vec<LoopMsg> = Vec::new();
        let out = run_loop_monitored(&mut b, &cfg, Some(&mut msgs), &mut mon).unwrap();
        assert_eq!(out.stop, StopReason::Interrupted);
        assert_eq!((out.samples, msgs.len(), b.applied.len()), (120, 120, 120));
        assert!((out.last_time_s - 0.119).abs() < 1e-12);
        assert_eq!(b.stopped, 1);
        assert_eq!(mon.finished, 1);
        assert_eq!(mon.warnings.len(), 1);
        assert!(
            mon.warnings[0].contains("T_s = 0.002 s"),
            "{:?}",
            mon.warnings
        );
        assert_eq!(out.warnings, mon.warnings);
    }
}
