//! servo-hw: the backends that run a position loop.
//!
//! * [`Backend`]: the small trait every backend implements (sample the sensors, apply a voltage).
//! * [`sim::SimBackend`]: the simulated gearmotor with a simulated clock (deterministic, faster
//!   than real time by default).
//! * The serial board backend, the virtual board and the QEMU board launcher live beside it.
//! * [`run`]: the closed loop on any backend ([`run::run_loop`]: position PID, open-loop
//!   voltages, speed control), its log sink, the logs of a run ([`run::logged`]) and the
//!   identification experiments ([`run::experiments`]).

pub mod backend;
pub mod board;
pub mod qemu;
pub mod run;
pub mod serial;
pub mod sim;
pub mod starvation;

pub use backend::{Backend, BoardInfo, HwError, Sample};
pub use board::{BoardConfig, BoardReport, VirtualBoard};
pub use serial::{LinkStats, SerialBackend, SerialConfig};
pub use sim::SimBackend;
