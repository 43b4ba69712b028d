//! The board core: the firmware of a servo board as `docs/protocol.md` defines it, written once
//! against the small hardware abstraction [`BoardHal`]. `no_std`, no heap, never panics on any
//! input.
//!
//! The same [`BoardCore`] runs in three places:
//! * the virtual board of `servo board --pty` (`servo_hw::board`), whose HAL is servo's simulated
//!   gearmotor stepped in real time on the host;
//! * the QEMU image of `firmware/qemu` (a Cortex-M4 `mps2-an386` machine), whose HAL drives the
//!   same simulated plant on the emulated microcontroller;
//! * the real firmware of `firmware/nucleo-f446re`, whose HAL is a timer in quadrature-encoder
//!   mode, a DAC or PWM output and an ADC on the current shunt.
//!
//! # How a firmware drives the core
//!
//! ```text
//! reset:            core = BoardCore::new(config)?          (hal.set_voltage(0.0) first)
//! serial RX bytes:  core.receive(&mut hal, bytes)           (any chunking, any time)
//! periodic tick:    core.tick(&mut hal)                     (every sample_period_us)
//! ```
//!
//! `receive` and `tick` must not run concurrently (call both from the main loop, or both from
//! interrupts of the same priority). The core applies a voltage command through
//! [`BoardHal::set_voltage`] as soon as `receive` decodes it, and asks the HAL to restart its
//! periodic tick at Start ([`BoardHal::restart_tick`]) so that Sample k is due k periods after
//! Start by the board's own clock.
//!
//! # State machine (docs/protocol.md, "Session")
//!
//! * **Idle** (after reset, Stop, a fault): 0 V. Hello → HelloAck (or Fault(Version)); Stop →
//!   Stopped; LoopGains → GainsAck (invalid gains → Fault(BadCommand)); Start → Running
//!   (host-driven); LoopReference with valid gains → Running (on-board PID), without them →
//!   Fault(BadCommand); SetVoltage → Fault(BadCommand), every time, except the late answers
//!   to the samples of a run a fault just ended (`seq` up to one past its last sample, until the
//!   next Hello, Start or Stop): those were sent before the host heard of the fault.
//! * **Running**: Sample 0 at once, then one Sample per tick. SetVoltage(seq, u) with a newer seq
//!   is clipped to the voltage limit and applied at once (and ends on-board mode); LoopReference
//!   moves the on-board reference. A command for Sample k that has not arrived by tick k+1 sets
//!   `MISSED_DEADLINE` on Sample k+1 and the previous voltage is held.
//! * **Watchdog**: no SetVoltage (LoopReference in on-board mode) for `watchdog_ms` → 0 V,
//!   Fault(Watchdog), Idle. Checked at every tick, so the trip comes within watchdog_ms plus one
//!   period.
//! * **Safety**: every sample checks the measured current and the encoder angle since Start
//!   against [`SafetyLimits`] → 0 V, Fault(OverCurrent/PositionLimit), Idle. A non-finite command
//!   is Fault(BadCommand).

use crate::control::{AntiWindup, LoopCompensation, Pid, PidConfig, PidGains, RefSample};
use crate::math;
use crate::protocol::{
    flags, Decoder, DecoderStats, Fault, FaultCode, Frame, HelloAck, LoopGains, Message, Sample,
    PROTOCOL_VERSION,
};
use crate::safety::SafetyLimits;

/// What the core needs from the hardware. Every method must return quickly (no blocking longer
/// than a few microseconds): they are called from the control loop.
pub trait BoardHal {
    /// A free-running microsecond clock [us] that wraps at 2^32 (only differences are used).
    fn now_us(&mut self) -> u32;
    /// The quadrature encoder position [counts at the load, `counts_per_rev` per revolution].
    /// Free-running, wrapping at the i32 range; the core subtracts the count at Start.
    fn encoder_count(&mut self) -> i32;
    /// The armature current from the current-sense ADC, offset removed [LSB of
    /// `current_scale_a_per_lsb`], saturated at the i16 range.
    fn current_raw(&mut self) -> i16;
    /// Applies the driver input `u_v` [V] now and holds it (already within the voltage limit).
    /// 0.0 means the motor is not driven.
    fn set_voltage(&mut self, u_v: f32);
    /// Restarts the periodic tick: the next [`BoardCore::tick`] comes one sample period from now.
    fn restart_tick(&mut self);
    /// Queues `bytes` (one whole frame) for the serial link. Should not block; a link that
    /// cannot take the frame drops it (the protocol survives lost frames).
    fn write(&mut self, bytes: &[u8]);
    /// Called when the board raises a fault (after 0 V was applied), for logging. Optional.
    fn on_fault(&mut self, _code: FaultCode, _text: &str) {}
}

/// The firmware's constants, reported in HelloAck.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoardConfig {
    /// Firmware name (UTF-8, NUL-padded, at most 16 bytes).
    pub firmware: [u8; 16],
    /// Control (sample) period [us], 50 us ..= 1 s.
    pub sample_period_us: u32,
    /// Watchdog time [ms]: longer than the period, at most 65 535 ms.
    pub watchdog_ms: u16,
    /// Voltage limit, soft position limits (from Start), over-current trip.
    pub limits: SafetyLimits,
    /// Encoder counts per load revolution [counts/rev], > 0.
    pub counts_per_rev: u32,
    /// Current-sense scale [A/LSB], > 0.
    pub current_scale_a_per_lsb: f32,
}

/// Why a [`BoardConfig`] is unusable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum BoardConfigError {
    #[error("board sample period must be between 50 us and 1 s, got {0} us")]
    Period(u32),
    #[error("board watchdog must be longer than the sample period, got {0} ms")]
    Watchdog(u16),
    #[error("encoder counts per revolution must be > 0")]
    CountsPerRev,
    #[error("current scale must be > 0 A/LSB and finite, got {0}")]
    CurrentScale(f32),
    #[error("safety limits: {0}")]
    Limits(#[from] crate::safety::LimitsError),
}

impl BoardConfig {
    /// Checks every field (see their docs).
    pub fn validate(&self) -> Result<(), BoardConfigError> {
        if !(50..=1_000_000).contains(&self.sample_period_us) {
            return Err(BoardConfigError::Period(self.sample_period_us));
        }
        if (self.watchdog_ms as u64) * 1000 <= self.sample_period_us as u64 {
            return Err(BoardConfigError::Watchdog(self.watchdog_ms));
        }
        if self.counts_per_rev == 0 {
            return Err(BoardConfigError::CountsPerRev);
        }
        let s = self.current_scale_a_per_lsb;
        if !(s > 0.0 && s.is_finite()) {
            return Err(BoardConfigError::CurrentScale(s));
        }
        self.limits.validate()?;
        Ok(())
    }

    /// The handshake answer of a board with this configuration.
    pub fn hello_ack(&self) -> HelloAck {
        HelloAck {
            protocol_version: PROTOCOL_VERSION,
            firmware: self.firmware,
            counts_per_rev: self.counts_per_rev,
            current_scale_a_per_lsb: self.current_scale_a_per_lsb,
            voltage_limit_v: self.limits.voltage_limit_v as f32,
            sample_period_us: self.sample_period_us,
            watchdog_ms: self.watchdog_ms,
        }
    }
}

/// Counters of a board since reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BoardStats {
    /// Runs started (Start, or LoopReference from idle).
    pub runs: u64,
    /// Samples sent.
    pub samples: u64,
    /// Periods whose command did not arrive before the next sample was due.
    pub missed_deadlines: u64,
    /// Faults raised.
    pub faults: u64,
}

/// One run, between Start and Stop or a fault.
#[derive(Debug, Clone)]
struct Run {
    /// Index of the last sample sent.
    k: u32,
    sample_sent_us: u32,
    /// Arrival time of the command answering sample k.
    cmd_for_k_us: Option<u32>,
    last_cmd_us: u32,
    last_seq_applied: Option<u32>,
    u_v: f32,
    clipped: bool,
    count0: i32,
    /// On-board PID and its reference [rad].
    onboard: Option<(Pid, f64)>,
}

/// The board's state machine (see the module documentation).
#[derive(Debug, Clone)]
pub struct BoardCore {
    cfg: BoardConfig,
    dec: Decoder,
    gains: Option<LoopGains>,
    run: Option<Run>,
    /// The index of the last sample of the run a fault ended, until the next Hello, Start or
    /// Stop: SetVoltage answers up to one past it are late, not out of order.
    faulted_run_k: Option<u32>,
    stats: BoardStats,
    /// The compensation of the on-board loop (issue #29), set by the firmware.
    compensation: Option<LoopCompensation>,
}

impl BoardCore {
    /// A board at rest. The caller applies 0 V before (the core only drives the output on
    /// events).
    pub fn new(cfg: BoardConfig) -> Result<BoardCore, BoardConfigError> {
        cfg.validate()?;
        Ok(BoardCore {
            cfg,
            dec: Decoder::new(),
            gains: None,
            run: None,
            faulted_run_k: None,
            stats: BoardStats::default(),
            compensation: None,
        })
    }

    /// Compensates the identified effects in the on-board loop (LoopReference): the effects'
    /// torques at the measured angle (an unbalanced load, a periodic motor torque) and the reference's (a
    /// holding reference has no speed), the inverted input maps on the PID's output and the PID's
    /// limit narrowed for them ([`LoopCompensation`]); `None` switches it off. The same value
    /// `servo run --ff` computes on the host; no heap. Takes effect at the next LoopReference
    /// from idle (the PID's limit is set when the loop starts).
    pub fn set_compensation(&mut self, compensation: Option<LoopCompensation>) {
        self.compensation = compensation;
    }

    /// The on-board loop's compensation, if any.
    pub fn compensation(&self) -> Option<&LoopCompensation> {
        self.compensation.as_ref()
    }

    /// The configuration.
    pub fn config(&self) -> &BoardConfig {
        &self.cfg
    }

    /// Counters since reset.
    pub fn stats(&self) -> BoardStats {
        self.stats
    }

    /// Counters of the frame decoder (CRC and framing errors).
    pub fn decoder_stats(&self) -> DecoderStats {
        self.dec.stats()
    }

    /// Whether a run is driving the motor.
    pub fn is_running(&self) -> bool {
        self.run.is_some()
    }

    /// The driver input the core commands now [V] (0 when idle).
    pub fn output_v(&self) -> f32 {
        self.run.as_ref().map_or(0.0, |r| r.u_v)
    }

    /// Feeds bytes received on the serial link; every complete frame is handled at once.
    pub fn receive<H: BoardHal + ?Sized>(&mut self, hal: &mut H, bytes: &[u8]) {
        for &b in bytes {
            if let Some(Ok(m)) = self.dec.push(b) {
                self.handle(hal, m);
            }
        }
    }

    /// The periodic tick, every `sample_period_us` after [`BoardHal::restart_tick`]: watchdog,
    /// then measurement, safety check, on-board PID and the next Sample. Does nothing when idle.
    pub fn tick<H: BoardHal + ?Sized>(&mut self, hal: &mut H) {
        let Some(r) = self.run.as_mut() else {
            return;
        };
        let now = hal.now_us();
        let watchdog_us = self.cfg.watchdog_ms as u32 * 1000;
        if now.wrapping_sub(r.last_cmd_us) > watchdog_us {
            let what = if r.onboard.is_some() {
                "reference"
            } else {
                "command"
            };
            let mut text = TextBuf::new();
            // Fits the 32-byte fault text: "watchdog: no reference in 50 ms".
            let _ = core::fmt::write(
                &mut text,
                format_args!("watchdog: no {what} in {} ms", self.cfg.watchdog_ms),
            );
            self.fault(hal, FaultCode::Watchdog, text.as_str());
            return;
        }
        let missed = r.onboard.is_none() && r.cmd_for_k_us.is_none();
        if missed {
            self.stats.missed_deadlines += 1;
        }
        let rtt_us = match r.cmd_for_k_us {
            Some(at) => at.wrapping_sub(r.sample_sent_us).min(0xFFFE) as u16,
            None => 0xFFFF,
        };
        r.k = r.k.wrapping_add(1);
        let u_applied = r.u_v;
        let flags = if missed { flags::MISSED_DEADLINE } else { 0 }
            | if r.onboard.is_some() {
                flags::ONBOARD_LOOP
            } else {
                0
            }
            | if r.clipped { flags::VOLTAGE_CLIPPED } else { 0 };
        self.send_sample(hal, u_applied, rtt_us, flags);
    }

    /// Measures, checks the limits, runs the on-board PID if active and sends the sample of the
    /// current run's `k`.
    fn send_sample<H: BoardHal + ?Sized>(
        &mut self,
        hal: &mut H,
        u_applied_v: f32,
        rtt_us: u16,
        flags: u8,
    ) {
        let count_now = hal.encoder_count();
        let current_raw = hal.current_raw();
        let Some(r) = self.run.as_mut() else {
            return;
        };
        let count = count_now.wrapping_sub(r.count0);
        let theta_rad = count as f64 * math::TAU / self.cfg.counts_per_rev as f64;
        let i_a_a = current_raw as f64 * self.cfg.current_scale_a_per_lsb as f64;
        if let Err(trip) = self.cfg.limits.check(theta_rad, i_a_a) {
            let mut text = TextBuf::new();
            let _ = core::fmt::write(&mut text, format_args!("{trip}"));
            self.fault(hal, trip.into(), text.as_str());
            return;
        }
        if let Some((pid, ref_rad)) = r.onboard.as_mut() {
            let u = match &self.compensation {
                Some(c) => {
                    let t_s = r.k as f64 * self.cfg.sample_period_us as f64 * 1e-6;
                    let limit = self.cfg.limits.voltage_limit_v;
                    let hold = RefSample {
                        pos_rad: *ref_rad,
                        vel_rad_s: 0.0,
                        acc_rad_s2: 0.0,
                    };
                    let ff = c.feedforward(&hold, t_s, theta_rad, f64::NAN).total_v;
                    c.command_v(pid.update(*ref_rad, theta_rad, ff).u_v, t_s, limit)
                }
                None => pid.update(*ref_rad, theta_rad, 0.0).u_v,
            };
            r.u_v = u as f32;
            hal.set_voltage(r.u_v);
        }
        let sample = Sample {
            seq: r.k,
            time_us: r.k.wrapping_mul(self.cfg.sample_period_us),
            encoder_count: count,
            current_raw,
            u_applied_v,
            rtt_us,
            flags,
        };
        hal.write(Frame::new(&Message::Sample(sample)).as_bytes());
        r.sample_sent_us = hal.now_us();
        r.cmd_for_k_us = None;
        self.stats.samples += 1;
    }

    fn start_run<H: BoardHal + ?Sized>(&mut self, hal: &mut H, onboard: Option<(Pid, f64)>) {
        self.stats.runs += 1;
        self.faulted_run_k = None;
        hal.set_voltage(0.0);
        hal.restart_tick();
        let now = hal.now_us();
        self.run = Some(Run {
            k: 0,
            sample_sent_us: now,
            cmd_for_k_us: None,
            last_cmd_us: now,
            last_seq_applied: None,
            u_v: 0.0,
            clipped: false,
            count0: hal.encoder_count(),
            onboard,
        });
        self.send_sample(hal, 0.0, 0xFFFF, 0);
    }

    fn handle<H: BoardHal + ?Sized>(&mut self, hal: &mut H, m: Message) {
        let now = hal.now_us();
        match m {
            Message::Hello { protocol_version } => {
                self.faulted_run_k = None;
                self.hello(hal, protocol_version)
            }
            Message::LoopGains(g) => {
                if self.onboard_pid(g).is_none() {
                    self.fault(hal, FaultCode::BadCommand, "invalid loop gains");
                } else {
                    self.gains = Some(g);
                    hal.write(Frame::new(&Message::GainsAck).as_bytes());
                }
            }
            Message::Start => self.start_run(hal, None),
            Message::Stop => {
                self.faulted_run_k = None;
                if self.run.take().is_some() {
                    hal.set_voltage(0.0);
                }
                hal.write(Frame::new(&Message::Stopped).as_bytes());
            }
            Message::SetVoltage { seq, u_v } => {
                let Some(r) = self.run.as_mut() else {
                    // A late answer to the run a fault just ended (the host's SetVoltage(0 V)
                    // before its Stop is one past the last sample): not out of order.
                    let late = self
                        .faulted_run_k
                        .is_some_and(|k| seq <= k.saturating_add(1));
                    if !late {
                        self.fault(hal, FaultCode::BadCommand, "SetVoltage before Start");
                    }
                    return;
                };
                let newer = r
                    .last_seq_applied
                    .is_none_or(|l| (seq.wrapping_sub(l) as i32) > 0);
                if !newer {
                    return;
                }
                if !u_v.is_finite() {
                    self.fault(hal, FaultCode::BadCommand, "non-finite voltage command");
                    return;
                }
                let (u, clipped) = self.cfg.limits.clamp_voltage(u_v as f64);
                r.u_v = u as f32;
                r.clipped = clipped;
                r.onboard = None;
                r.last_seq_applied = Some(seq);
                r.last_cmd_us = now;
                if seq == r.k && r.cmd_for_k_us.is_none() {
                    r.cmd_for_k_us = Some(now);
                }
                hal.set_voltage(r.u_v);
            }
            Message::LoopReference { ref_rad, .. } => {
                let pid = self.gains.and_then(|g| self.onboard_pid(g));
                let Some(pid) = pid else {
                    self.fault(hal, FaultCode::BadCommand, "LoopReference without gains");
                    return;
                };
                if !ref_rad.is_finite() {
                    self.fault(hal, FaultCode::BadCommand, "non-finite reference");
                    return;
                }
                match self.run.as_mut() {
                    None => self.start_run(hal, Some((pid, ref_rad as f64))),
                    Some(r) => {
                        match r.onboard.as_mut() {
                            Some((_, rf)) => *rf = ref_rad as f64,
                            None => r.onboard = Some((pid, ref_rad as f64)),
                        }
                        r.last_cmd_us = now;
                    }
                }
            }
            // Board-to-host messages echoed back (e.g. a loopback): ignored.
            Message::HelloAck(_)
            | Message::Sample(_)
            | Message::Fault(_)
            | Message::Stopped
            | Message::GainsAck => {}
        }
    }

    fn hello<H: BoardHal + ?Sized>(&mut self, hal: &mut H, version: u16) {
        if version != PROTOCOL_VERSION {
            let mut text = TextBuf::new();
            let _ = core::fmt::write(
                &mut text,
                format_args!("host speaks v{version}, board v{PROTOCOL_VERSION}"),
            );
            self.fault(hal, FaultCode::Version, text.as_str());
            return;
        }
        hal.write(Frame::new(&Message::HelloAck(self.cfg.hello_ack())).as_bytes());
    }

    /// The on-board PID: servo's discrete PID (backward Euler, real derivative with
    /// T_L = tau_f_s, clamping anti-windup, limited to the voltage limit).
    fn onboard_pid(&self, g: LoopGains) -> Option<Pid> {
        let gains = PidGains {
            kp: g.kp as f64,
            ki: g.ki as f64,
            kd: g.kd as f64,
            tl_s: g.tau_f_s as f64,
        };
        let limit = self.cfg.limits.voltage_limit_v;
        let cfg = PidConfig {
            anti_windup: AntiWindup::Clamping,
            ..PidConfig::new(gains, self.cfg.sample_period_us as f64 * 1e-6).with_symmetric_limit(
                self.compensation
                    .as_ref()
                    .map_or(limit, |c| c.pid_limit_v(limit)),
            )
        };
        Pid::new(cfg).ok()
    }

    /// 0 V, the run ends, Fault sent.
    fn fault<H: BoardHal + ?Sized>(&mut self, hal: &mut H, code: FaultCode, text: &str) {
        if let Some(r) = self.run.take() {
            hal.set_voltage(0.0);
            self.faulted_run_k = Some(r.k);
        }
        self.stats.faults += 1;
        hal.on_fault(code, text);
        hal.write(Frame::new(&Message::Fault(Fault::new(code, text))).as_bytes());
    }
}

/// A fault text being formatted: 32 bytes, truncated at a char boundary.
struct TextBuf {
    buf: [u8; crate::protocol::message::FAULT_TEXT_LEN],
    len: usize,
}

impl TextBuf {
    fn new() -> TextBuf {
        TextBuf {
            buf: [0; crate::protocol::message::FAULT_TEXT_LEN],
            len: 0,
        }
    }
    fn as_str(&self) -> &str {
        core::str::from_utf8(&self.buf[..self.len]).unwrap_or("")
    }
}

impl core::fmt::Write for TextBuf {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        for c in s.chars() {
            let mut b = [0u8; 4];
            let e = c.encode_utf8(&mut b).as_bytes();
            if self.len + e.len() > self.buf.len() {
                return Err(core::fmt::Error);
            }
            self.buf[self.len..self.len + e.len()].copy_from_slice(e);
            self.len += e.len();
        }
        Ok(())
    }
}

pub mod sim_drive;
pub use sim_drive::SimDrive;

#[cfg(test)]
mod tests;
