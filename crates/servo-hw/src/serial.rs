//! The serial backend: a board speaking [`servo_core::protocol`] over a serial port (USB CDC or
//! UART), driven by the host one period at a time.
//!
//! Per period: [`Backend::sample`] waits for the board's next Sample (the board's clock paces the
//! loop), [`Backend::apply`] answers it with SetVoltage carrying the same sequence number. The
//! backend measures the loop timing as it goes ([`LinkStats`]): period jitter of the samples'
//! arrival, the board-measured round trip (sample out → command in), missed deadlines, CRC and
//! framing errors, lost and out-of-order frames.
//!
//! Safety: the host applies the same [`SafetyLimits`] as the board (voltage clip, over-current,
//! soft position limits) on every sample; a trip is an error and the caller must call
//! [`Backend::stop`] (0 V). So is a loop that cannot keep the board's period
//! ([`crate::starvation`], [`HwError::Starved`]): watched from the first samples of each run,
//! which the host answers with 0 V for a short settle phase
//! ([`crate::starvation::settle_samples`]) before the caller sees any, so that such a loop is
//! refused before any voltage. A board that stays silent longer than `timeout_s` is an error too.
//! Dropping the backend sends Stop (best effort).

pub use crate::backend::LinkStats;
use crate::backend::{Backend, BoardInfo, HwError, Sample};
use crate::starvation::{StarvationWatch, Starved};
use serialport::{ClearBuffer, SerialPort};
use servo_core::math;
use servo_core::protocol::{flags, Decoder, Frame, HelloAck, Message, PROTOCOL_VERSION};
use servo_core::safety::SafetyLimits;
use std::collections::VecDeque;
use std::io::ErrorKind;
use std::time::{Duration, Instant};

/// How to reach and supervise a board.
#[derive(Debug, Clone, PartialEq)]
pub struct SerialConfig {
    /// Port path, e.g. `/dev/ttyACM0`.
    pub port: String,
    /// Baud rate [bit/s] (ignored by USB CDC and pseudo-terminals).
    pub baud: u32,
    /// A board silent for this long during a run is lost [s].
    pub timeout_s: f64,
    /// Time to wait for each handshake attempt [s].
    pub handshake_timeout_s: f64,
    /// Host-side limits; the voltage limit is further reduced to the board's.
    pub limits: SafetyLimits,
    /// Stop a run whose loop cannot keep the board's period ([`crate::starvation`]); on by
    /// default (off only for tests of the link itself, which lose frames on purpose).
    pub watch_starvation: bool,
}

impl Default for SerialConfig {
    fn default() -> Self {
        SerialConfig {
            port: "/dev/ttyACM0".into(),
            baud: 115_200,
            timeout_s: 0.25,
            handshake_timeout_s: 0.5,
            limits: SafetyLimits::default(),
            watch_starvation: true,
        }
    }
}

/// p-quantile (0..=1) of `v` by nearest rank; 0 for an empty set.
fn quantile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let i = (p * v.len() as f64).ceil().max(1.0) as usize - 1;
    v[i.min(v.len() - 1)]
}

/// A board on a serial port.
pub struct SerialBackend {
    port: Box<dyn SerialPort>,
    cfg: SerialConfig,
    dec: Decoder,
    hello: HelloAck,
    info: BoardInfo,
    limits: SafetyLimits,
    inbox: VecDeque<Message>,
    started: bool,
    stopped: bool,
    /// Sequence and unwrapped board time of the last sample.
    last_seq: Option<u32>,
    time_base_us: u64,
    last_time_us: Option<u32>,
    last_arrival: Option<Instant>,
    jitter_s: Vec<f64>,
    rtt_s: Vec<f64>,
    stats: LinkStats,
    /// Whether the run keeps the board's period (reset at each Start).
    watch: StarvationWatch,
    /// Board time at the end of the run's 0 V settle phase [s]: the caller's samples are timed
    /// from there.
    settle_end_s: f64,
}

impl std::fmt::Debug for SerialBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SerialBackend")
            .field("port", &self.cfg.port)
            .field("info", &self.info)
            .finish()
    }
}

impl SerialBackend {
    /// Opens `cfg.port` at `cfg.baud` and performs the handshake.
    pub fn open(cfg: SerialConfig) -> Result<SerialBackend, HwError> {
        let port = serialport::new(&cfg.port, cfg.baud)
            .timeout(Duration::from_millis(100))
            .open()
            .map_err(|e| HwError::Protocol(format!("cannot open serial port {}: {e}", cfg.port)))?;
        SerialBackend::from_port(port, cfg)
    }

    /// Performs the handshake on an already open port (e.g. one end of a pty pair).
    pub fn from_port(
        port: Box<dyn SerialPort>,
        cfg: SerialConfig,
    ) -> Result<SerialBackend, HwError> {
        cfg.limits
            .validate()
            .map_err(|e| HwError::Safety(e.to_string()))?;
        if !(cfg.timeout_s > 0.0 && cfg.handshake_timeout_s > 0.0) {
            return Err(HwError::Protocol("serial timeouts must be > 0 s".into()));
        }
        // Stale bytes from a previous session are garbage now.
        let _ = port.clear(ClearBuffer::Input);
        let port = port;
        let mut me = SerialBackend {
            port,
            dec: Decoder::new(),
            hello: HelloAck {
                protocol_version: 0,
                firmware: [0; 16],
                counts_per_rev: 0,
                current_scale_a_per_lsb: 0.0,
                voltage_limit_v: 0.0,
                sample_period_us: 0,
                watchdog_ms: 0,
            },
            info: BoardInfo {
                firmware: "",
                counts_per_rev: 0,
                voltage_limit_v: 0.0,
                sample_period_s: 0.0,
            },
            limits: cfg.limits,
            inbox: VecDeque::new(),
            started: false,
            stopped: false,
            last_seq: None,
            time_base_us: 0,
            last_time_us: None,
            last_arrival: None,
            jitter_s: Vec::new(),
            rtt_s: Vec::new(),
            stats: LinkStats::default(),
            watch: StarvationWatch::new(1.0),
            settle_end_s: 0.0,
            cfg,
        };
        me.handshake()?;
        Ok(me)
    }

    fn handshake(&mut self) -> Result<(), HwError> {
        // A lone delimiter ends any partial frame the board may hold.
        self.write_raw(&[0])?;
        let wait = Duration::from_secs_f64(self.cfg.handshake_timeout_s);
        for _attempt in 0..3 {
            self.send(&Message::Hello {
                protocol_version: PROTOCOL_VERSION,
            })?;
            let deadline = Instant::now() + wait;
            while let Some(m) = self.next_message(deadline)? {
                match m {
                    Message::HelloAck(h) => return self.accept_hello(h),
                    Message::Fault(f) => {
                        return Err(HwError::Fault {
                            code: f.code.to_u16(),
                            text: f.text_str().to_string(),
                        })
                    }
                    _ => {} // leftovers of a previous session
                }
            }
        }
        Err(HwError::Protocol(format!(
            "no handshake answer from {} after 3 attempts of {} ms (is a servo board connected, at {} baud?)",
            self.cfg.port,
            wait.as_millis(),
            self.cfg.baud
        )))
    }

    fn accept_hello(&mut self, h: HelloAck) -> Result<(), HwError> {
        if h.protocol_version != PROTOCOL_VERSION {
            return Err(HwError::Protocol(format!(
                "board speaks protocol v{}, host v{PROTOCOL_VERSION}",
                h.protocol_version
            )));
        }
        let v = h.voltage_limit_v as f64;
        if !(v > 0.0 && v.is_finite())
            || h.sample_period_us == 0
            || h.current_scale_a_per_lsb.is_nan()
            || h.current_scale_a_per_lsb <= 0.0
        {
            return Err(HwError::Protocol(format!(
                "board reported an invalid description: {h:?}"
            )));
        }
        self.limits.voltage_limit_v = self.limits.voltage_limit_v.min(v);
        // BoardInfo holds a &'static str: one small leak per connection.
        let firmware: &'static str = Box::leak(h.firmware_str().to_string().into_boxed_str());
        self.info = BoardInfo {
            firmware,
            counts_per_rev: h.counts_per_rev,
            voltage_limit_v: self.limits.voltage_limit_v,
            sample_period_s: h.sample_period_us as f64 * 1e-6,
        };
        self.stats.period_s = self.info.sample_period_s;
        self.watch = StarvationWatch::new(self.info.sample_period_s);
        self.hello = h;
        Ok(())
    }

    /// The board's handshake answer.
    pub fn hello(&self) -> &HelloAck {
        &self.hello
    }

    /// Loop-timing and link statistics so far.
    pub fn stats(&self) -> LinkStats {
        let mut s = self.stats;
        let ds = self.dec.stats();
        s.crc_errors = ds.crc_errors;
        s.framing_errors = ds.framing_errors;
        let mut j = self.jitter_s.clone();
        s.jitter_p50_s = quantile(&mut j, 0.5);
        s.jitter_p99_s = quantile(&mut j, 0.99);
        s.jitter_max_s = j.last().copied().unwrap_or(0.0);
        let mut r = self.rtt_s.clone();
        s.rtt_p50_s = quantile(&mut r, 0.5);
        s.rtt_p99_s = quantile(&mut r, 0.99);
        s.rtt_max_s = r.last().copied().unwrap_or(0.0);
        s
    }

    fn write_raw(&mut self, bytes: &[u8]) -> Result<(), HwError> {
        self.port
            .write_all(bytes)
            .map_err(|e| port_error(&self.cfg.port, e))
    }

    fn send(&mut self, m: &Message) -> Result<(), HwError> {
        let f = Frame::new(m);
        self.write_raw(f.as_bytes())
    }

    /// Next decoded message before `deadline`, `None` on timeout.
    fn next_message(&mut self, deadline: Instant) -> Result<Option<Message>, HwError> {
        let mut buf = [0u8; 256];
        loop {
            if let Some(m) = self.inbox.pop_front() {
                return Ok(Some(m));
            }
            let Some(wait) = deadline
                .checked_duration_since(Instant::now())
                .filter(|d| !d.is_zero())
            else {
                return Ok(None);
            };
            self.port.set_timeout(wait).map_err(HwError::Serial)?;
            match self.port.read(&mut buf) {
                Ok(0) => {
                    return Err(HwError::Protocol(format!(
                        "serial port {} closed",
                        self.cfg.port
                    )))
                }
                Ok(n) => {
                    let inbox = &mut self.inbox;
                    self.dec.feed(&buf[..n], |r| {
                        if let Ok(m) = r {
                            inbox.push_back(m);
                        }
                    });
                }
                Err(e) if e.kind() == ErrorKind::TimedOut => return Ok(None),
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => return Err(port_error(&self.cfg.port, e)),
            }
        }
    }

    /// Converts and accounts a wire sample.
    fn accept_sample(
        &mut self,
        s: servo_core::protocol::Sample,
        at: Instant,
    ) -> Result<Option<Sample>, HwError> {
        if let Some(last) = self.last_seq {
            let d = s.seq.wrapping_sub(last) as i32;
            if d <= 0 {
                self.stats.out_of_order += 1;
                return Ok(None);
            }
            self.stats.lost_frames += (d - 1) as u64;
            if let Some(prev) = self.last_arrival {
                let dt = at.duration_since(prev).as_secs_f64() / d as f64;
                self.jitter_s.push((dt - self.info.sample_period_s).abs());
            }
        }
        if let Some(lt) = self.last_time_us {
            if s.time_us < lt {
                self.time_base_us += 1 << 32;
            }
        }
        self.last_time_us = Some(s.time_us);
        self.last_seq = Some(s.seq);
        self.last_arrival = Some(at);
        self.stats.samples += 1;
        if s.seq != 0 {
            if s.flags & flags::MISSED_DEADLINE != 0 {
                self.stats.missed_deadlines += 1;
            }
            if s.rtt_us != 0xFFFF {
                self.rtt_s.push(s.rtt_us as f64 * 1e-6);
            }
        }
        let cpr = self.hello.counts_per_rev;
        let theta_l_rad = if cpr > 0 {
            s.encoder_count as f64 * math::TAU / cpr as f64
        } else {
            0.0
        };
        let i_a_a = s.current_raw as f64 * self.hello.current_scale_a_per_lsb as f64;
        if let Err(trip) = self.limits.check(theta_l_rad, i_a_a) {
            return Err(HwError::Safety(format!("host-side {trip}")));
        }
        let time_s = (self.time_base_us + s.time_us as u64) as f64 * 1e-6;
        let missed = s.seq != 0 && s.flags & flags::MISSED_DEADLINE != 0;
        if self.cfg.watch_starvation {
            self.watch
                .push(time_s, at, missed)
                .map_err(HwError::Starved)?;
        }
        Ok(Some(Sample {
            time_s,
            theta_l_rad,
            encoder_count: s.encoder_count as i64,
            i_a_a,
            u_applied_v: s.u_applied_v as f64,
        }))
    }
}

impl SerialBackend {
    /// The settle phase after Start ([`crate::starvation::settle_samples`]): every sample answered
    /// with 0 V while the watch judges the loop, so that a loop that cannot keep the board's
    /// period is refused before the host commands any voltage ([`Starved::at_rest`]).
    fn settle(&mut self) -> Result<(), HwError> {
        self.settle_end_s = 0.0;
        for _ in 0..crate::starvation::settle_samples(self.info.sample_period_s) {
            match self.next_sample() {
                Ok(s) => {
                    self.apply(0.0)?;
                    self.settle_end_s = s.time_s + self.info.sample_period_s;
                }
                Err(HwError::Starved(s)) => {
                    return Err(HwError::Starved(Starved { at_rest: true, ..s }))
                }
                // The board's watchdog fired while the host answered 0 V: it cannot answer in
                // time here either.
                Err(HwError::Fault { code, text }) => {
                    return Err(HwError::Fault {
                        code,
                        text: format!("{text} (in the 0 V settle phase, before the loop moved)"),
                    })
                }
                Err(e) => return Err(e),
            }
        }
        self.watch
            .settle_verdict()
            .map_err(|s| HwError::Starved(Starved { at_rest: true, ..s }))
    }

    /// The board's next sample, answered by the caller (the body of [`Backend::sample`]).
    fn next_sample(&mut self) -> Result<Sample, HwError> {
        let timeout =
            Duration::from_secs_f64(self.cfg.timeout_s.max(2.0 * self.info.sample_period_s));
        let mut deadline = Instant::now() + timeout;
        // Until the first sample arrives, Start is repeated every 50 ms: a Start lost on the
        // link (CRC error, dropped byte) would otherwise cost the whole run.
        let retry = Duration::from_millis(50);
        let mut next_start = Instant::now() + retry;
        loop {
            let wait_until = if self.last_seq.is_none() {
                deadline.min(next_start)
            } else {
                deadline
            };
            let Some(m) = self.next_message(wait_until)? else {
                if Instant::now() < deadline {
                    self.send(&Message::Start)?;
                    next_start = Instant::now() + retry;
                    continue;
                }
                return Err(HwError::Timeout {
                    timeout_ms: timeout.as_millis() as u64,
                });
            };
            match m {
                Message::Sample(s) => {
                    if let Some(out) = self.accept_sample(s, Instant::now())? {
                        return Ok(out);
                    }
                    deadline = Instant::now() + timeout;
                }
                Message::Fault(f) => {
                    self.stopped = true;
                    return Err(HwError::Fault {
                        code: f.code.to_u16(),
                        text: f.text_str().to_string(),
                    });
                }
                Message::Stopped => {
                    self.stopped = true;
                    return Err(HwError::Protocol("the board stopped the run".into()));
                }
                _ => {}
            }
        }
    }
}

fn port_error(port: &str, e: std::io::Error) -> HwError {
    HwError::Protocol(format!(
        "serial port {port} failed (vanished or closed?): {e}"
    ))
}

impl Backend for SerialBackend {
    fn info(&self) -> BoardInfo {
        self.info
    }

    fn link_stats(&self) -> Option<LinkStats> {
        Some(self.stats())
    }

    fn missed_deadlines(&self) -> Option<u64> {
        Some(self.stats.missed_deadlines)
    }

    fn sample(&mut self) -> Result<Sample, HwError> {
        if self.stopped {
            return Err(HwError::Protocol("the run was stopped".into()));
        }
        if !self.started {
            self.started = true;
            self.watch = StarvationWatch::new(self.info.sample_period_s);
            self.send(&Message::Start)?;
            self.settle_end_s = 0.0;
            if self.cfg.watch_starvation {
                self.settle()?;
            }
        }
        let mut s = self.next_sample()?;
        s.time_s -= self.settle_end_s;
        Ok(s)
    }

    fn apply(&mut self, u_v: f64) -> Result<(), HwError> {
        if !u_v.is_finite() {
            return Err(HwError::Safety(format!("non-finite voltage command {u_v}")));
        }
        let Some(seq) = self.last_seq else {
            return Err(HwError::Protocol(
                "apply() before the first sample()".into(),
            ));
        };
        let (u, _clipped) = self.limits.clamp_voltage(u_v);
        self.send(&Message::SetVoltage { seq, u_v: u as f32 })
    }

    fn stop(&mut self) -> Result<(), HwError> {
        if self.stopped && !self.started {
            return Ok(());
        }
        self.stopped = true;
        self.started = false;
        self.send(&Message::SetVoltage {
            seq: self.last_seq.unwrap_or(0).wrapping_add(1),
            u_v: 0.0,
        })?;
        self.send(&Message::Stop)?;
        let deadline = Instant::now() + Duration::from_millis(200);
        while let Some(m) = self.next_message(deadline)? {
            match m {
                Message::Stopped => return Ok(()),
                Message::Sample(s) => {
                    let _ = self.accept_sample(s, Instant::now());
                }
                _ => {}
            }
        }
        // No confirmation: 0 V was sent but is not known to hold (the board's watchdog should
        // bring it to 0 V); say so rather than claim it.
        Err(HwError::Protocol(
            "the board did not acknowledge Stop within 200 ms: 0 V was sent but not confirmed"
                .into(),
        ))
    }
}

impl Drop for SerialBackend {
    fn drop(&mut self) {
        if self.started {
            let _ = self.send(&Message::Stop);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::board::{BoardConfig, VirtualBoard};
    use servo_core::sim::SensorConfig;
    use servo_core::Plant;
    use std::sync::atomic::AtomicBool;
    use std::sync::Arc;

    fn board_thread(
        cfg: BoardConfig,
    ) -> (
        serialport::TTYPort,
        std::thread::JoinHandle<crate::board::BoardReport>,
        Arc<AtomicBool>,
    ) {
        let (mut master, slave) = serialport::TTYPort::pair().unwrap();
        let stop = Arc::new(AtomicBool::new(false));
        let s2 = stop.clone();
        let plant = Plant::nominal();
        let h = std::thread::spawn(move || {
            let mut b = VirtualBoard::new(&plant, SensorConfig::default(), cfg).unwrap();
            b.serve(&mut master, &s2).unwrap()
        });
        (slave, h, stop)
    }

    #[test]
    fn handshake_and_short_p_loop() {
        let (slave, h, stop) = board_thread(BoardConfig::default());
        let mut be = SerialBackend::from_port(Box::new(slave), SerialConfig::default()).unwrap();
        assert_eq!(be.info().counts_per_rev, 4096);
        assert_eq!(be.info().sample_period_s, 1e-3);
        assert!(be.info().firmware.starts_with("servo-vboard"));
        let mut last = Sample::default();
        for _ in 0..300 {
            let s = be.sample().unwrap();
            be.apply(5.0 * (1.0 - s.theta_l_rad)).unwrap();
            last = s;
        }
        be.stop().unwrap();
        let st = be.stats();
        eprintln!("{st}\nlast {last:?}");
        // Timed from the end of the 0 V settle phase.
        assert!((last.time_s - 0.299).abs() < 1e-9, "{last:?}");
        assert!(
            be.stats().samples as usize >= 300 + crate::starvation::settle_samples(1e-3),
            "{:?}",
            be.stats()
        );
        assert!(last.theta_l_rad > 0.3, "{last:?}");
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
        let rep = h.join().unwrap();
        eprintln!("{rep:?}");
        assert_eq!(rep.runs, 1);
    }
}
