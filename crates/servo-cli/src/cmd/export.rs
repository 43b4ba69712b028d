//! `servo export`: convert a log between MCAP and servo's CSV, or a model file to MuJoCo.
//!
//! ```text
//! servo export model.toml -o arm.xml          model file -> MuJoCo MJCF (servo_io::mjcf)
//! servo export run.mcap -o run.csv            MCAP -> CSV (time_s,u_V,theta_l_rad,i_a_A,ref_rad,omega_l_rad_s)
//! servo export lab.csv -o lab.mcap --columns time=t_s,theta_l=thl_meas_deg:deg,u=u_V
//! ```
//!
//! A truncated MCAP (killed run) exports what is readable and says what was lost.

use crate::io::mcap_read::loop_msgs_of;
use crate::io::{meta_keys, read_log_with_meta, write_csv, McapLog, McapLogOptions, Registry};
use anyhow::bail;
use std::path::PathBuf;

/// Convert a log: MCAP -> CSV, or CSV (servo's or foreign with --columns) -> MCAP/CSV.
#[derive(Debug, clap::Parser)]
pub struct Export {
    /// Input log (.mcap, .csv or MATLAB .mat), or a model file (.toml) to write as MuJoCo MJCF.
    pub input: PathBuf,
    /// Output file; the format follows the extension (.csv or .mcap; .xml for a model file).
    /// Default: the input with .csv (or .mcap for a CSV input, .xml for a model file).
    #[arg(short = 'o', long = "output", value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Column map of a foreign CSV input, e.g. `time=t_s,theta_l=thl_meas_deg:deg,u=u_V,i_a=ia_A`,
    /// or MATLAB paths for a .mat input (`time=scope.time,theta_l=scope.signals(1).values:deg`).
    #[arg(long, value_name = "MAP")]
    pub columns: Option<String>,
    /// Export only this part (and, with an `enable` column, only where the drive was on).
    #[command(flatten)]
    pub part: crate::log_part::LogPartArgs,
}

impl Export {
    pub fn run(self) -> anyhow::Result<()> {
        if self
            .input
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
        {
            return self.model();
        }
        let registry = Registry::built_in();
        let format = |path: &std::path::Path| -> anyhow::Result<&'static str> {
            let reader = registry.reader_for(path)?;
            Ok(reader.extensions().first().copied().unwrap_or(""))
        };
        let in_fmt = format(&self.input)?;
        let output = match &self.output {
            Some(o) => o.clone(),
            None => self
                .input
                .with_extension(if in_fmt == "csv" { "mcap" } else { "csv" }),
        };
        if output == self.input {
            bail!(
                "the output {} is the input; give another name with -o",
                output.display()
            );
        }
        let out_fmt = format(&output)?;
        let (mut rec, mut meta) = read_log_with_meta(&self.input, self.columns.as_deref())?;
        for n in &meta.notes {
            eprintln!("note: {n}");
        }
        let used = self.part.apply(&mut rec, &self.input, 0, 1)?;
        meta.feedforward_v = meta.feedforward_v.map(|f| used.slice_of(&f).to_vec());
        out!("{}", crate::log_part::text(std::slice::from_ref(&used)));
        match out_fmt {
            "csv" => write_csv(&output, &rec)?,
            "mcap" => {
                let mut entries = meta.entries.clone();
                entries
                    .entry(meta_keys::SERVO_VERSION.into())
                    .or_insert_with(|| env!("CARGO_PKG_VERSION").into());
                entries.insert("converted_from".into(), self.input.display().to_string());
                if let Some(c) = &meta.columns {
                    entries.insert("columns".into(), c.clone());
                }
                let opts = McapLogOptions {
                    start_unix_ns: 0,
                    // A conversion, not a live run: chunks by wall-clock time.
                    flush_on_wall_clock: true,
                    ..McapLogOptions::default()
                };
                let mut log = McapLog::create(&output, &entries, opts)?;
                for m in loop_msgs_of(&rec) {
                    log.write_loop(&m)?;
                }
                if !meta.summary.is_empty() {
                    log.write_summary(&meta.summary)?;
                }
                log.finish()?;
            }
            "mat" => bail!(
                "{}: servo does not write MAT-files; export to .csv or .mcap",
                output.display()
            ),
            other => bail!(
                "{}: servo does not write .{other} files; export to .csv or .mcap",
                output.display()
            ),
        }
        outln!(
            "{} -> {}: {} samples, {:.3} s, signals {}",
            self.input.display(),
            output.display(),
            rec.len(),
            rec.time_s.last().copied().unwrap_or(0.0) - rec.time_s.first().copied().unwrap_or(0.0),
            rec.signals().join(", ")
        );
        Ok(())
    }

    /// A model file to MuJoCo MJCF: the writer is `servo_io::mjcf`.
    fn model(self) -> anyhow::Result<()> {
        if self.columns.is_some() || !self.part.window.is_empty() {
            bail!(
                "--columns and the part options apply to a log; {} is a model file",
                self.input.display()
            );
        }
        let output = self
            .output
            .clone()
            .unwrap_or_else(|| self.input.with_extension("xml"));
        if !output
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("xml"))
        {
            bail!(
                "{}: a model file exports to MuJoCo's MJCF; give an .xml output (-o NAME.xml)",
                output.display()
            );
        }
        let (m, _) = crate::io::mjcf::export(&self.input, &output)?;
        for n in &m.notes {
            outln!("note: {n}");
        }
        for l in m.summary() {
            outln!("{l}");
        }
        outln!(
            "{} -> {}: MuJoCo MJCF, one {} joint (position in {}), one actuator whose ctrl is the command [{}]",
            self.input.display(),
            output.display(),
            m.joint,
            m.position_unit,
            m.ctrl_unit
        );
        Ok(())
    }
}
