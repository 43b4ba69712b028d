//! servo's files and logs: the [`servo_io`] crate, re-exported so that `crate::io::...` paths
//! keep working, plus what needs the CLI's runner (the controller recorded in a log).

pub use servo_io::*;

use crate::runner::controller::LoggedController;
use anyhow::Context as _;

/// The record of the controller as it ran (`None` for logs without one: CSV, open loop, or
/// written before servo recorded it).
pub fn logged_controller(meta: &LogMeta) -> anyhow::Result<Option<LoggedController>> {
    meta.get(meta_keys::CONTROLLER_TOML)
        .map(|t| LoggedController::parse(t).context("in the log's controller metadata"))
        .transpose()
}
