//! The virtual board: servo's board firmware core ([`servo_core::board::BoardCore`]) with the
//! simulated gearmotor ([`servo_core::board::SimDrive`]) behind its HAL, speaking the protocol
//! over a serial port (a pseudo-terminal) in real time on the host. The QEMU image and the real
//! firmware of `firmware/` run the same core; only the HAL differs.
//!
//! Firmware behaviour: see [`servo_core::board`] and `docs/protocol.md`. This adapter adds the
//! host-side clock: the plant is integrated in sub-steps of period/`physics_substeps`, one per
//! wall-clock sub-step, with a command applied from the sub-step after it arrives; a late
//! wake-up (the host machine is busy) is caught up at once and counted, never skipped. While
//! idle the plant keeps coasting at 0 V so that a second run starts from where the load is.

use crate::backend::HwError;
use serialport::SerialPort;
use servo_core::board::{self as core_board, BoardCore, BoardHal, SimDrive};
use servo_core::math;
use servo_core::protocol::{fixed_text, FaultCode, HelloAck};
use servo_core::safety::SafetyLimits;
use servo_core::sim::{PlantSim, SensorConfig};
use servo_core::Plant;
use std::io::ErrorKind;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Firmware name reported in the handshake.
pub const FIRMWARE: &str = concat!("servo-vboard ", env!("CARGO_PKG_VERSION"));

/// Configuration of the virtual board (the firmware's constants).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoardConfig {
    /// Control (sample) period [s]; whole microseconds on the wire.
    pub sample_period_s: f64,
    /// No command for this long → 0 V and a fault [s].
    pub watchdog_s: f64,
    /// Voltage limit, soft position limits, over-current trip.
    pub limits: SafetyLimits,
    /// Current-sense scale [A per LSB].
    pub current_scale_a_per_lsb: f64,
    /// Physics sub-steps per period: the time resolution of command arrival.
    pub physics_substeps: u32,
}

impl Default for BoardConfig {
    fn default() -> Self {
        BoardConfig {
            sample_period_s: 1e-3,
            watchdog_s: 0.050,
            limits: SafetyLimits::default(),
            current_scale_a_per_lsb: 1e-3,
            physics_substeps: 5,
        }
    }
}

impl BoardConfig {
    /// The board core's configuration for an encoder of `counts_per_rev`.
    pub fn core_config(&self, counts_per_rev: u32) -> core_board::BoardConfig {
        core_board::BoardConfig {
            firmware: fixed_text(FIRMWARE),
            sample_period_us: math::round(self.sample_period_s * 1e6) as u32,
            watchdog_ms: math::round(self.watchdog_s * 1e3).min(65_535.0) as u16,
            limits: self.limits,
            counts_per_rev,
            current_scale_a_per_lsb: self.current_scale_a_per_lsb as f32,
        }
    }

    fn validate(&self) -> Result<(), HwError> {
        let us = math::round(self.sample_period_s * 1e6);
        if !(us.is_finite() && (50.0..=1e6).contains(&us)) {
            return Err(HwError::Protocol(format!(
                "board sample period must be between 50 us and 1 s, got {} s",
                self.sample_period_s
            )));
        }
        if !(self.watchdog_s > self.sample_period_s && self.watchdog_s <= 65.0) {
            return Err(HwError::Protocol(format!(
                "board watchdog must be longer than the sample period and at most 65 s, got {} s",
                self.watchdog_s
            )));
        }
        if !(self.current_scale_a_per_lsb > 0.0 && self.current_scale_a_per_lsb.is_finite()) {
            return Err(HwError::Protocol(format!(
                "current scale must be > 0 A/LSB, got {}",
                self.current_scale_a_per_lsb
            )));
        }
        if !(1..=100).contains(&self.physics_substeps) {
            return Err(HwError::Protocol(format!(
                "physics sub-steps must be in 1..=100, got {}",
                self.physics_substeps
            )));
        }
        self.limits
            .validate()
            .map_err(|e| HwError::Safety(e.to_string()))
    }
}

/// What happened while the board served.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BoardReport {
    /// Runs started (Start or LoopReference from idle).
    pub runs: u64,
    /// Samples sent.
    pub samples: u64,
    /// Periods whose command arrived after the next sample was due, or never.
    pub missed_deadlines: u64,
    /// Ticks that woke up more than one period late (host machine busy).
    pub late_ticks: u64,
    /// Largest tick lateness [s].
    pub max_lateness_s: f64,
    /// Faults raised, in order.
    pub faults: Vec<(FaultCode, String)>,
    /// Frames rejected by CRC.
    pub crc_errors: u64,
    /// Frames rejected for framing/parse errors.
    pub framing_errors: u64,
    /// The host side of the port closed.
    pub disconnected: bool,
    /// A run was still driving the motor when serving ended (stop flag): the board had not
    /// gone to 0 V on its own (Stop, watchdog, trip or disconnect).
    pub driving_at_exit: bool,
    /// Driver input at that moment [V].
    pub output_at_exit_v: f64,
}

/// The virtual board.
#[derive(Debug)]
pub struct VirtualBoard {
    cfg: BoardConfig,
    core: BoardCore,
    drive: SimDrive,
    report: BoardReport,
    /// Wall-clock origin of the board's microsecond clock.
    epoch: Instant,
}

/// The HAL of the virtual board: the simulated drive, the host clock and the serial port.
struct HostHal<'a> {
    drive: &'a mut SimDrive,
    port: &'a mut dyn SerialPort,
    epoch: Instant,
    /// The core asked for a new tick schedule (Start).
    restart: bool,
    faults: &'a mut Vec<(FaultCode, String)>,
    /// A write error other than a full or closed link.
    io_error: Option<std::io::Error>,
}

impl BoardHal for HostHal<'_> {
    fn now_us(&mut self) -> u32 {
        self.epoch.elapsed().as_micros() as u32
    }
    fn encoder_count(&mut self) -> i32 {
        self.drive.encoder_count()
    }
    fn current_raw(&mut self) -> i16 {
        self.drive.current_raw()
    }
    fn set_voltage(&mut self, u_v: f32) {
        self.drive.set_voltage(u_v);
    }
    fn restart_tick(&mut self) {
        self.restart = true;
    }
    /// A write that times out (nobody reading a full pty) or hits a closed peer drops the frame.
    fn write(&mut self, bytes: &[u8]) {
        match self.port.write_all(bytes) {
            Ok(()) => {}
            Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::BrokenPipe) => {}
            Err(e) => {
                if self.io_error.is_none() {
                    self.io_error = Some(e);
                }
            }
        }
    }
    fn on_fault(&mut self, code: FaultCode, text: &str) {
        self.faults.push((code, text.to_string()));
    }
}

impl VirtualBoard {
    /// A board for `plant` with its sensors and firmware constants.
    pub fn new(
        plant: &Plant,
        sensors: SensorConfig,
        cfg: BoardConfig,
    ) -> Result<VirtualBoard, HwError> {
        cfg.validate()?;
        let core_cfg = cfg.core_config(sensors.counts_per_rev);
        let core = BoardCore::new(core_cfg).map_err(|e| HwError::Protocol(e.to_string()))?;
        let h = cfg.sample_period_s / cfg.physics_substeps as f64;
        Ok(VirtualBoard {
            cfg,
            core,
            drive: SimDrive::new(plant, sensors, h, cfg.current_scale_a_per_lsb as f32)?,
            report: BoardReport::default(),
            epoch: Instant::now(),
        })
    }

    /// The handshake answer of this board.
    pub fn hello_ack(&self) -> HelloAck {
        self.core.config().hello_ack()
    }

    /// The true plant simulator behind the board.
    pub fn plant_sim(&self) -> &PlantSim {
        self.drive.plant_sim()
    }

    /// The driver input the board applies right now [V]: 0 V whenever no run is active.
    pub fn output_v(&self) -> f64 {
        self.drive.voltage_v() as f64
    }

    /// What happened so far.
    pub fn report(&self) -> BoardReport {
        let mut r = self.report.clone();
        let s = self.core.stats();
        r.runs = s.runs;
        r.samples = s.samples;
        r.missed_deadlines = s.missed_deadlines;
        let d = self.core.decoder_stats();
        r.crc_errors = d.crc_errors;
        r.framing_errors = d.framing_errors;
        r
    }

    /// Serves the protocol on `port` until `stop` is set or the host side closes (POLLHUP).
    /// I/O errors other than a closed peer are returned.
    pub fn serve(
        &mut self,
        port: &mut dyn SerialPort,
        stop: &AtomicBool,
    ) -> Result<BoardReport, HwError> {
        let subs = self.cfg.physics_substeps as u64;
        let h = Duration::from_secs_f64(self.cfg.sample_period_s / subs as f64);
        let mut hal = HostHal {
            drive: &mut self.drive,
            port,
            epoch: self.epoch,
            restart: false,
            faults: &mut self.report.faults,
            io_error: None,
        };
        let core = &mut self.core;
        let mut buf = [0u8; 256];
        // Tick schedule of the run: sub-step n ends at t0 + n h.
        let mut t0 = Instant::now();
        let mut n: u64 = 0;
        let mut idle_since = Instant::now();
        let mut late_ticks = 0u64;
        let mut max_lateness_s = 0.0f64;
        let mut disconnected = false;
        while !stop.load(Ordering::Relaxed) {
            if let Some(e) = hal.io_error.take() {
                return Err(HwError::Io(e));
            }
            let running = core.is_running();
            let deadline = if running {
                t0 + h * (n as u32 + 1)
            } else {
                Instant::now() + Duration::from_millis(50)
            };
            let link = receive(hal.port, deadline, &mut buf)?;
            let got = match link {
                Received::Bytes(k) => k,
                Received::Nothing => 0,
                Received::Closed => {
                    disconnected = true;
                    break;
                }
            };
            if !running {
                // Coast at 0 V over the wall time spent idle (at most 1 s per call).
                let idle = idle_since.elapsed().min(Duration::from_secs(1));
                for _ in 0..(idle.as_nanos() / h.as_nanos().max(1)) {
                    hal.drive.step();
                }
                idle_since = Instant::now();
            }
            if got > 0 {
                core.receive(&mut hal, &buf[..got]);
                if hal.restart {
                    hal.restart = false;
                    t0 = Instant::now();
                    n = 0;
                }
                if !core.is_running() {
                    idle_since = Instant::now();
                }
                continue;
            }
            if !running || Instant::now() < deadline {
                continue;
            }
            // The sub-step is over: physics, and at the end of a period the core's tick.
            hal.drive.step();
            n += 1;
            if n.is_multiple_of(subs) {
                let late = Instant::now()
                    .saturating_duration_since(deadline)
                    .as_secs_f64();
                if late > self.cfg.sample_period_s {
                    late_ticks += 1;
                }
                max_lateness_s = max_lateness_s.max(late);
                core.tick(&mut hal);
                if !core.is_running() {
                    idle_since = Instant::now();
                }
            }
        }
        let driving = core.is_running();
        if disconnected && driving {
            let text = "host side of the port closed during a run";
            hal.faults.push((FaultCode::Other, text.to_string()));
        }
        // Whatever ended serving (Ctrl-C, a closed port), the driver goes to 0 V.
        let output_at_exit_v = hal.drive.voltage_v() as f64;
        hal.drive.set_voltage(0.0);
        self.report.disconnected = disconnected;
        self.report.late_ticks += late_ticks;
        self.report.max_lateness_s = self.report.max_lateness_s.max(max_lateness_s);
        self.report.driving_at_exit = driving && !disconnected;
        self.report.output_at_exit_v = if disconnected { 0.0 } else { output_at_exit_v };
        // A new core: the board restarts idle if served again.
        if driving {
            self.core = BoardCore::new(*self.core.config())
                .map_err(|e| HwError::Protocol(e.to_string()))?;
        }
        Ok(self.report())
    }
}

enum Received {
    Bytes(usize),
    Nothing,
    Closed,
}

/// Reads what arrives before `deadline` into `buf` (returns at the first bytes).
fn receive(
    port: &mut dyn SerialPort,
    deadline: Instant,
    buf: &mut [u8],
) -> Result<Received, HwError> {
    loop {
        let Some(wait) = deadline
            .checked_duration_since(Instant::now())
            .filter(|d| !d.is_zero())
        else {
            return Ok(Received::Nothing);
        };
        port.set_timeout(wait)?;
        match port.read(buf) {
            Ok(0) => return Ok(Received::Closed),
            Ok(n) => return Ok(Received::Bytes(n)),
            Err(e) if e.kind() == ErrorKind::TimedOut => return Ok(Received::Nothing),
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) if matches!(e.kind(), ErrorKind::BrokenPipe) || e.raw_os_error() == Some(5) => {
                return Ok(Received::Closed)
            }
            Err(e) => {
                // EIO and friends from a pty whose other side went away.
                if e.to_string().contains("Input/output") {
                    return Ok(Received::Closed);
                }
                return Err(HwError::Io(e));
            }
        }
    }
}
