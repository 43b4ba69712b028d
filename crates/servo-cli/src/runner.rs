//! The closed-loop driver shared by `servo run`, `servo demo` and the identification
//! experiments: sample -> control -> apply, once per control period, on any
//! [`servo_hw::Backend`].
//!
//! Each period k: `sample()` gives the sensors at t_k; the speed estimator updates; the program
//! gives the setpoint (a position reference for the PID, with optional feedforward from the
//! reference's speed and acceleration, an open-loop voltage, or a speed reference for the speed
//! controller [`SpeedLoop`], e.g. the identification staircase); the output is clipped to the
//! voltage limit and applied with `apply(u_k)`, held until t_{k+1}. Row k of the record and of
//! the log holds the measurements at t_k and u_k (servo's log convention).
//!
//! With [`RunConfig::progress`], long runs show their progress on stderr: run time elapsed and
//! left, and the missed deadlines of a board.
//!
//! Ctrl-C (with [`RunConfig::handle_ctrlc`]): the loop stops at the next sample, the backend is
//! stopped at 0 V, the log is flushed and the output says [`StopReason::Interrupted`]; a second
//! Ctrl-C exits at once with status 130. On a backend error the backend is also stopped and the
//! log flushed before the error is returned.

pub mod controller;
pub mod program;
pub mod speed;
pub mod summary;

pub use program::{Program, Setpoint, SpeedProfile};
pub use speed::{SpeedEstimator, SpeedLoop, SpeedLoopConfig};
pub use summary::{RunSummary, StepMetrics};

use crate::io::{LoopMsg, McapLog};
use anyhow::{bail, Context};
use servo_core::control::{Feedforward, Pid, PidConfig};
use servo_core::record::Record;
use servo_hw::Backend;
use std::sync::atomic::{AtomicBool, Ordering};

/// Where each sample goes while the loop runs (an MCAP log, a test's buffer, ...).
pub trait LogSink {
    /// Records one sample.
    fn write_loop(&mut self, msg: &LoopMsg) -> anyhow::Result<()>;
    /// Makes everything written so far durable (called on stop, error and Ctrl-C).
    fn flush(&mut self) -> anyhow::Result<()>;
}

impl LogSink for McapLog {
    fn write_loop(&mut self, msg: &LoopMsg) -> anyhow::Result<()> {
        Ok(McapLog::write_loop(self, msg)?)
    }
    fn flush(&mut self) -> anyhow::Result<()> {
        Ok(McapLog::flush(self)?)
    }
}

impl LogSink for Vec<LoopMsg> {
    fn write_loop(&mut self, msg: &LoopMsg) -> anyhow::Result<()> {
        self.push(*msg);
        Ok(())
    }
    fn flush(&mut self) -> anyhow::Result<()> {
        Ok(())
    }
}

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
    /// Feedforward from the reference's speed and acceleration, added before the limit.
    pub feedforward: Option<Feedforward>,
    /// Limit of the driver input [V] (symmetric); the board's own limit applies on top.
    pub u_limit_v: f64,
    /// Bandwidth of the speed estimator [rad/s].
    pub speed_bandwidth_rad_s: f64,
    /// Stop cleanly on Ctrl-C (installs a process-wide handler once).
    pub handle_ctrlc: bool,
    /// Keep every sample in [`RunOutput::record`]. Without it the record stays empty and the
    /// run's memory does not depend on its length: samples go only to the log sink and to the
    /// running summary ([`RunOutput::summary`]).
    pub keep_record: bool,
    /// The speed controller (required when the program has speed parts, [`Program::Speed`]).
    pub speed_loop: Option<SpeedLoopConfig>,
    /// Live progress on stderr (None: silent).
    pub progress: Option<Progress>,
}

impl RunConfig {
    /// A closed-loop run with defaults: no feedforward, 10 V limit, 50 Hz speed estimator,
    /// Ctrl-C handled.
    pub fn closed_loop(program: Program, pid: PidConfig, duration_s: f64) -> RunConfig {
        RunConfig {
            program,
            duration_s,
            pid: Some(pid),
            feedforward: None,
            u_limit_v: 10.0,
            speed_bandwidth_rad_s: DEFAULT_SPEED_BANDWIDTH_RAD_S,
            handle_ctrlc: true,
            keep_record: true,
            speed_loop: None,
            progress: None,
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

/// When and how [`run_loop`] shows its progress on stderr.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    /// What runs (`servo run`, `identify_friction`, ...), the start of each line.
    pub label: String,
    /// Wall-clock time between two updates [s]; the first comes after one interval, so short
    /// runs print nothing.
    pub interval_s: f64,
    /// Rewrite one line in place (a terminal) instead of printing a line per update (a log).
    pub in_place: bool,
}

/// How `--progress` is chosen on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ProgressMode {
    /// When stderr is a terminal: one line updated in place twice a second.
    #[default]
    Auto,
    /// Always: in place on a terminal, else a line every 2 s (for logs and CI).
    Always,
    /// Never.
    Never,
}

impl Progress {
    /// The progress `mode` asks for, labelled `label` (None: silent).
    pub fn from_mode(mode: ProgressMode, label: &str) -> Option<Progress> {
        use std::io::IsTerminal;
        let tty = std::io::stderr().is_terminal();
        let show = match mode {
            ProgressMode::Auto => tty,
            ProgressMode::Always => true,
            ProgressMode::Never => false,
        };
        show.then(|| Progress {
            label: label.to_string(),
            interval_s: if tty { 0.5 } else { 2.0 },
            in_place: tty,
        })
    }

    /// The text of one update: run time elapsed and planned [s], time left, missed deadlines
    /// (None: the backend has no deadlines).
    pub fn line(&self, t_s: f64, total_s: f64, missed: Option<u64>) -> String {
        let mut s = format!(
            "{}: {t_s:.1} s of {total_s:.1} s, {:.1} s left",
            self.label,
            (total_s - t_s).max(0.0)
        );
        if let Some(m) = missed {
            s.push_str(&format!(
                ", {m} missed deadline{}",
                if m == 1 { "" } else { "s" }
            ));
        }
        s
    }
}

/// The progress display of one run.
struct ProgressState {
    cfg: Progress,
    start: std::time::Instant,
    next_s: f64,
    shown: bool,
}

impl ProgressState {
    fn tick(&mut self, t_s: f64, total_s: f64, backend: &dyn Backend) {
        let wall = self.start.elapsed().as_secs_f64();
        if wall < self.next_s {
            return;
        }
        self.next_s = wall + self.cfg.interval_s;
        let line = self.cfg.line(t_s, total_s, backend.missed_deadlines());
        if self.cfg.in_place {
            eprint!("\r{line}\x1b[K");
        } else {
            eprintln!("{line}");
        }
        self.shown = true;
    }
    fn finish(&self) {
        if self.shown && self.cfg.in_place {
            eprint!("\r\x1b[K");
        }
    }
}

/// Why the loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// The whole duration ran.
    Completed,
    /// Ctrl-C.
    Interrupted,
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

/// The error of a run stopped by Ctrl-C (after the board was stopped and the logs closed):
/// `servo` exits with status 130 on it, like a shell.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("interrupted by Ctrl-C at t = {at_s:.3} s")]
pub struct Interrupted {
    /// Run time of the last sample [s].
    pub at_s: f64,
}

/// How stopping the board went after the loop failed, attached as context to the loop's error:
/// `servo run` claims 0 V only for [`StopOutcome::Acknowledged`] (the backend sent 0 V and the
/// board confirmed, or the simulator applied it).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StopOutcome {
    #[error("run stopped, board at 0 V (acknowledged)")]
    Acknowledged,
    #[error("run stopped; 0 V NOT confirmed ({0})")]
    Failed(String),
}

/// Longest run the loop accepts, in samples (about 3.2 years at 1 kHz): beyond, the sample
/// index loses precision as a time.
pub const MAX_SAMPLES: f64 = 1e11;

static INTERRUPTED: AtomicBool = AtomicBool::new(false);
static HANDLER: std::sync::Once = std::sync::Once::new();

/// Installs the Ctrl-C handler (once per process): the first Ctrl-C asks running loops to stop,
/// the second exits with status 130.
pub fn install_ctrlc_handler() {
    HANDLER.call_once(|| {
        let r = ctrlc::set_handler(|| {
            if INTERRUPTED.swap(true, Ordering::SeqCst) {
                eprintln!("\nsecond Ctrl-C: exiting without cleanup");
                std::process::exit(130);
            }
            eprintln!("\nCtrl-C: stopping the loop (0 V) and closing the log; press again to exit at once");
        });
        if let Err(e) = r {
            eprintln!("warning: cannot install the Ctrl-C handler ({e}); Ctrl-C will kill the run without closing the log");
        }
    });
}

/// True once Ctrl-C was pressed.
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

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

/// Runs the loop on `backend`, streaming samples to `sink`.
pub fn run_loop(
    backend: &mut dyn Backend,
    cfg: &RunConfig,
    mut sink: Option<&mut dyn LogSink>,
) -> anyhow::Result<RunOutput> {
    let info = backend.info();
    let ts = info.sample_period_s;
    if !(ts.is_finite() && ts > 0.0) {
        bail!("backend reports a sample period of {ts} s");
    }
    if !(cfg.duration_s.is_finite() && cfg.duration_s > 0.0) {
        bail!("--duration must be > 0 s, got {}", cfg.duration_s);
    }
    if !(cfg.u_limit_v.is_finite() && cfg.u_limit_v > 0.0) {
        bail!("the voltage limit must be > 0 V, got {}", cfg.u_limit_v);
    }
    let u_limit = cfg.u_limit_v.min(info.voltage_limit_v);
    let mut pid = match (&cfg.pid, cfg.program.needs_controller()) {
        (Some(p), _) => {
            if (p.ts_s - ts).abs() > 1e-9 * ts {
                eprintln!(
                    "warning: the gains were designed for T_s = {} s but the loop runs at {} s; using the loop's period",
                    p.ts_s, ts
                );
            }
            Some(Pid::new(effective_pid_config(p, u_limit, ts)).context("controller")?)
        }
        (None, true) => bail!(
            "the program has closed-loop (position) parts but no controller was given (--gains)"
        ),
        (None, false) => None,
    };
    let mut speed_ctl = match (&cfg.speed_loop, cfg.program.needs_speed_loop()) {
        (Some(c), _) => Some(SpeedLoop::new(*c, ts)),
        (None, true) => bail!("the program has speed-controlled parts but no speed controller"),
        (None, false) => None,
    };
    let mut progress = cfg.progress.clone().map(|p| ProgressState {
        next_s: p.interval_s,
        cfg: p,
        start: std::time::Instant::now(),
        shown: false,
    });
    if cfg.handle_ctrlc {
        install_ctrlc_handler();
    }
    let n_f = ((cfg.duration_s / ts) - 1e-9).ceil().max(1.0);
    if n_f > MAX_SAMPLES {
        bail!(
            "--duration {} s at T_s = {ts} s is {n_f:e} samples; servo runs at most {MAX_SAMPLES:e}",
            cfg.duration_s
        );
    }
    let n = n_f as usize;
    // Memory grows with the run only when the caller keeps the samples; then it grows as they
    // come (no allocation sized by the planned duration).
    let keep = cfg.keep_record;
    let some_if = |keep: bool| keep.then(Vec::new);
    let mut rec = Record {
        source: format!("servo run on {}", info.firmware),
        time_s: Vec::new(),
        u_v: some_if(keep),
        theta_l_rad: some_if(keep),
        omega_l_rad_s: some_if(keep),
        i_a_a: some_if(keep),
        ref_rad: some_if(keep),
        ..Record::default()
    };
    let mut saturated = Vec::new();
    let mut acc = summary::SummaryAccumulator::new(ts, 0.05);
    let mut last_t = 0.0;
    let mut any_ref = false;
    let mut speed = SpeedEstimator::new(cfg.speed_bandwidth_rad_s, ts);
    let mut stop = StopReason::Completed;
    let mut was_open_loop = false;
    let result: anyhow::Result<()> = (|| {
        for k in 0..n {
            if cfg.handle_ctrlc && interrupted() {
                stop = StopReason::Interrupted;
                break;
            }
            let s = backend
                .sample()
                .with_context(|| format!("sampling the board at sample {k}"))?;
            // Run time from the sample index: the board clock may start anywhere.
            let t = k as f64 * ts;
            let omega = speed.update(s.theta_l_rad);
            let mut w_ref = f64::NAN;
            let (u, r, terms, sat) = match cfg.program.at(t) {
                Setpoint::Position(r) => {
                    let pid = pid
                        .as_mut()
                        .context("closed-loop segment without a controller")?;
                    if was_open_loop {
                        pid.reset();
                        was_open_loop = false;
                    }
                    let ff = cfg
                        .feedforward
                        .as_ref()
                        .map_or(0.0, |f| f.for_sample(&r).total_v);
                    let o = pid.update(r.pos_rad, s.theta_l_rad, ff);
                    if o.invalid_input {
                        bail!(
                            "non-finite measurement or reference at t = {t} s (theta_l = {} rad)",
                            s.theta_l_rad
                        );
                    }
                    (o.u_v, r.pos_rad, [o.p_v, o.i_v, o.d_v, o.ff_v], o.saturated)
                }
                Setpoint::Voltage { u_v } => {
                    was_open_loop = true;
                    let u = u_v.clamp(-u_limit, u_limit);
                    (u, f64::NAN, [0.0, 0.0, 0.0, 0.0], u != u_v)
                }
                Setpoint::Speed {
                    omega_l_rad_s,
                    alpha_l_rad_s2,
                } => {
                    was_open_loop = true;
                    let c = speed_ctl
                        .as_mut()
                        .context("speed segment without a speed controller")?;
                    let o = c.update(omega_l_rad_s, alpha_l_rad_s2, omega, u_limit);
                    w_ref = omega_l_rad_s;
                    (o.u_v, f64::NAN, [o.p_v, o.i_v, 0.0, o.ff_v], o.saturated)
                }
            };
            backend
                .apply(u)
                .with_context(|| format!("applying u = {u} V at t = {t} s"))?;
            acc.push(t, r, s.theta_l_rad, u, sat);
            last_t = t;
            any_ref |= !r.is_nan();
            if keep {
                rec.time_s.push(t);
                push(&mut rec.u_v, u);
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
                    u_v: u,
                    ff_v: terms[3],
                    p_v: terms[0],
                    i_v: terms[1],
                    d_v: terms[2],
                    i_a_a: s.i_a_a,
                    saturated: sat,
                    ref_omega_l_rad_s: w_ref,
                })?;
            }
            if let Some(p) = progress.as_mut() {
                p.tick(t, n as f64 * ts, &*backend);
            }
        }
        Ok(())
    })();
    if let Some(p) = &progress {
        p.finish();
    }
    // Always: 0 V, then make the log durable.
    let stopped = backend.stop().context("stopping the board (0 V)");
    let flushed = sink.map_or(Ok(()), |s| s.flush());
    if let Err(e) = result {
        return Err(match stopped {
            Ok(()) => e.context(StopOutcome::Acknowledged),
            Err(se) => e.context(StopOutcome::Failed(format!("{se:#}"))),
        });
    }
    stopped?;
    flushed?;
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
        summary: acc.finish(),
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
    use servo_hw::{BoardInfo, HwError, Sample};

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
        let cfg = RunConfig {
            handle_ctrlc: false,
            ..RunConfig::closed_loop(
                Program::Position(servo_core::control::Reference::step(1.0, 0.0)),
                pid,
                0.5,
            )
        };
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
        let p = Program::open_loop(servo_core::control::Reference::step(7.0, 0.0), 0.1).unwrap();
        let cfg = RunConfig {
            handle_ctrlc: false,
            ..RunConfig::open_loop(p.clone(), 0.2)
        };
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
                Program::Position(servo_core::control::Reference::step(1.0, 0.0)),
                PidConfig::new(Default::default(), 1e-3),
                1.0,
            )
        };
        let mut b2 = board();
        assert!(format!("{:#}", run_loop(&mut b2, &cfg2, None).unwrap_err()).contains("--gains"));
        assert!(b2.applied.is_empty());
        // A board error mid-run: the board is stopped, the error says where.
        let mut b3 = Integrator {
            fail_at: Some(42),
            ..board()
        };
        let mut msgs: Vec<LoopMsg> = Vec::new();
        let e = format!(
            "{:#}",
            run_loop(&mut b3, &cfg, Some(&mut msgs)).unwrap_err()
        );
        assert!(e.contains("sample 42") && e.contains("10 ms"), "{e}");
        assert_eq!(b3.stopped, 1);
        assert_eq!(msgs.len(), 42);
    }
}
