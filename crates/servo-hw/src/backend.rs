//! The backend trait: what a position loop needs from hardware.

/// Static description of a board, as reported by its handshake or by the simulator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoardInfo {
    /// Firmware or simulator version string (static).
    pub firmware: &'static str,
    /// Encoder counts per load revolution [counts/rev].
    pub counts_per_rev: u32,
    /// Largest driver input the board accepts [V] (symmetric).
    pub voltage_limit_v: f64,
    /// Control period [s].
    pub sample_period_s: f64,
}

/// One sample of the board's sensors.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sample {
    /// Board time of the sample [s] since the start of the run (on a serial board, the end of
    /// its 0 V settle phase).
    pub time_s: f64,
    /// Load angle from the encoder [rad].
    pub theta_l_rad: f64,
    /// Raw encoder count since start.
    pub encoder_count: i64,
    /// Measured armature current [A].
    pub i_a_a: f64,
    /// Driver input voltage the board applied over the previous period [V] (after its limit).
    pub u_applied_v: f64,
}

/// Errors of a backend.
#[derive(Debug, thiserror::Error)]
pub enum HwError {
    #[error("serial port error: {0}")]
    Serial(#[from] serialport::Error),
    #[error("I/O error: {0}")]
    Io(#[from] std::io::Error),
    #[error("board did not answer within {timeout_ms} ms")]
    Timeout { timeout_ms: u64 },
    #[error("board fault {code}: {text}")]
    Fault { code: u16, text: String },
    #[error("protocol error: {0}")]
    Protocol(String),
    #[error("simulator error: {0}")]
    Sim(#[from] servo_core::sim::SimError),
    #[error("safety limit: {0}")]
    Safety(String),
    /// The loop cannot keep the board's period ([`crate::starvation`]): stopped before the
    /// error grows.
    #[error("{0}")]
    Starved(crate::starvation::Starved),
}

/// A board that runs a sampled position loop.
///
/// Contract: the caller alternates [`Backend::sample`] and [`Backend::apply`], once per control
/// period. `sample` returns the sensors as measured at the start of the current period (waiting for
/// that instant on real-time backends); `apply(u)` holds driver input `u` [V] from then until the
/// next sample (zero-order hold). [`Backend::stop`] commands 0 V and must be safe to call at any
/// time, more than once.
pub trait Backend {
    /// The board's description.
    fn info(&self) -> BoardInfo;
    /// Sensors at the start of the current control period.
    fn sample(&mut self) -> Result<Sample, HwError>;
    /// Holds driver input `u_v` [V] until the next sample.
    fn apply(&mut self, u_v: f64) -> Result<(), HwError>;
    /// Commands 0 V and ends the run.
    fn stop(&mut self) -> Result<(), HwError>;
    /// Loop-timing and link statistics, for backends with a real link (serial); `None` else.
    fn link_stats(&self) -> Option<LinkStats> {
        None
    }
    /// Periods whose command reached the board too late so far (cheap: for live progress while
    /// the loop runs); `None` for backends without a deadline (the simulator).
    fn missed_deadlines(&self) -> Option<u64> {
        None
    }
}

/// Loop-timing and link statistics of a run over a real link (the serial backend's,
/// [`crate::serial`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinkStats {
    /// Samples received in order.
    pub samples: u64,
    /// Nominal period [s].
    pub period_s: f64,
    /// |arrival interval − period|: median, 99th percentile, max [s].
    pub jitter_p50_s: f64,
    pub jitter_p99_s: f64,
    pub jitter_max_s: f64,
    /// Board-measured round trip, sample out → command in: median, p99, max [s].
    pub rtt_p50_s: f64,
    pub rtt_p99_s: f64,
    pub rtt_max_s: f64,
    /// Periods whose command reached the board after the next sample was due (or never).
    pub missed_deadlines: u64,
    /// Frames rejected by CRC.
    pub crc_errors: u64,
    /// Frames rejected for COBS/length/type errors.
    pub framing_errors: u64,
    /// Samples never received (gaps in the sequence).
    pub lost_frames: u64,
    /// Samples received with a sequence number older than one already seen.
    pub out_of_order: u64,
}

impl std::fmt::Display for LinkStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let us = |s: f64| s * 1e6;
        writeln!(
            f,
            "serial link: {} samples at {:.0} us period",
            self.samples,
            us(self.period_s)
        )?;
        writeln!(
            f,
            "  period jitter [us]: p50 {:.0}  p99 {:.0}  max {:.0}",
            us(self.jitter_p50_s),
            us(self.jitter_p99_s),
            us(self.jitter_max_s)
        )?;
        writeln!(
            f,
            "  round trip [us]:    p50 {:.0}  p99 {:.0}  max {:.0}",
            us(self.rtt_p50_s),
            us(self.rtt_p99_s),
            us(self.rtt_max_s)
        )?;
        write!(
            f,
            "  missed deadlines {}  CRC errors {}  framing errors {}  lost frames {}  out-of-order {}",
            self.missed_deadlines, self.crc_errors, self.framing_errors, self.lost_frames, self.out_of_order
        )
    }
}

impl LinkStats {
    /// The figures as key/value strings with units in the keys (for the log's summary record).
    pub fn to_map(&self) -> std::collections::BTreeMap<String, String> {
        let mut m = std::collections::BTreeMap::new();
        let mut put = |k: &str, v: String| {
            m.insert(format!("link_{k}"), v);
        };
        put("samples", self.samples.to_string());
        put("period_s", self.period_s.to_string());
        put("jitter_p50_s", self.jitter_p50_s.to_string());
        put("jitter_p99_s", self.jitter_p99_s.to_string());
        put("jitter_max_s", self.jitter_max_s.to_string());
        put("rtt_p50_s", self.rtt_p50_s.to_string());
        put("rtt_p99_s", self.rtt_p99_s.to_string());
        put("rtt_max_s", self.rtt_max_s.to_string());
        put("missed_deadlines", self.missed_deadlines.to_string());
        put("crc_errors", self.crc_errors.to_string());
        put("framing_errors", self.framing_errors.to_string());
        put("lost_frames", self.lost_frames.to_string());
        put("out_of_order", self.out_of_order.to_string());
        m
    }
}
