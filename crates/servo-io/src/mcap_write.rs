//! Writing a run to MCAP: JSON messages on channels with a registered JSON schema (they open
//! directly in Foxglove and PlotJuggler), a metadata record describing the run, and a chunk flush
//! at least every [`McapLogOptions::flush_period_s`] of run time so that a killed run loses at
//! most that much (the open chunk).

use super::loop_msg::{
    loop_descriptor_set, loop_schema, LoopMsg, LOOP_PROTO_NAME, LOOP_SCHEMA_NAME, LOOP_TOPIC,
};
use crate::error::{self as anyhow, anyhow, Context};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// Name of the metadata record that describes a run.
pub const RUN_METADATA: &str = "servo.run";
/// Name of the metadata record written at the end of a run with its summary figures.
pub const SUMMARY_METADATA: &str = "servo.summary";
/// Metadata key of the Unix time [ns] of run time 0 (`log_time = start + time_s`).
pub const START_TIME_KEY: &str = "start_time_unix_ns";
/// Profile string in the MCAP header.
pub const PROFILE: &str = "";

/// Options of an MCAP log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct McapLogOptions {
    /// End the open chunk and flush to the OS at least this often, in run time [s].
    pub flush_period_s: f64,
    /// Compress chunks (zstd, or LZ4 with `fast_compression`).
    pub compress: bool,
    /// LZ4 instead of zstd: about 3 times faster to write, files about 25 % larger (for
    /// simulations faster than real time, where the log's cost is the run's cost).
    pub fast_compression: bool,
    /// Unix time [ns] of run time 0, added to `log_time`/`publish_time`.
    pub start_unix_ns: u64,
    /// Measure `flush_period_s` on the wall clock instead of in run time: for a simulation
    /// faster than real time, chunks then hold many samples (cheaper to compress and index)
    /// while a killed run still loses at most `flush_period_s` of work. Real-time runs are
    /// the same either way.
    pub flush_on_wall_clock: bool,
    /// How `/servo/loop` messages are encoded.
    pub encoding: LogEncoding,
}

/// Message encoding of the `/servo/loop` channel. Both open in Foxglove and PlotJuggler and in
/// every servo command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum LogEncoding {
    /// JSON text with a JSON schema (`jsonschema`): readable anywhere, ~360 bytes a sample.
    #[default]
    Json,
    /// Protobuf (`servo.Loop`, schema a FileDescriptorSet): 110 bytes a sample, about 5 times
    /// cheaper to write.
    Protobuf,
}

impl Default for McapLogOptions {
    /// Flush every 50 ms of run time (half the 100 ms the log promises to lose at most), zstd,
    /// start time now.
    fn default() -> Self {
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos() as u64)
            .unwrap_or(0);
        McapLogOptions {
            flush_period_s: 0.05,
            compress: true,
            start_unix_ns: now,
            flush_on_wall_clock: false,
            encoding: LogEncoding::Json,
            fast_compression: false,
        }
    }
}

/// An MCAP log being written. Call [`McapLog::finish`] at the end (also on Ctrl-C); a log that
/// is dropped unfinished is still readable up to its last flush.
pub struct McapLog {
    writer: Option<mcap::Writer<BufWriter<File>>>,
    path: PathBuf,
    loop_channel: u16,
    sequence: u32,
    last_flush_s: f64,
    opts: McapLogOptions,
    messages: u64,
    /// Encoding buffer, reused.
    buf: Vec<u8>,
    last_flush_wall: std::time::Instant,
}

impl std::fmt::Debug for McapLog {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapLog")
            .field("path", &self.path)
            .field("messages", &self.messages)
            .finish()
    }
}

fn mcap_err(path: &Path, what: &str) -> impl FnOnce(mcap::McapError) -> anyhow::Error {
    let p = path.display().to_string();
    let what = what.to_string();
    move |e| anyhow!("MCAP log {p}: {what}: {e}")
}

impl McapLog {
    /// Creates `path` and writes the header, the schemas/channels and the run metadata
    /// (`metadata`: key/value strings, see [`RUN_METADATA`]); flushes so that the metadata
    /// survives a kill.
    pub fn create(
        path: &Path,
        metadata: &BTreeMap<String, String>,
        opts: McapLogOptions,
    ) -> anyhow::Result<McapLog> {
        let file =
            File::create(path).with_context(|| format!("creating MCAP log {}", path.display()))?;
        let wopts = mcap::WriteOptions::new()
            .library(concat!(
                "servo ",
                env!("CARGO_PKG_VERSION"),
                " / ",
                "mcap-rust"
            ))
            .compression(match (opts.compress, opts.fast_compression) {
                (false, _) => None,
                (true, false) => Some(mcap::Compression::Zstd),
                (true, true) => Some(mcap::Compression::Lz4),
            })
            // Chunks of 50-100 samples: one thread, fast level.
            .compression_threads(0)
            .compression_level(1)
            // Chunks end on flush (by run time), not by size.
            .chunk_size(None);
        let mut writer = mcap::Writer::with_options(BufWriter::with_capacity(1 << 16, file), wopts)
            .map_err(mcap_err(path, "writing the header"))?;
        let (schema, encoding) = match opts.encoding {
            LogEncoding::Json => (
                writer.add_schema(LOOP_SCHEMA_NAME, "jsonschema", loop_schema().as_bytes()),
                "json",
            ),
            LogEncoding::Protobuf => (
                writer.add_schema(LOOP_PROTO_NAME, "protobuf", &loop_descriptor_set()),
                "protobuf",
            ),
        };
        let schema = schema.map_err(mcap_err(path, "adding the schema"))?;
        let loop_channel = writer
            .add_channel(schema, LOOP_TOPIC, encoding, &BTreeMap::new())
            .map_err(mcap_err(path, "adding the channel"))?;
        let mut metadata = metadata.clone();
        metadata.insert(START_TIME_KEY.to_string(), opts.start_unix_ns.to_string());
        writer
            .write_metadata(&mcap::records::Metadata {
                name: RUN_METADATA.to_string(),
                metadata,
            })
            .map_err(mcap_err(path, "writing the metadata"))?;
        writer.flush().map_err(mcap_err(path, "flushing"))?;
        Ok(McapLog {
            writer: Some(writer),
            path: path.to_path_buf(),
            loop_channel,
            sequence: 0,
            last_flush_s: f64::NEG_INFINITY,
            opts,
            messages: 0,
            buf: Vec::with_capacity(512),
            last_flush_wall: std::time::Instant::now(),
        })
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Messages written so far.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    fn log_time_ns(&self, time_s: f64) -> u64 {
        let ns = (time_s.max(0.0) * 1e9).round();
        self.opts
            .start_unix_ns
            .saturating_add(if ns.is_finite() { ns as u64 } else { 0 })
    }

    /// Writes one loop sample; ends the chunk and flushes when `flush_period_s` of run time has
    /// passed since the last flush.
    pub fn write_loop(&mut self, msg: &LoopMsg) -> anyhow::Result<()> {
        self.buf.clear();
        match self.opts.encoding {
            LogEncoding::Json => msg.write_json(&mut self.buf),
            LogEncoding::Protobuf => msg.write_protobuf(&mut self.buf),
        }
        let t = self.log_time_ns(msg.time_s);
        let header = mcap::records::MessageHeader {
            channel_id: self.loop_channel,
            sequence: self.sequence,
            log_time: t,
            publish_time: t,
        };
        let Some(w) = self.writer.as_mut() else {
            return Err(anyhow!(
                "MCAP log {}: already finished",
                self.path.display()
            ));
        };
        w.write_to_known_channel(&header, &self.buf)
            .map_err(|e| mcap_err(&self.path, "writing a message")(e))?;
        self.sequence = self.sequence.wrapping_add(1);
        self.messages += 1;
        let due = if self.opts.flush_on_wall_clock {
            // The clock is read every 64 messages only.
            self.messages.is_multiple_of(64)
                && self.last_flush_wall.elapsed().as_secs_f64() >= self.opts.flush_period_s
        } else {
            msg.time_s - self.last_flush_s >= self.opts.flush_period_s - 1e-9 || msg.time_s.is_nan()
        };
        if due {
            w.flush().map_err(|e| mcap_err(&self.path, "flushing")(e))?;
            self.last_flush_s = msg.time_s;
            self.last_flush_wall = std::time::Instant::now();
        }
        Ok(())
    }

    /// Ends the open chunk and flushes to the OS now.
    pub fn flush(&mut self) -> anyhow::Result<()> {
        let path = self.path.clone();
        if let Some(w) = self.writer.as_mut() {
            w.flush().map_err(mcap_err(&path, "flushing"))?;
        }
        Ok(())
    }

    /// Writes the end-of-run summary metadata record ([`SUMMARY_METADATA`]).
    pub fn write_summary(&mut self, summary: &BTreeMap<String, String>) -> anyhow::Result<()> {
        let path = self.path.clone();
        let w = self
            .writer
            .as_mut()
            .ok_or_else(|| anyhow!("MCAP log {}: already finished", path.display()))?;
        w.write_metadata(&mcap::records::Metadata {
            name: SUMMARY_METADATA.to_string(),
            metadata: summary.clone(),
        })
        .map_err(mcap_err(&path, "writing the summary"))
    }

    /// Writes the summary section and the footer and closes the file. Safe to call twice.
    pub fn finish(&mut self) -> anyhow::Result<()> {
        let path = self.path.clone();
        if let Some(mut w) = self.writer.take() {
            w.finish().map_err(mcap_err(&path, "finishing"))?;
            let mut inner = w.into_inner();
            std::io::Write::flush(&mut inner)
                .with_context(|| format!("MCAP log {}: flushing", path.display()))?;
        }
        Ok(())
    }
}

impl Drop for McapLog {
    /// An unfinished log is finished on drop (errors ignored); call [`McapLog::finish`] to see them.
    fn drop(&mut self) {
        let _ = self.finish();
    }
}
