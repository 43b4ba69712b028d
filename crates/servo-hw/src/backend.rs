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
    /// Board time of the sample [s] since the start of the run.
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
    fn link_stats(&self) -> Option<crate::serial::LinkStats> {
        None
    }
    /// Periods whose command reached the board too late so far (cheap: for live progress while
    /// the loop runs); `None` for backends without a deadline (the simulator).
    fn missed_deadlines(&self) -> Option<u64> {
        None
    }
}
