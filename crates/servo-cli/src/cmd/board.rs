//! `servo board --pty`: a virtual board (servo's board core + simulated gearmotor in real time)
//! on a pseudo-terminal, for running `servo run --backend serial` without hardware.
//! `servo board --qemu`: the same board core as Cortex-M firmware under qemu-system-arm, its UART
//! on a pseudo-terminal.

use crate::plant_args::PlantArgs;
use anyhow::{bail, Context};
use serialport::SerialPort;
use servo_core::safety::SafetyLimits;
use servo_hw::board::{BoardConfig, BoardReport, VirtualBoard};
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Run a virtual board on a pseudo-terminal (or an existing serial port) until Ctrl-C.
#[derive(Debug, clap::Parser)]
pub struct Board {
    /// Create a pseudo-terminal and serve on it; its path is printed ("board ready on PATH").
    #[arg(long, required_unless_present_any = ["port", "qemu"])]
    pub pty: bool,
    /// Run the board firmware image under qemu-system-arm (mps2-an386) and put its UART on a
    /// pseudo-terminal; its path is printed like --pty's. The image's plant is fixed
    /// (--qemu-plant); --period-ms, --watchdog-ms and ±max(|--theta-min-rad|, |--theta-max-rad|)
    /// are passed to it.
    #[arg(long, conflicts_with_all = ["pty", "port"])]
    pub qemu: bool,
    /// The QEMU firmware image (default: $SERVO_QEMU_ELF, else
    /// firmware/target/thumbv7em-none-eabihf/release/servo-board-qemu of the checkout).
    #[arg(long, value_name = "FILE", requires = "qemu")]
    pub elf: Option<PathBuf>,
    /// The qemu-system-arm executable.
    #[arg(
        long = "qemu-bin",
        value_name = "PATH",
        default_value = "qemu-system-arm",
        requires = "qemu"
    )]
    pub qemu_bin: PathBuf,
    /// The plant simulated inside the QEMU image: lab (friction as measured on real SRV-02s),
    /// table2 (no friction) or lab-unbalanced (lab with an eccentric load of 0.01 N m at phase 0.5 rad, an
    /// unbalanced load to identify and compensate).
    #[arg(long = "qemu-plant", value_name = "PLANT", default_value = "lab", value_parser = ["lab", "table2", "lab-unbalanced"], requires = "qemu")]
    pub qemu_plant: String,
    /// Write the QEMU firmware's loop statistics (one line a second) to this file.
    #[arg(long = "stats-file", value_name = "FILE", requires = "qemu")]
    pub stats_file: Option<PathBuf>,
    /// Serve on an existing serial port instead of a pty.
    #[arg(long, value_name = "PATH", conflicts_with = "pty")]
    pub port: Option<String>,
    /// Baud rate for --port [bit/s].
    #[arg(long, default_value_t = 115_200, value_name = "BAUD")]
    pub baud: u32,
    /// Also write the pty path to this file (for scripts).
    #[arg(long = "path-file", value_name = "FILE")]
    pub path_file: Option<PathBuf>,
    /// Control (sample) period of the board [ms]. Default: 1 ms for --pty and --port; for
    /// --qemu, the shortest of 1, 2, 5 and 10 ms that the emulated board and a host on this
    /// machine hold (measured at start, a fraction of a second per period tried).
    #[arg(long = "period-ms", value_name = "MS")]
    pub period_ms: Option<f64>,
    /// Physics sub-steps of the simulated plant per period, 1..=20: the time resolution at which
    /// a command takes effect (period / N), and the plant's cost per period on the QEMU image.
    #[arg(long = "physics-substeps", default_value_t = 5, value_name = "N")]
    pub physics_substeps: u32,
    /// Board watchdog: no voltage command for this long means 0 V and a fault [ms].
    #[arg(long = "watchdog-ms", default_value_t = 50.0, value_name = "MS")]
    pub watchdog_ms: f64,
    /// Voltage limit of the driver input [V].
    #[arg(long = "voltage-limit-v", default_value_t = SafetyLimits::default().voltage_limit_v, value_name = "V")]
    pub voltage_limit_v: f64,
    /// Soft lower position limit of the load [rad].
    #[arg(long = "theta-min-rad", default_value_t = SafetyLimits::default().theta_min_rad, value_name = "RAD", allow_hyphen_values = true)]
    pub theta_min_rad: f64,
    /// Soft upper position limit of the load [rad].
    #[arg(long = "theta-max-rad", default_value_t = SafetyLimits::default().theta_max_rad, value_name = "RAD", allow_hyphen_values = true)]
    pub theta_max_rad: f64,
    /// Over-current trip level [A].
    #[arg(long = "i-trip-a", default_value_t = SafetyLimits::default().i_trip_a, value_name = "A")]
    pub i_trip_a: f64,
    /// Current-sense scale reported to the host [A/LSB].
    #[arg(
        long = "current-scale-a",
        default_value_t = 1e-3,
        value_name = "A_PER_LSB"
    )]
    pub current_scale_a: f64,
    #[command(flatten)]
    pub plant: PlantArgs,
}

/// The board period when --period-ms is not given (--pty, --port) [ms].
pub const DEFAULT_PERIOD_MS: f64 = 1.0;

impl Board {
    /// The period in force [ms]: --period-ms, else [`DEFAULT_PERIOD_MS`].
    fn period_ms(&self) -> f64 {
        self.period_ms.unwrap_or(DEFAULT_PERIOD_MS)
    }

    pub fn config(&self) -> anyhow::Result<BoardConfig> {
        let period_ms = self.period_ms();
        if !(period_ms.is_finite() && period_ms > 0.0) {
            bail!("--period-ms must be > 0 ms, got {period_ms}");
        }
        if !(1..=20).contains(&self.physics_substeps) {
            bail!(
                "--physics-substeps must be 1..=20, got {}",
                self.physics_substeps
            );
        }
        let cfg = BoardConfig {
            physics_substeps: self.physics_substeps,
            sample_period_s: period_ms * 1e-3,
            watchdog_s: self.watchdog_ms * 1e-3,
            limits: SafetyLimits {
                voltage_limit_v: self.voltage_limit_v,
                theta_min_rad: self.theta_min_rad,
                theta_max_rad: self.theta_max_rad,
                i_trip_a: self.i_trip_a,
            },
            current_scale_a_per_lsb: self.current_scale_a,
        };
        cfg.limits
            .validate()
            .context("--voltage-limit-v / --theta-min-rad / --theta-max-rad / --i-trip-a")?;
        Ok(cfg)
    }

    pub fn run(self) -> anyhow::Result<()> {
        if self.qemu {
            return self.run_qemu();
        }
        let (plant, sensors) = self.plant.load()?;
        crate::plant_args::voltage_drive_only(
            &self.plant,
            "servo board (its protocol carries volts)",
        )?;
        let cfg = self.config()?;
        let mut board = VirtualBoard::new(&plant, sensors, cfg)
            .context("virtual board (--period-ms, --watchdog-ms, --current-scale-a)")?;
        let stop = Arc::new(AtomicBool::new(false));
        {
            let stop = stop.clone();
            ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed))
                .context("installing the Ctrl-C handler")?;
        }
        let report = if self.pty {
            let (mut master, slave) =
                serialport::TTYPort::pair().context("creating a pseudo-terminal")?;
            let path = slave.name().context("the pseudo-terminal has no path")?;
            if let Some(f) = &self.path_file {
                write_path_file(f, &path)?;
            }
            outln!("board ready on {path}");
            outln!(
                "  {} | period {} ms | watchdog {} ms | limits ±{} V, [{}, {}] rad, {} A | Ctrl-C to quit",
                servo_hw::board::FIRMWARE,
                self.period_ms(),
                self.watchdog_ms,
                cfg.limits.voltage_limit_v,
                cfg.limits.theta_min_rad,
                cfg.limits.theta_max_rad,
                cfg.limits.i_trip_a
            );
            let _ = std::io::stdout().flush();
            // The slave stays open here so that hosts can come and go without hanging up the pty.
            let r = board
                .serve(&mut master, &stop)
                .context("serving on the pseudo-terminal")?;
            drop(slave);
            r
        } else {
            let Some(port) = &self.port else {
                bail!("give --pty or --port PATH")
            };
            let mut p = serialport::new(port, self.baud)
                .open()
                .with_context(|| format!("opening --port {port}"))?;
            outln!("board ready on {port}");
            let _ = std::io::stdout().flush();
            board
                .serve(&mut *p, &stop)
                .with_context(|| format!("serving on {port}"))?
        };
        print_report(&report);
        Ok(())
    }
}

impl Board {
    fn run_qemu(&self) -> anyhow::Result<()> {
        let cfg = self.config()?;
        let elf = match &self.elf {
            Some(e) => e.clone(),
            None => servo_hw::qemu::default_image().context(
                "no QEMU board image: build it (cd firmware && cargo build --release) or give --elf FILE",
            )?,
        };
        let theta_limit_rad = cfg
            .limits
            .theta_min_rad
            .abs()
            .max(cfg.limits.theta_max_rad.abs());
        let mut qcfg = servo_hw::qemu::QemuConfig {
            qemu: self.qemu_bin.clone(),
            elf: elf.clone(),
            period_us: (self.period_ms() * 1e3).round() as u32,
            watchdog_ms: self.watchdog_ms.round() as u32,
            substeps: self.physics_substeps,
            theta_limit_mrad: (theta_limit_rad * 1e3).round().min(u32::MAX as f64) as u32,
            plant: match self.qemu_plant.as_str() {
                "table2" => servo_hw::qemu::QemuPlant::Table2,
                "lab-unbalanced" => servo_hw::qemu::QemuPlant::LabUnbalanced,
                _ => servo_hw::qemu::QemuPlant::Lab,
            },
            stats_file: self.stats_file.clone(),
        };
        let stop = Arc::new(AtomicBool::new(false));
        {
            let stop = stop.clone();
            ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed))
                .context("installing the Ctrl-C handler")?;
        }
        let period_note = match self.period_ms {
            Some(_) => "--period-ms".to_string(),
            None => {
                qcfg.period_us = self.measured_period_us(&qcfg)?;
                "measured: the shortest of 1, 2, 5, 10 ms this machine holds".to_string()
            }
        };
        let period_ms = qcfg.period_us as f64 * 1e-3;
        if (qcfg.watchdog_ms as u64) * 1000 <= qcfg.period_us as u64 {
            bail!(
                "--watchdog-ms {} must be longer than the board's period ({period_ms} ms)",
                self.watchdog_ms
            );
        }
        let mut board = servo_hw::qemu::QemuBoard::start(&qcfg)
            .with_context(|| format!("starting the QEMU board ({})", elf.display()))?;
        let path = board.path().to_string();
        if let Some(f) = &self.path_file {
            write_path_file(f, &path)?;
        }
        outln!("board ready on {path}");
        outln!(
            "  QEMU mps2-an386 running {} | plant {} | period {period_ms} ms ({period_note}) | watchdog {} ms | Ctrl-C to quit",
            elf.display(),
            self.qemu_plant,
            self.watchdog_ms
        );
        let _ = std::io::stdout().flush();
        while !stop.load(Ordering::Relaxed) {
            if !board.is_running() {
                bail!("qemu-system-arm exited");
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        board.shutdown();
        outln!("board stopped (QEMU)");
        Ok(())
    }
}

impl Board {
    /// The shortest period the QEMU board of `qcfg` holds here ([`servo_hw::qemu::choose_period`]),
    /// each probe said on stderr; an error naming the figures when it holds none.
    fn measured_period_us(&self, qcfg: &servo_hw::qemu::QemuConfig) -> anyhow::Result<u32> {
        eprintln!("measuring the period this machine holds (no --period-ms) ...");
        let (chosen, probes) = servo_hw::qemu::choose_period(qcfg)
            .context("measuring the QEMU board's period (give --period-ms to skip)")?;
        for p in &probes {
            eprintln!("  {p}: {}", if p.held() { "held" } else { "not held" });
        }
        let Some(us) = chosen else {
            let last = servo_hw::qemu::PROBE_PERIODS_US[servo_hw::qemu::PROBE_PERIODS_US.len() - 1];
            bail!(
                "the QEMU board cannot hold a period of {} ms or less on this machine (a period \
                 is held with at most {:.0} % of its deadlines missed and the host's answer \
                 within {:.0} % of it: {}); free the machine or give a longer --period-ms",
                last as f64 * 1e-3,
                servo_hw::qemu::PROBE_MAX_MISSED_FRACTION * 100.0,
                servo_hw::qemu::PROBE_MAX_RTT_FRACTION * 100.0,
                probes
                    .iter()
                    .map(|p| p.to_string())
                    .collect::<Vec<_>>()
                    .join("; ")
            );
        };
        Ok(us)
    }
}

fn print_report(r: &BoardReport) {
    outln!(
        "board stopped: {} run(s), {} samples sent, {} missed deadlines, {} late ticks (max {:.1} ms late), {} CRC errors, {} framing errors",
        r.runs,
        r.samples,
        r.missed_deadlines,
        r.late_ticks,
        r.max_lateness_s * 1e3,
        r.crc_errors,
        r.framing_errors
    );
    for (code, text) in &r.faults {
        outln!("  fault {code:?}: {text}");
    }
}

/// Writes the board's device path to `--path-file`, atomically: a script polling the file reads
/// a whole path or none. The file only ever holds a transient path: replaced, not kept.
fn write_path_file(f: &std::path::Path, path: &str) -> anyhow::Result<()> {
    crate::io::output::write_file_with(
        f,
        "--path-file",
        format!("{path}\n"),
        crate::io::output::Previous::Replace,
    )?;
    Ok(())
}
