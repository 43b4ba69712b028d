//! Reading and writing logs: servo's MCAP, servo's CSV and foreign CSVs through a column map.
//!
//! Every command that reads a log calls [`read_log`].

use servo_core::record::Record;
use std::path::Path;

/// Reads a log (MCAP or CSV, by extension) into a [`Record`] in SI units.
///
/// `columns` is the `--columns` map for foreign CSVs, e.g.
/// `time=t_s,theta_l=thl_meas_deg:deg,u=u_V,i_a=ia_A`; `None` means servo's own columns
/// (`time_s,u_V,theta_l_rad,i_a_A[,ref_rad]`).
pub fn read_log(path: &Path, columns: Option<&str>) -> anyhow::Result<Record> {
    let _ = columns;
    anyhow::bail!("reading logs is not implemented yet ({})", path.display())
}
