//! servo's files: the model and gains files (TOML), reference programs, and logs: servo's MCAP,
//! servo's CSV, foreign CSVs through a column map, MATLAB MAT-files.
//!
//! * [`model_file`], [`gains_file`], [`reference_file`]: the TOML files servo reads and writes.
//! * [`recipe_file`]: the recipes of the identification experiments (speed staircase, ramps).
//! * [`controller`]: the controller of a run from the gains file, the options and a log's record
//!   of the controller that ran.
//! * [`error`]: the typed [`Error`] every function here returns.
//!
//! Every command that reads a log calls [`read_log`] (or [`read_log_with_meta`] for the run's
//! metadata: gains, plant, reference), which asks the [`log_reader`] registry: one reader per
//! format behind the [`LogReader`] trait.
//!
//! * [`units`]: signal names (`time`, `u`, `theta_l`, ...) and the units columns may use.
//! * [`columns`]: the `--columns` map, servo's own header, guessing from header suffixes.
//! * [`csv_read`], [`csv_write`]: CSV logs.
//! * [`loop_msg`]: the `/servo/loop` JSON message and its JSON schema.
//! * [`mcap_write`], [`mcap_read`]: MCAP logs (Foxglove/PlotJuggler compatible).
//! * [`disk`]: room on disk for a long log, checked before a run starts.
//! * [`output`]: every file servo writes: atomic replacement, numbered backups, `.partial` logs.
//! * [`mat_read`], [`mat_path`], [`mat_log`]: MATLAB MAT-files (Level 5, -v6/-v7), MATLAB paths
//!   in `--columns`, Simulink Scope structures.
//! * [`ros_bag`]: ROS 2 bags (rosbag2, MCAP storage, CDR messages); [`wpilog`]: WPILib DataLogs;
//!   [`series`]: their named series on one time grid.
//! * [`markup`]: HTML and SVG escaped by construction (the reports and charts).
//! * [`mjcf`]: a model file as a MuJoCo model (MJCF), with what MuJoCo cannot express.

pub mod bam_log;
pub mod chart_axes;
pub mod columns;
pub mod compensation;
pub mod controller;
pub mod crosscheck;
pub mod csv_read;
pub mod csv_write;
pub mod disk;
pub mod effects_file;
pub mod error;
pub mod excerpt;
pub mod gains_file;
pub mod log_reader;
pub mod loop_msg;
pub mod markup;
pub mod mat_log;
pub mod mat_path;
pub mod mat_read;
pub mod mcap_read;
pub mod mcap_recover;
pub mod mcap_write;
pub mod mjcf;
pub mod model_file;
pub mod output;
pub mod recipe_file;
pub mod reference_file;
pub mod ros_bag;
pub mod series;
pub mod smart_log;
pub mod smart_model;
pub mod text_file;
pub mod units;
pub mod wpilog;

pub use loop_msg::LoopMsg;
pub use mcap_write::{LogEncoding, McapLog, McapLogOptions};

pub use columns::ColumnMap;
pub use controller::logged_controller;
pub use csv_write::{write_csv, write_csv_on};
pub use error::{Context, Error, Result};
pub use log_reader::{LogReader, Registry};
pub use units::{Signal, Unit};

use crate::error::{self as anyhow};
use servo_core::record::Record;
use std::collections::BTreeMap;
use std::path::Path;

/// The log formats servo reads ([`log_reader`]), in the order of the "expected ..." message: one
/// line per format. (Here, at the crate's root, so that the readers' files and the registry's
/// do not import each other.)
pub static BUILT_IN: [&dyn LogReader; 6] = [
    &crate::mat_log::MatReader,
    // Before servo's MCAP reader: it passes on an `.mcap` that is not a ROS 2 bag.
    &crate::ros_bag::RosBagReader,
    &crate::mcap_read::McapReader,
    &crate::csv_read::CsvReader,
    &crate::bam_log::BamReader,
    &crate::wpilog::WpilogReader,
];

/// What a log says about the run besides its samples.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LogMeta {
    /// The column map used for a CSV (`--columns` form).
    pub columns: Option<String>,
    /// Key/value metadata of an MCAP run (`servo_version`, `gains_toml`, `plant_toml`, ...).
    pub entries: BTreeMap<String, String>,
    /// End-of-run summary of an MCAP run (tracking error, overshoot, ...), if written.
    pub summary: BTreeMap<String, String>,
    /// Notes for the user: guessed column map, data lost at a truncated end, missing values.
    pub notes: Vec<String>,
    /// The feedforward part of u per sample [V] (`ff_v` of an MCAP run; None when no sample
    /// has a value, e.g. a CSV).
    pub feedforward_v: Option<Vec<f64>>,
}

/// Metadata keys of a servo MCAP run (values are strings; TOML documents for files).
pub mod meta_keys {
    /// servo version that wrote the log.
    pub const SERVO_VERSION: &str = "servo_version";
    /// Backend name (`sim`, `serial`).
    pub const BACKEND: &str = "backend";
    /// Board or simulator firmware string.
    pub const FIRMWARE: &str = "firmware";
    /// Control period [s].
    pub const SAMPLE_PERIOD_S: &str = "sample_period_s";
    /// Requested run duration [s].
    pub const DURATION_S: &str = "duration_s";
    /// The reference as given (`step:1.5`) or the experiment file's text.
    pub const REFERENCE: &str = "reference";
    /// The controller, as a gains file (TOML, `[pid]`).
    pub const GAINS_TOML: &str = "gains_toml";
    /// The controller exactly as it ran (TOML, servo-cli's `LoggedController`):
    /// gains, period, discretisation, derivative input, anti-windup, limit, feedforward.
    pub const CONTROLLER_TOML: &str = "controller_toml";
    /// The simulated plant (truth), as a model file (TOML); simulator runs only.
    pub const PLANT_TOML: &str = "plant_toml";
    /// Effects of the simulated plant, `name:key=value` list; simulator runs only.
    pub const PLANT_EFFECTS: &str = "plant_effects";
    /// The model used for feedforward, as a model file (TOML).
    pub const MODEL_TOML: &str = "model_toml";
    /// Feedforward terms in use (`inertia,friction` or `none`).
    pub const FEEDFORWARD: &str = "feedforward";
    /// The effects a run compensated, comma-separated registry names (`<effect>,<effect>`;
    /// empty for none): `servo compare` checks each against the log.
    pub const COMPENSATED_EFFECTS: &str = "compensated_effects";
    /// How each effect was compensated, or why not, `; `-separated sentences.
    pub const COMPENSATION: &str = "compensation";
    /// Simulator noise seed.
    pub const SEED: &str = "seed";
    /// Voltage limit applied to the controller output [V].
    pub const U_LIMIT_V: &str = "u_limit_v";
    /// Encoder resolution [counts/rev].
    pub const COUNTS_PER_REV: &str = "counts_per_rev";
    /// The command line that made the log.
    pub const COMMAND: &str = "command";
}

impl LogMeta {
    /// A metadata entry.
    pub fn get(&self, key: &str) -> Option<&str> {
        self.entries.get(key).map(String::as_str)
    }
    /// The controller of the run (`None` when the log has none, e.g. a CSV or open loop).
    pub fn gains(&self) -> anyhow::Result<Option<crate::gains_file::GainsFile>> {
        self.get(meta_keys::GAINS_TOML)
            .map(|t| crate::gains_file::GainsFile::parse(t).context("in the log's gains metadata"))
            .transpose()
    }
    /// The simulated plant (truth) of a simulator run.
    pub fn plant(&self) -> anyhow::Result<Option<crate::model_file::ModelFile>> {
        self.get(meta_keys::PLANT_TOML)
            .map(|t| crate::model_file::ModelFile::parse(t).context("in the log's plant metadata"))
            .transpose()
    }
    /// The model used for feedforward, if any.
    pub fn model(&self) -> anyhow::Result<Option<crate::model_file::ModelFile>> {
        self.get(meta_keys::MODEL_TOML)
            .map(|t| crate::model_file::ModelFile::parse(t).context("in the log's model metadata"))
            .transpose()
    }
    /// The reference as given on the command line or in the experiment file.
    pub fn reference(&self) -> Option<&str> {
        self.get(meta_keys::REFERENCE)
    }
}

/// Reads a log (MCAP, CSV or MAT, by extension: the readers of [`BUILT_IN`]) into a [`Record`]
/// in SI units, printing notes (a
/// guessed column map, data lost from a truncated MCAP) to stderr.
///
/// `columns` is the `--columns` map for foreign CSVs, e.g.
/// `time=t_s,theta_l=thl_meas_deg:deg,u=u_V,i_a=ia_A`; `None` means servo's own columns
/// (`time_s,u_V,theta_l_rad,i_a_A[,ref_rad]`) or a guess from the header's unit suffixes. For a
/// MAT-file the columns are MATLAB paths (`time=scope.time,theta_l=scope.signals(1).values:deg`),
/// guessed from Simulink Scope labels when `None`.
pub fn read_log(path: &Path, columns: Option<&str>) -> anyhow::Result<Record> {
    let (rec, meta) = read_log_with_meta(path, columns)?;
    for n in &meta.notes {
        eprintln!("note: {n}");
    }
    Ok(rec)
}

/// Like [`read_log`], returning the metadata and notes instead of printing them.
pub fn read_log_with_meta(path: &Path, columns: Option<&str>) -> anyhow::Result<(Record, LogMeta)> {
    read_log_signals(path, columns, None)
}

/// Like [`read_log_with_meta`], building only the signals in `want` (time always; `None`: every
/// signal and, from an MCAP, the feedforward): a command that needs three signals of a long log
/// does not parse or store the others. A CSV's mapped columns that are not wanted are not
/// parsed (nor checked).
pub fn read_log_signals(
    path: &Path,
    columns: Option<&str>,
    want: Option<&[Signal]>,
) -> anyhow::Result<(Record, LogMeta)> {
    read_log_on(path, columns, want, &servo_core::Transmission::GEAR)
}

/// [`read_log`] on the axis of a model file: printing the notes as [`read_log`] does.
pub fn read_log_axis(
    path: &Path,
    columns: Option<&str>,
    axis: &servo_core::Transmission,
) -> anyhow::Result<Record> {
    let (rec, meta) = read_log_on(path, columns, None, axis)?;
    for n in &meta.notes {
        eprintln!("note: {n}");
    }
    Ok(rec)
}

/// Logs are what their headers say, where the model tells what they should hold: a voltage
/// drive's logged current against its voltage balance
/// ([`crate::crosscheck::check_current_units`]). Notes, or the refusal naming the fix;
/// `columns` is the column map the log was read with.
pub fn check_against_model(
    rec: &Record,
    columns: Option<&str>,
    model: &crate::model_file::ModelFile,
) -> anyhow::Result<Vec<String>> {
    if model.drive.kind != servo_core::drive::DriveKind::Voltage {
        return Ok(Vec::new());
    }
    crate::crosscheck::check_current_units(rec, &model.params, columns)
}

/// [`read_log_on`] on the axis of `model`, the log checked against it
/// ([`check_against_model`]: its notes join the log's).
pub fn read_log_checked(
    path: &Path,
    columns: Option<&str>,
    model: &crate::model_file::ModelFile,
) -> anyhow::Result<(Record, LogMeta)> {
    let (rec, mut meta) = read_log_on(path, columns, None, &model.transmission)?;
    let notes = check_against_model(&rec, meta.columns.as_deref().or(columns), model)?;
    meta.notes.extend(notes);
    Ok((rec, meta))
}

/// [`read_log_axis`] on the axis and the drive of `model`: the log's input column (`u`,
/// `i_ref`, `duty` with `v_supply`) is checked against the model's drive and turned into the
/// input of its equivalent voltage chain ([`servo_core::drive::Drive::prepare`]).
pub fn read_log_model(
    path: &Path,
    columns: Option<&str>,
    model: &crate::model_file::ModelFile,
) -> anyhow::Result<Record> {
    let (mut rec, meta) = read_log_checked(path, columns, model)?;
    for n in &meta.notes {
        eprintln!("note: {n}");
    }
    model
        .drive
        .prepare(&mut rec)
        .map_err(|e| crate::error::anyhow!("{e}"))?;
    Ok(rec)
}

/// [`read_log_signals`] on the axis `axis` (from the model file's `[transmission]`): a CSV or
/// MAT column in a length or linear speed unit (`x=q:mm`, `v_x=v:m/s`) becomes the load shaft's
/// equivalent rotation [rad] (x / s, s the axis' travel per radian); on a rotary gear such a
/// column is refused with a message naming it. An MCAP log holds the equivalent rotation itself.
pub fn read_log_on(
    path: &Path,
    columns: Option<&str>,
    want: Option<&[Signal]>,
    axis: &servo_core::Transmission,
) -> anyhow::Result<(Record, LogMeta)> {
    log_reader::Registry::built_in().read(path, columns, want, axis)
}
