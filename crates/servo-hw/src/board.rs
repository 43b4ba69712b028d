//! The virtual board: what the firmware of a servo board does, with the simulated gearmotor
//! behind it, speaking the protocol of [`servo_core::protocol`] over a serial port in real time.
//!
//! Firmware behaviour (the reference for a real board, see `docs/protocol.md`):
//! * Hello → HelloAck with firmware name, encoder counts/rev, current-sense scale, voltage limit,
//!   sample period and watchdog time.
//! * Start → encoder and board clock zeroed, Sample 0 sent at once, then one Sample every period,
//!   paced by the board's clock. SetVoltage(seq, u) is applied from the next physics sub-step after
//!   it arrives (sub-steps of period/`physics_substeps`), clipped by the voltage limit; a command
//!   older than the last applied one is ignored.
//! * Watchdog: no SetVoltage (or LoopReference in on-board mode) for `watchdog_s` → 0 V, Fault
//!   (Watchdog), sampling stops until the next Start.
//! * Safety ([`SafetyLimits`], the same checks the host runs): every sample is checked for
//!   over-current and soft position limits; a trip means 0 V, a Fault and sampling stops.
//! * Stop → 0 V, Stopped, sampling stops.
//! * On-board loop: LoopGains then LoopReference(seq, ref) runs a PID on the board every period
//!   towards ref; Samples stream as in host-driven mode with the ONBOARD_LOOP flag.
//!
//! The plant is integrated in simulated time, one sub-step per wall-clock sub-step: a late
//! wake-up (the host machine is busy) is caught up at once and counted, never skipped. While
//! idle the plant keeps coasting at 0 V so that a second run starts from where the load is.

use crate::backend::HwError;
use serialport::SerialPort;
use servo_core::control::{AntiWindup, Pid, PidConfig, PidGains};
use servo_core::math;
use servo_core::protocol::{
    fixed_text, flags, Decoder, Fault, FaultCode, Frame, HelloAck, LoopGains, Message, Sample,
    PROTOCOL_VERSION,
};
use servo_core::safety::SafetyLimits;
use servo_core::sim::{PlantSim, SensorConfig, Sensors};
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

/// State of one run (between Start and Stop/fault).
#[derive(Debug)]
struct Run {
    t0: Instant,
    /// Index of the last sample sent.
    k: u32,
    sample_sent_at: Instant,
    cmd_for_k: Option<Instant>,
    last_cmd_at: Instant,
    last_seq_applied: Option<u32>,
    u_v: f64,
    clipped: bool,
    count0: i64,
    onboard: Option<(Pid, f64)>,
}

/// The virtual board.
#[derive(Debug)]
pub struct VirtualBoard {
    cfg: BoardConfig,
    sim: PlantSim,
    sensors: Sensors,
    dec: Decoder,
    gains: Option<LoopGains>,
    report: BoardReport,
    idle_since: Instant,
    bad_cmd_reported: bool,
    /// Driver input being applied now [V] (0 when idle).
    output_v: f64,
}

enum Link {
    Open,
    Closed,
}

impl VirtualBoard {
    /// A board for `plant` with its sensors and firmware constants.
    pub fn new(
        plant: &Plant,
        sensors: SensorConfig,
        cfg: BoardConfig,
    ) -> Result<VirtualBoard, HwError> {
        cfg.validate()?;
        let h = cfg.sample_period_s / cfg.physics_substeps as f64;
        Ok(VirtualBoard {
            cfg,
            sim: PlantSim::new(plant, h)?,
            sensors: Sensors::new(sensors),
            dec: Decoder::new(),
            gains: None,
            report: BoardReport::default(),
            idle_since: Instant::now(),
            bad_cmd_reported: false,
            output_v: 0.0,
        })
    }

    /// The handshake answer of this board.
    pub fn hello_ack(&self) -> HelloAck {
        HelloAck {
            protocol_version: PROTOCOL_VERSION,
            firmware: fixed_text(FIRMWARE),
            counts_per_rev: self.sensors.config().counts_per_rev,
            current_scale_a_per_lsb: self.cfg.current_scale_a_per_lsb as f32,
            voltage_limit_v: self.cfg.limits.voltage_limit_v as f32,
            sample_period_us: math::round(self.cfg.sample_period_s * 1e6) as u32,
            watchdog_ms: math::round(self.cfg.watchdog_s * 1e3).min(65_535.0) as u16,
        }
    }

    /// The true plant simulator behind the board.
    pub fn plant_sim(&self) -> &PlantSim {
        &self.sim
    }

    /// The driver input the board applies right now [V]: 0 V whenever no run is active.
    pub fn output_v(&self) -> f64 {
        self.output_v
    }

    /// What happened so far.
    pub fn report(&self) -> BoardReport {
        let mut r = self.report.clone();
        let s = self.dec.stats();
        r.crc_errors = s.crc_errors;
        r.framing_errors = s.framing_errors;
        r
    }

    /// Serves the protocol on `port` until `stop` is set or the host side closes (POLLHUP).
    /// I/O errors other than a closed peer are returned.
    pub fn serve(
        &mut self,
        port: &mut dyn SerialPort,
        stop: &AtomicBool,
    ) -> Result<BoardReport, HwError> {
        let mut run: Option<Run> = None;
        let mut msgs = Vec::new();
        self.idle_since = Instant::now();
        while !stop.load(Ordering::Relaxed) {
            match run.take() {
                None => {
                    let link =
                        self.receive(port, Instant::now() + Duration::from_millis(50), &mut msgs)?;
                    self.coast_idle();
                    for (at, m) in msgs.drain(..) {
                        if run.is_none() {
                            run = self.handle_idle(port, m, at)?;
                        } else if let Some(r) = run.as_mut() {
                            if !self.handle_running(port, r, m, at)? {
                                run = None;
                            }
                        }
                    }
                    if let Link::Closed = link {
                        self.report.disconnected = true;
                        break;
                    }
                }
                Some(mut r) => {
                    let (keep, link) = self.tick(port, &mut r, &mut msgs)?;
                    if keep {
                        run = Some(r);
                    } else {
                        self.output_v = 0.0;
                        self.idle_since = Instant::now();
                    }
                    if let Link::Closed = link {
                        self.output_v = 0.0;
                        self.report.disconnected = true;
                        let text = "host side of the port closed during a run";
                        self.report
                            .faults
                            .push((FaultCode::Other, text.to_string()));
                        break;
                    }
                }
            }
        }
        // Whatever ended serving (Ctrl-C, a closed port), the driver goes to 0 V.
        self.report.driving_at_exit = run.is_some();
        self.report.output_at_exit_v = self.output_v;
        self.output_v = 0.0;
        Ok(self.report())
    }

    /// One control period: sub-steps of physics with commands applied as they arrive, then the
    /// safety check and the next sample. Returns whether the run goes on.
    fn tick(
        &mut self,
        port: &mut dyn SerialPort,
        r: &mut Run,
        msgs: &mut Vec<(Instant, Message)>,
    ) -> Result<(bool, Link), HwError> {
        let s = self.cfg.physics_substeps;
        let h = Duration::from_secs_f64(self.cfg.sample_period_s / s as f64);
        let watchdog = Duration::from_secs_f64(self.cfg.watchdog_s);
        for j in 1..=s {
            let deadline = r.t0 + h * (r.k.wrapping_mul(s).wrapping_add(j));
            loop {
                let link = self.receive(port, deadline, msgs)?;
                for (at, m) in msgs.drain(..) {
                    if !self.handle_running(port, r, m, at)? {
                        return Ok((false, link));
                    }
                }
                if let Link::Closed = link {
                    return Ok((false, link));
                }
                if Instant::now() >= deadline {
                    break;
                }
            }
            if r.last_cmd_at.elapsed() > watchdog {
                r.u_v = 0.0;
                let what = if r.onboard.is_some() {
                    "reference"
                } else {
                    "command"
                };
                // Fits the 32-byte fault text: "watchdog: no reference in 50 ms".
                let text = format!("watchdog: no {what} in {} ms", watchdog.as_millis());
                self.fault(port, FaultCode::Watchdog, &text)?;
                return Ok((false, Link::Open));
            }
            self.output_v = r.u_v;
            self.sim.step(r.u_v);
        }
        // The period is over: sample k+1.
        let due = r.t0 + h * (r.k.wrapping_add(1).wrapping_mul(s));
        let late = Instant::now().saturating_duration_since(due).as_secs_f64();
        if late > self.cfg.sample_period_s {
            self.report.late_ticks += 1;
        }
        self.report.max_lateness_s = self.report.max_lateness_s.max(late);
        let missed = r.onboard.is_none() && r.cmd_for_k.is_none();
        if missed {
            self.report.missed_deadlines += 1;
        }
        let rtt_us = match r.cmd_for_k {
            Some(at) => at
                .saturating_duration_since(r.sample_sent_at)
                .as_micros()
                .min(0xFFFE) as u16,
            None => 0xFFFF,
        };
        r.k = r.k.wrapping_add(1);
        let u_applied = r.u_v;
        let was_clipped = r.clipped;
        let flags = if missed { flags::MISSED_DEADLINE } else { 0 }
            | if r.onboard.is_some() {
                flags::ONBOARD_LOOP
            } else {
                0
            }
            | if was_clipped {
                flags::VOLTAGE_CLIPPED
            } else {
                0
            };
        let keep = self.send_sample(port, r, u_applied, rtt_us, flags)?;
        Ok((keep, Link::Open))
    }

    /// Measures, checks the limits, runs the on-board PID if active, and sends the sample.
    fn send_sample(
        &mut self,
        port: &mut dyn SerialPort,
        r: &mut Run,
        u_applied_v: f64,
        rtt_us: u16,
        flags: u8,
    ) -> Result<bool, HwError> {
        let m = self.sensors.measure(self.sim.state());
        let count = m.encoder_count - r.count0;
        let cpr = self.sensors.config().counts_per_rev;
        let theta = if cpr > 0 {
            count as f64 * math::TAU / cpr as f64
        } else {
            m.theta_l_rad
        };
        if let Err(trip) = self.cfg.limits.check(self.sim.state().theta_l_rad, m.i_a_a) {
            r.u_v = 0.0;
            self.fault(port, trip.into(), &trip.to_string())?;
            return Ok(false);
        }
        if let Some((pid, ref_rad)) = r.onboard.as_mut() {
            r.u_v = pid.update(*ref_rad, theta, 0.0).u_v;
        }
        let sample = Sample {
            seq: r.k,
            time_us: (r.k as u64 * math::round(self.cfg.sample_period_s * 1e6) as u64) as u32,
            encoder_count: count.clamp(i32::MIN as i64, i32::MAX as i64) as i32,
            current_raw: math::round(m.i_a_a / self.cfg.current_scale_a_per_lsb)
                .clamp(-32768.0, 32767.0) as i16,
            u_applied_v: u_applied_v as f32,
            rtt_us,
            flags,
        };
        self.send(port, &Message::Sample(sample))?;
        r.sample_sent_at = Instant::now();
        r.cmd_for_k = None;
        self.report.samples += 1;
        Ok(true)
    }

    fn start_run(
        &mut self,
        port: &mut dyn SerialPort,
        at: Instant,
        onboard: Option<(Pid, f64)>,
    ) -> Result<Option<Run>, HwError> {
        self.coast_idle();
        self.report.runs += 1;
        self.bad_cmd_reported = false;
        let count0 = self.sensors.measure(self.sim.state()).encoder_count;
        let now = Instant::now();
        let mut r = Run {
            t0: now,
            k: 0,
            sample_sent_at: now,
            cmd_for_k: None,
            last_cmd_at: now,
            last_seq_applied: None,
            u_v: 0.0,
            clipped: false,
            count0,
            onboard,
        };
        let _ = at;
        let keep = self.send_sample(port, &mut r, 0.0, 0xFFFF, 0)?;
        Ok(keep.then_some(r))
    }

    fn handle_idle(
        &mut self,
        port: &mut dyn SerialPort,
        m: Message,
        at: Instant,
    ) -> Result<Option<Run>, HwError> {
        match m {
            Message::Hello { protocol_version } => self.hello(port, protocol_version)?,
            Message::Start => return self.start_run(port, at, None),
            Message::Stop => self.send(port, &Message::Stopped)?,
            Message::LoopGains(g) => self.set_gains(port, g)?,
            Message::LoopReference { ref_rad, .. } => match self.gains {
                Some(g) if ref_rad.is_finite() => match self.onboard_pid(g) {
                    Some(pid) => return self.start_run(port, at, Some((pid, ref_rad as f64))),
                    None => self.bad_command(port, "invalid loop gains")?,
                },
                _ => self.bad_command(port, "LoopReference without valid gains")?,
            },
            Message::SetVoltage { .. } => self.bad_command(port, "SetVoltage while not started")?,
            // Board-to-host messages echoed back (e.g. a loopback): ignore.
            _ => {}
        }
        Ok(None)
    }

    /// Handles a message during a run; returns whether the run goes on.
    fn handle_running(
        &mut self,
        port: &mut dyn SerialPort,
        r: &mut Run,
        m: Message,
        at: Instant,
    ) -> Result<bool, HwError> {
        match m {
            Message::SetVoltage { seq, u_v } => {
                let newer = r
                    .last_seq_applied
                    .is_none_or(|l| (seq.wrapping_sub(l) as i32) > 0);
                if !newer {
                    return Ok(true);
                }
                if !u_v.is_finite() {
                    r.u_v = 0.0;
                    self.fault(port, FaultCode::BadCommand, "non-finite voltage command")?;
                    return Ok(false);
                }
                let (u, clipped) = self.cfg.limits.clamp_voltage(u_v as f64);
                r.u_v = u;
                r.clipped = clipped;
                r.onboard = None;
                r.last_seq_applied = Some(seq);
                r.last_cmd_at = at;
                if seq == r.k && r.cmd_for_k.is_none() {
                    r.cmd_for_k = Some(at);
                }
            }
            Message::LoopReference { ref_rad, .. } => {
                let Some(g) = self.gains else {
                    r.u_v = 0.0;
                    self.fault(port, FaultCode::BadCommand, "LoopReference without gains")?;
                    return Ok(false);
                };
                if !ref_rad.is_finite() {
                    r.u_v = 0.0;
                    self.fault(port, FaultCode::BadCommand, "non-finite reference")?;
                    return Ok(false);
                }
                match (r.onboard.as_mut(), self.onboard_pid(g)) {
                    (Some((_, rf)), _) => *rf = ref_rad as f64,
                    (None, Some(pid)) => r.onboard = Some((pid, ref_rad as f64)),
                    (None, None) => {
                        r.u_v = 0.0;
                        self.fault(port, FaultCode::BadCommand, "invalid loop gains")?;
                        return Ok(false);
                    }
                }
                r.last_cmd_at = at;
            }
            Message::Stop => {
                r.u_v = 0.0;
                self.send(port, &Message::Stopped)?;
                return Ok(false);
            }
            Message::Start => {
                // Restart: clock and encoder zeroed, the load stays where it is.
                if let Some(nr) = self.start_run(port, at, None)? {
                    *r = nr;
                } else {
                    return Ok(false);
                }
            }
            Message::Hello { protocol_version } => self.hello(port, protocol_version)?,
            Message::LoopGains(g) => self.set_gains(port, g)?,
            _ => {}
        }
        Ok(true)
    }

    fn hello(&mut self, port: &mut dyn SerialPort, version: u16) -> Result<(), HwError> {
        if version != PROTOCOL_VERSION {
            let text = format!("host speaks v{version}, board v{PROTOCOL_VERSION}");
            return self.fault(port, FaultCode::Version, &text);
        }
        self.send(port, &Message::HelloAck(self.hello_ack()))
    }

    /// The firmware's PID for the on-board loop: servo's discrete PID (backward Euler, real
    /// derivative with T_L = tau_f_s, clamping anti-windup, limited to the voltage limit).
    fn onboard_pid(&self, g: LoopGains) -> Option<Pid> {
        let gains = PidGains {
            kp: g.kp as f64,
            ki: g.ki as f64,
            kd: g.kd as f64,
            tl_s: g.tau_f_s as f64,
        };
        let cfg = PidConfig {
            anti_windup: AntiWindup::Clamping,
            ..PidConfig::new(gains, self.cfg.sample_period_s)
                .with_symmetric_limit(self.cfg.limits.voltage_limit_v)
        };
        Pid::new(cfg).ok()
    }

    fn set_gains(&mut self, port: &mut dyn SerialPort, g: LoopGains) -> Result<(), HwError> {
        if self.onboard_pid(g).is_none() {
            return self.bad_command(port, "invalid loop gains");
        }
        self.gains = Some(g);
        self.send(port, &Message::GainsAck)
    }

    fn bad_command(&mut self, port: &mut dyn SerialPort, text: &str) -> Result<(), HwError> {
        if self.bad_cmd_reported {
            return Ok(());
        }
        self.bad_cmd_reported = true;
        self.fault(port, FaultCode::BadCommand, text)
    }

    fn fault(
        &mut self,
        port: &mut dyn SerialPort,
        code: FaultCode,
        text: &str,
    ) -> Result<(), HwError> {
        self.report.faults.push((code, text.to_string()));
        self.bad_cmd_reported = true;
        self.send(port, &Message::Fault(Fault::new(code, text)))
    }

    /// Advances the plant at 0 V over the wall time spent idle (at most 1 s per call).
    fn coast_idle(&mut self) {
        let h = self.sim.dt_s();
        let idle = self.idle_since.elapsed().as_secs_f64().min(1.0);
        let steps = (idle / h) as u64;
        for _ in 0..steps {
            self.sim.step(0.0);
        }
        self.idle_since = Instant::now();
    }

    /// Sends one frame. A write that times out (nobody reading a full pty) drops the frame.
    fn send(&mut self, port: &mut dyn SerialPort, m: &Message) -> Result<(), HwError> {
        let f = Frame::new(m);
        match port.write_all(f.as_bytes()) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == ErrorKind::TimedOut => Ok(()),
            Err(e) if matches!(e.kind(), ErrorKind::BrokenPipe) => Ok(()),
            Err(e) => Err(HwError::Io(e)),
        }
    }

    /// Reads and decodes until `deadline`, appending (arrival, message) to `out`.
    fn receive(
        &mut self,
        port: &mut dyn SerialPort,
        deadline: Instant,
        out: &mut Vec<(Instant, Message)>,
    ) -> Result<Link, HwError> {
        let mut buf = [0u8; 256];
        loop {
            let now = Instant::now();
            let Some(wait) = deadline
                .checked_duration_since(now)
                .filter(|d| !d.is_zero())
            else {
                return Ok(Link::Open);
            };
            port.set_timeout(wait)?;
            match port.read(&mut buf) {
                Ok(0) => return Ok(Link::Closed),
                Ok(n) => {
                    let at = Instant::now();
                    self.dec.feed(&buf[..n], |r| {
                        if let Ok(m) = r {
                            out.push((at, m));
                        }
                    });
                    if !out.is_empty() {
                        // Handle what arrived now; the caller comes back for the rest.
                        return Ok(Link::Open);
                    }
                }
                Err(e) if e.kind() == ErrorKind::TimedOut => return Ok(Link::Open),
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e)
                    if matches!(e.kind(), ErrorKind::BrokenPipe) || e.raw_os_error() == Some(5) =>
                {
                    return Ok(Link::Closed)
                }
                Err(e) => {
                    // EIO and friends from a pty whose other side went away.
                    if e.to_string().contains("Input/output") {
                        return Ok(Link::Closed);
                    }
                    return Err(HwError::Io(e));
                }
            }
        }
    }
}
