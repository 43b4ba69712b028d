//! Subcommands, one file each.

pub mod board;
pub mod compare;
pub mod demo;
pub mod design;
pub mod diagnose;
pub mod diagnose_custom;
pub mod export;
pub mod frf;
pub mod identify;
pub mod identify_ramp;
pub mod inspect;
pub mod log;
pub mod params;
pub mod ports;
pub mod run;
pub mod trend;

/// The subcommands of `servo`.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Print the default plant parameter file (Table 2) with units.
    Params(params::Params),
    /// Design a PID/PI/PD position controller by Bode's method and verify it.
    Design(Box<design::Design>),
    /// Run the position loop on the simulator or a board, logging to MCAP.
    Run(run::Run),
    /// Tell the whole story on the simulator: design, run, identify, compare, diagnose.
    Demo(demo::Demo),
    /// Convert a log (MCAP) to servo's CSV.
    Export(export::Export),
    /// List what a log holds: MAT variables, fields, shapes and labels; CSV columns; MCAP channels.
    Inspect(inspect::Inspect),
    /// Identify friction, inertia and electrical constants from experiments or logs.
    Identify(identify::Identify),
    /// Compare a model with measurements; add effects and watch the error fall.
    Compare(compare::Compare),
    /// Find which physical effect the model is missing.
    Diagnose(diagnose::Diagnose),
    /// Measured frequency response, achieved margins and where the model fails in frequency.
    Frf(frf::Frf),
    /// Run a virtual board on a pseudo-terminal.
    Board(board::Board),
    /// List serial ports that may be boards.
    Ports(ports::Ports),
    /// Log utilities (recover an unfinished MCAP).
    Log(log::Log),
    /// Follow each actuator's parameters over many logs and say what is changing.
    Trend(trend::Trend),
}

impl Command {
    pub fn run(self) -> anyhow::Result<()> {
        match self {
            Command::Params(c) => c.run(),
            Command::Design(c) => c.run(),
            Command::Run(c) => c.run(),
            Command::Demo(c) => c.run(),
            Command::Export(c) => c.run(),
            Command::Inspect(c) => c.run(),
            Command::Identify(c) => c.run(),
            Command::Compare(c) => c.run(),
            Command::Diagnose(c) => c.run(),
            Command::Frf(c) => c.run(),
            Command::Board(c) => c.run(),
            Command::Ports(c) => c.run(),
            Command::Log(c) => c.run(),
            Command::Trend(c) => c.run(),
        }
    }
}
