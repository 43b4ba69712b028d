//! `servo run`: the position loop on the simulator (default) or a board, logged to MCAP/CSV,
//! with a summary of tracking error, overshoot, settling and saturation at the end.
//!
//! ```text
//! servo run --gains gains.toml --ref step:1.5 --duration 5 --log run.mcap
//! servo run --gains gains.toml --ref step:90deg --plant-effect saturation:limit=6 --csv run.csv
//! servo run --voltage step:3 --duration 2 --log open_loop.mcap        (open loop, no gains)
//! servo run --plant torque_drive.toml --command step:0.5 --log i_ref.mcap  (0.5 A to the drive)
//! servo run --experiment experiments/steps.toml --gains gains.toml --log steps.mcap
//! ```

mod backend;
mod program;
mod said;

use crate::gains_file::GainsFile;
use crate::io::{meta_keys, write_csv_on, McapLog, McapLogOptions};
use crate::live;
use crate::model_file::ModelFile;
use crate::plant_args::PlantArgs;
use anyhow::{anyhow, bail, Context};
use servo_core::metrics::RunSummary;
use servo_hw::run::logged::close_log;
use servo_hw::run::{LogSink, RunConfig, RunOutput, StopOutcome, StopReason};
use servo_io::compensation::CompensationChoice;
use servo_io::controller::{run_controller, PidOptions};
use std::path::PathBuf;

/// The plots of a run (also used by `servo demo`).
pub use crate::plot::plot_run;

/// Which backend runs the loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendKind {
    /// The simulated gearmotor (`--plant`, `--plant-effect`), faster than real time unless
    /// `--realtime`.
    Sim,
    /// A board (or `servo board --pty`) on `--port` at `--baud`; its clock paces the loop.
    Serial,
}

/// Run the position loop and log it.
#[derive(Debug, clap::Parser)]
pub struct Run {
    /// Backend that runs the loop.
    #[arg(long, value_enum, default_value = "sim")]
    pub backend: BackendKind,

    #[command(flatten)]
    pub plant: PlantArgs,

    /// Controller gains file (from `servo design -o gains.toml`); needed for closed loop.
    #[arg(long, value_name = "FILE")]
    pub gains: Option<PathBuf>,

    /// Position reference at the load, e.g. `step:1.5`, `step:90deg@0.5`, `sine:amp=0.5,freq=1`,
    /// `trap:distance=3,vmax=10,amax=100`, `square:amp=1,period=2`, `prbs:amp=0.5,bit=0.05`.
    /// On a linear axis (a `--plant` or `--model` file with a screw or belt `[transmission]`)
    /// positions are lengths in m (`step:10mm`, `trap:20mm,vmax=50mm/s,amax=1m/s2`).
    #[arg(long = "ref", value_name = "REF", conflicts_with_all = ["voltage", "command", "experiment"])]
    pub reference: Option<String>,

    /// Experiment file (TOML, see `experiments/`): a sequence of closed-loop reference and
    /// open-loop segments (`u`: the drive's command, in V, A or duty). The run lasts the
    /// experiment's duration unless --duration.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["voltage", "command"])]
    pub experiment: Option<PathBuf>,

    /// Open loop: driver input u [V] from a generator read in volts, e.g. `step:3`,
    /// `sine:amp=2,freq=1`, `prbs:amp=3,bit=0.02`.
    #[arg(long, value_name = "REF", conflicts_with = "command")]
    pub voltage: Option<String>,

    /// Open loop: the drive's command from a generator, in the drive's unit: u [V] on a voltage
    /// amplifier, the current reference i_ref [A] on a current drive, the duty cycle in [-1, 1]
    /// on a PWM bridge or smart servo (a `--plant` file's `[drive]`), e.g. `step:0.5`.
    #[arg(long, value_name = "REF")]
    pub command: Option<String>,

    /// Run length [s] (default: the experiment's duration, else 5 s).
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,

    /// Write the run to this MCAP file (Foxglove, PlotJuggler; `servo export` makes a CSV).
    #[arg(long, value_name = "FILE.mcap")]
    pub log: Option<PathBuf>,

    /// Write the run to this CSV file (time_s,u_V,theta_l_rad,i_a_A,ref_rad,omega_l_rad_s; on a
    /// linear axis x_m, ref_m and v_x_m_s in metres instead of the load angles).
    #[arg(long, value_name = "FILE.csv")]
    pub csv: Option<PathBuf>,

    /// Write a plot of reference, angle and voltage (SVG).
    #[arg(long, value_name = "FILE.svg")]
    pub plot: Option<PathBuf>,

    /// Pace the simulator to wall-clock time.
    #[arg(long)]
    pub realtime: bool,

    /// Live progress on stderr (run time elapsed and left, missed deadlines of a board): `auto`
    /// on a terminal, `always` (a line every 2 s when stderr is not a terminal), `never`.
    #[arg(long, value_enum, default_value = "auto")]
    pub progress: live::ProgressMode,

    /// Simulator: stop the run with an error when |theta_l| exceeds this many load revolutions,
    /// like the board's soft position limit (+-2 rev: `--soft-limit-rev 2`). Off by default;
    /// a diverging simulation (non-finite state, |theta_l| > 1e9 rad) always stops.
    #[arg(long = "soft-limit-rev", value_name = "REV")]
    pub soft_limit_rev: Option<f64>,

    /// Encoding of the loop messages in the --log MCAP: `protobuf` (compact and fast to write)
    /// or `json` (JSON schema); both open in Foxglove, PlotJuggler and every servo command.
    #[arg(long = "log-encoding", value_enum, default_value = "protobuf")]
    pub log_encoding: crate::io::LogEncoding,

    /// Serial port of the board (`--backend serial`), e.g. /dev/ttyACM0 (see `servo ports`).
    #[arg(long, value_name = "PATH", default_value = "/dev/ttyACM0")]
    pub port: String,

    /// Baud rate of the serial port [bit/s] (ignored by USB CDC and pseudo-terminals).
    #[arg(long, value_name = "BAUD", default_value_t = 115_200)]
    pub baud: u32,

    /// A board silent for this long during a run is lost: 0 V, log closed, error [ms].
    #[arg(long = "board-timeout-ms", value_name = "MS", default_value_t = 250.0)]
    pub board_timeout_ms: f64,

    /// Control period T_s [s] of the simulator (default: the gains file's ts_s, else 1e-3).
    #[arg(long, value_name = "SECONDS")]
    pub ts: Option<f64>,

    /// Driver input limit [V] (default: the gains file's u_limit_v, else 10 V; on a duty or
    /// current drive its range: duty_limit x V_supply, i_limit_a [A]).
    #[arg(long = "u-limit", value_name = "VOLTS")]
    pub u_limit: Option<f64>,

    /// Feedforward and compensation, a comma list: linear terms from the reference's speed and
    /// acceleration, `inertia` (J_eq and back-EMF), `friction` (B_eq and tau_sf), `viscous`,
    /// `coulomb`, `back_emf`; effects of the --model file by their registry names (as `servo
    /// diagnose` and the model file name them), each compensated as its effect file declares;
    /// `all` (every term and every effect of the model); `none`.
    #[arg(long, value_name = "TERMS")]
    pub ff: Option<String>,

    /// Ramp the effects' compensation in over this time from the start of the run [s] (0: at
    /// once).
    #[arg(long = "ff-ramp", value_name = "SECONDS", default_value_t = 0.0)]
    pub ff_ramp_s: f64,

    /// Model file for the feedforward constants (J_eq, B_eq, tau_sf, ...) and the effects `--ff`
    /// compensates; default Table 2.
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,

    #[command(flatten)]
    pub pid: PidOptions,

    /// Bandwidth of the speed estimate [Hz] (tracking-loop estimator on the encoder angle).
    #[arg(long = "speed-bandwidth-hz", value_name = "HZ", default_value_t = 50.0)]
    pub speed_bandwidth_hz: f64,
}

/// Everything a finished run leaves behind.
#[derive(Debug)]
pub struct RunReport {
    pub output: RunOutput,
    pub summary: RunSummary,
}

impl Run {
    pub fn run(self) -> anyhow::Result<()> {
        let report = self.execute()?;
        if report.output.stop == StopReason::Interrupted {
            let at_s = report.output.last_time_s;
            eprintln!("the board was stopped at 0 V and the logs are closed");
            return Err(live::Interrupted { at_s }.into());
        }
        Ok(())
    }

    /// The axis of the run: the transmission of the `--plant` file, else of `--model`, else the
    /// handout's gear. On a linear axis (a screw, a belt) references are lengths and the CSV log
    /// is written in metres.
    pub fn axis(&self) -> anyhow::Result<servo_core::Transmission> {
        if self.plant.plant.is_some() {
            return self.plant.transmission();
        }
        match &self.model {
            Some(p) => Ok(ModelFile::load(p).context("--model")?.transmission),
            None => Ok(servo_core::Transmission::GEAR),
        }
    }

    /// Runs and reports; used by `servo run` and by tests.
    pub fn execute(&self) -> anyhow::Result<RunReport> {
        for p in [&self.log, &self.csv, &self.plot].into_iter().flatten() {
            if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
                if !dir.is_dir() {
                    bail!(
                        "cannot write {}: folder {} does not exist",
                        p.display(),
                        dir.display()
                    );
                }
            }
        }
        if let Some(l) = &self.log {
            if l.extension().is_none_or(|e| e != "mcap") {
                bail!(
                    "--log {}: expected a .mcap file name (use --csv for CSV)",
                    l.display()
                );
            }
        }
        if let Some(d) = self.duration {
            if !(d.is_finite() && d > 0.0) {
                bail!("--duration must be > 0 s, got {d}");
            }
        }
        let axis = self.axis()?;
        let metres = axis.metres_per_rad();
        let drive = self.drive()?;
        let (program, program_text) = self.program(self.duration, metres, &drive)?;
        if let Some(m) = metres {
            eprintln!(
                "linear axis ({}, {:.4} mm per radian of the screw/pulley): references in m (suffix mm, um), the CSV log in metres (x_m, v_x_m_s, ref_m)",
                axis.kind_name(),
                m * 1e3
            );
        }
        let duration_s = self.duration.or(program.duration_s()).unwrap_or(5.0);
        let gains = match &self.gains {
            Some(p) => Some(GainsFile::load(p)?),
            None if program.needs_controller() => {
                bail!("--gains is needed for a closed-loop run (make one with `servo design -o gains.toml`)")
            }
            None => None,
        };
        let gains_name = self.gains.as_ref().map(|p| p.display().to_string());
        let gains_src = gains.as_ref().zip(gains_name.as_deref());
        // Without --u-limit or a gains file's limit, a drive's loop may use the drive's range
        // (a duty drive's whole bridge, a current drive's limit), not an amplifier's 10 V.
        let limit = match (self.u_limit, gains.as_ref().and_then(|g| g.pid.u_limit_v)) {
            (None, None) => drive.input_range(),
            _ => self.u_limit,
        };
        let ctl = run_controller(gains_src, &self.pid, self.ts, limit)?;
        let (ts_s, u_limit_v, pid) = (ctl.ts_s, ctl.u_limit_v, ctl.pid);
        let what = self.program_flag();
        program
            .check_sampling(ts_s)
            .map_err(|e| anyhow!("{what}: {e} ({:.4} ms)", 1e3 * ts_s))?;
        self.say_plant_and_controller(gains.as_ref(), pid.as_ref(), ctl.description.as_deref());
        let model = match &self.model {
            Some(p) => Some(ModelFile::load(p).context("--model")?),
            None => None,
        };
        if self.ff.is_some() && model.is_none() {
            eprintln!("note: --ff without --model: feedforward constants from Table 2 (nominal)");
        }
        let choice = match self.ff.as_deref() {
            Some(terms) => {
                let mf = model.clone().unwrap_or_default();
                let plant = mf.plant().context("--model")?;
                let c = CompensationChoice::parse(terms, &mf, &plant, self.ff_ramp_s)?;
                for line in c.lines() {
                    eprintln!("{line}");
                }
                Some((c.build(&plant)?, c))
            }
            None => None,
        };
        let feedforward = choice.as_ref().map(|(c, _)| *c);

        let (mut backend, mut meta) = self.open_backend(ts_s, u_limit_v)?;
        let info = backend.info();
        let backend_name = format!("{:?}", self.backend).to_lowercase();
        meta.run(&backend_name, &info, duration_s, u_limit_v, &program_text)
            .controller(
                &info,
                u_limit_v,
                gains.as_ref(),
                pid.as_ref(),
                choice.as_ref().map(|(c, ch)| (c, ch)),
                model.as_ref(),
            )?
            .put(
                meta_keys::COMMAND,
                std::env::args().collect::<Vec<_>>().join(" "),
            );

        let cfg = RunConfig {
            program,
            duration_s,
            pid,
            feedforward,
            u_limit_v,
            speed_bandwidth_rad_s: 2.0 * std::f64::consts::PI * self.speed_bandwidth_hz,
            // Samples stay in memory only for --csv and --plot; the log and the summary stream.
            keep_record: self.csv.is_some() || self.plot.is_some(),
            speed_loop: None,
            drive,
        };
        // A simulation faster than real time: log chunks by wall-clock time, fast compression.
        let fast = self.backend == BackendKind::Sim && !self.realtime;
        let log_options = McapLogOptions {
            flush_on_wall_clock: fast,
            fast_compression: fast,
            encoding: self.log_encoding,
            ..McapLogOptions::default()
        };
        let mut log = match &self.log {
            Some(p) => {
                let samples = (duration_s / ts_s).ceil();
                servo_io::disk::ensure_room_for_log(p, samples, self.log_encoding)?;
                Some(McapLog::create(p, &meta.0, log_options)?)
            }
            None => None,
        };
        let progress = live::Progress::from_mode(self.progress, "servo run");
        let sink = log.as_mut().map(|l| l as &mut dyn LogSink);
        let out = live::run_loop_with_progress(backend.as_mut(), &cfg, sink, progress);
        let link = backend.link_stats();
        let out = match out {
            Ok(o) => o,
            Err(e) => {
                if let Some(ls) = &link {
                    eprintln!("{ls}");
                }
                if let Some(l) = log.as_mut() {
                    let closed = close_log(l, Err(&e), link.as_ref(), duration_s);
                    eprintln!("{}", log_end(l, closed.err(), "the fault"));
                }
                if let Some(StopOutcome::Failed(why)) = e.stop_outcome() {
                    eprintln!(
                        "WARNING: 0 V could not be confirmed ({why}); check the motor and power"
                    );
                }
                return Err(e.into());
            }
        };
        let summary = out.summary();
        outln!("{}", summary.on_axis(metres));
        if let Some(ls) = &link {
            outln!("{ls}");
        }
        if let Some(l) = log.as_mut() {
            if let Err(e) = close_log(l, Ok(&out), link.as_ref(), duration_s) {
                eprintln!("{}", log_end(l, Some(e), "the end"));
                bail!("the log {} could not be finished", l.path().display());
            }
            outln!(
                "log: {} ({} samples, MCAP: open in Foxglove/PlotJuggler, or `servo export`)",
                l.path().display(),
                l.messages_in_file()
            );
        }
        if let Some(p) = &self.csv {
            write_csv_on(p, &out.record, &axis)?;
            outln!("csv: {}", p.display());
        }
        if let Some(p) = &self.plot {
            crate::plot::plot_run_on(p, &out, &axis)?;
            outln!("plot: {}", p.display());
        }
        Ok(RunReport {
            output: out,
            summary,
        })
    }
}

/// The line that says where a run's log ended up after [`close_log`] (`closed`: its error) and
/// how many samples the file holds: finished under its name, or left as `NAME.partial` (a full
/// disk) with the samples that reached it and the previous log untouched. `until`: "the fault".
fn log_end(l: &McapLog, closed: Option<servo_io::Error>, until: &str) -> String {
    match closed {
        None => format!(
            "log {} finished with the {} samples before {until}",
            l.path().display(),
            l.messages_in_file()
        ),
        Some(e) => format!(
            "the log could not be finished ({e:#}): {} holds the first {} samples (of {} \
             taken); `servo log recover {} -o FIXED.mcap` makes it a finished log; {}",
            l.writing().display(),
            l.messages_in_file(),
            l.messages(),
            l.writing().display(),
            servo_io::output::unchanged_sentence(l.path())
        ),
    }
}
