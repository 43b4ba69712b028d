//! Writing a run to MCAP: `/servo/loop` messages (protobuf or JSON, with their schema, so they
//! open directly in Foxglove and PlotJuggler), a metadata record describing the run, and a chunk
//! flush at least every [`McapLogOptions::flush_period_s`] so that a killed run loses at most
//! that much (the open chunk).
//!
//! The writer lays the records out itself (MCAP spec, <https://mcap.dev/spec>) because the log
//! is the hot path of a simulation faster than real time: a message is framed directly into the
//! open chunk's buffer (no allocation, no per-message stream write), and a chunk is compressed
//! in one call when it ends (the `mcap` crate's writer streams every record through its
//! compressor and CRC layers, which cost twice the physics). The file is what the `mcap` crate
//! writes: header, schema, channel, run metadata, chunks each followed by its message index,
//! the summary metadata, data end with the data-section CRC, and a summary section (schema,
//! channel, statistics, chunk and metadata indexes, summary offsets) with its CRC.

use super::loop_msg::{
    loop_descriptor_set, loop_schema, LoopMsg, LOOP_PROTO_NAME, LOOP_SCHEMA_NAME, LOOP_TOPIC,
};
use crate::error::{self as anyhow, anyhow, Context, Error};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};

/// Name of the metadata record that describes a run.
pub const RUN_METADATA: &str = "servo.run";
/// Name of the metadata record written at the end of a run with its summary figures.
pub const SUMMARY_METADATA: &str = "servo.summary";
/// Metadata key of the Unix time [ns] of run time 0 (`log_time = start + time_s`).
pub const START_TIME_KEY: &str = "start_time_unix_ns";
/// Profile string in the MCAP header.
pub const PROFILE: &str = "";
/// A chunk ends once its uncompressed records reach this size [bytes] (about 29 000 protobuf
/// messages), whatever the flush period: it bounds the writer's memory and keeps each chunk
/// quick to decompress for a viewer seeking in the file (the `mcap` tools' default is 4 MiB).
pub const MAX_CHUNK_BYTES: usize = 4 << 20;

/// Options of an MCAP log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct McapLogOptions {
    /// End the open chunk and flush to the OS at least this often, in run time [s].
    pub flush_period_s: f64,
    /// Compress chunks (zstd, or LZ4 with `fast_compression`).
    pub compress: bool,
    /// LZ4 instead of zstd: faster to write, files larger (for simulations faster than real
    /// time, where the log's cost is the run's cost).
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

/// MCAP opcodes (spec "Records").
mod op {
    pub const HEADER: u8 = 0x01;
    pub const FOOTER: u8 = 0x02;
    pub const SCHEMA: u8 = 0x03;
    pub const CHANNEL: u8 = 0x04;
    pub const MESSAGE: u8 = 0x05;
    pub const CHUNK: u8 = 0x06;
    pub const MESSAGE_INDEX: u8 = 0x07;
    pub const CHUNK_INDEX: u8 = 0x08;
    pub const STATISTICS: u8 = 0x0B;
    pub const METADATA: u8 = 0x0C;
    pub const METADATA_INDEX: u8 = 0x0D;
    pub const SUMMARY_OFFSET: u8 = 0x0E;
    pub const DATA_END: u8 = 0x0F;
}

/// The MCAP magic, at the start and the end of a file.
const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
/// The one schema and the one channel of a servo log.
const SCHEMA_ID: u16 = 1;
const CHANNEL_ID: u16 = 1;

fn put_u16(v: &mut Vec<u8>, x: u16) {
    v.extend_from_slice(&x.to_le_bytes());
}
fn put_u32(v: &mut Vec<u8>, x: u32) {
    v.extend_from_slice(&x.to_le_bytes());
}
fn put_u64(v: &mut Vec<u8>, x: u64) {
    v.extend_from_slice(&x.to_le_bytes());
}
/// A length-prefixed string (u32 length).
fn put_str(v: &mut Vec<u8>, s: &str) {
    put_u32(v, s.len() as u32);
    v.extend_from_slice(s.as_bytes());
}
/// A map<string, string>: u32 byte length, then the pairs.
fn put_str_map(v: &mut Vec<u8>, m: &BTreeMap<String, String>) {
    let len: usize = m.iter().map(|(k, x)| 8 + k.len() + x.len()).sum();
    put_u32(v, len as u32);
    for (k, x) in m {
        put_str(v, k);
        put_str(v, x);
    }
}
/// A whole record: opcode, u64 body length, body.
fn record(opcode: u8, body: &[u8]) -> Vec<u8> {
    let mut v = Vec::with_capacity(9 + body.len());
    v.push(opcode);
    put_u64(&mut v, body.len() as u64);
    v.extend_from_slice(body);
    v
}

/// The file being written: position and running CRC of everything written (the data-section
/// CRC, then the summary CRC).
struct Out {
    w: BufWriter<File>,
    pos: u64,
    crc: crc32fast::Hasher,
}

impl Out {
    fn write(&mut self, b: &[u8]) -> std::io::Result<()> {
        self.w.write_all(b)?;
        self.crc.update(b);
        self.pos += b.len() as u64;
        Ok(())
    }
}

/// What the summary section needs of one chunk.
#[derive(Debug, Clone, Copy)]
struct ChunkIndexEntry {
    start_ns: u64,
    end_ns: u64,
    offset: u64,
    length: u64,
    message_index_offset: u64,
    message_index_length: u64,
    compressed_size: u64,
    uncompressed_size: u64,
}

/// Chunk compression, with its reused state.
enum Compressor {
    None,
    Lz4,
    Zstd(Box<zstd::bulk::Compressor<'static>>),
}

impl Compressor {
    fn name(&self) -> &'static str {
        match self {
            Compressor::None => "",
            Compressor::Lz4 => "lz4",
            Compressor::Zstd(_) => "zstd",
        }
    }

    /// Compresses `src` into `dst` (cleared first): one LZ4 or zstd frame.
    fn compress(&mut self, src: &[u8], dst: &mut Vec<u8>) -> std::io::Result<()> {
        dst.clear();
        match self {
            Compressor::None => dst.extend_from_slice(src),
            Compressor::Lz4 => {
                // Block and content checksums off: the chunk carries its own CRC (as the
                // `mcap` crate writes LZ4 chunks).
                let mut enc = lz4::EncoderBuilder::new()
                    .level(1)
                    .block_size(lz4::BlockSize::Max4MB)
                    .block_checksum(lz4::liblz4::BlockChecksum::NoBlockChecksum)
                    .checksum(lz4::ContentChecksum::NoChecksum)
                    .build(std::mem::take(dst))?;
                enc.write_all(src)?;
                let (out, r) = enc.finish();
                *dst = out;
                r?;
            }
            Compressor::Zstd(z) => {
                dst.reserve(zstd::zstd_safe::compress_bound(src.len()));
                z.compress_to_buffer(src, dst)?;
            }
        }
        Ok(())
    }
}

/// At most this many closed chunks wait for the writer thread: the loop then blocks on the next
/// one (back-pressure) instead of queueing without bound. With the open chunk, the one being
/// written and the recycled ones, a log holds at most `QUEUED_CHUNKS + 3` chunk buffers (each
/// at most [`MAX_CHUNK_BYTES`] and its message index).
const QUEUED_CHUNKS: usize = 2;

/// A chunk's records (uncompressed, laid out in place), its message index entries ((log_time,
/// offset in `records`), little-endian) and the first and last log time it holds [ns]. Closed
/// chunks go to the writer thread; their buffers come back for reuse.
#[derive(Default)]
struct ChunkBuf {
    records: Vec<u8>,
    msg_index: Vec<u8>,
    times: Option<(u64, u64)>,
}

/// Work for the writer thread, in file order.
enum Job {
    /// A closed chunk; then flush the file buffer to the OS when `flush`.
    Chunk { chunk: ChunkBuf, flush: bool },
    /// A whole metadata record named `name` (metadata lies outside chunks).
    Metadata { record: Vec<u8>, name: String },
    /// Flush the file buffer to the OS, then answer: the log is durable up to here.
    Sync(mpsc::SyncSender<()>),
}

/// The writer thread's side of a log: the file, the compressor, and what the summary section
/// will index. Its first I/O error stops all writing; the log's side reports it.
struct Writer {
    out: Out,
    compressor: Compressor,
    /// Compressed chunk, reused.
    compressed: Vec<u8>,
    chunk_indexes: Vec<ChunkIndexEntry>,
    /// (offset, length, name) of each metadata record.
    metadata_indexes: Vec<(u64, u64, String)>,
    /// What was being written when the first error happened, and the error.
    error: Option<(String, std::io::Error)>,
    /// (end offset in the file, messages up to there) after each chunk handed to `out`: the
    /// messages a cut-short file still holds in whole chunks ([`Writer::messages_in_file`]).
    chunk_ends: Vec<(u64, u64)>,
}

impl Writer {
    /// Runs the jobs until the log's side closes the channel, sending chunk buffers back on
    /// `free`; sets `failed` on the first error. Returns itself for the summary section.
    fn run(
        mut self,
        jobs: mpsc::Receiver<Job>,
        free: mpsc::Sender<ChunkBuf>,
        failed: &AtomicBool,
    ) -> Writer {
        for job in jobs {
            match job {
                Job::Chunk { mut chunk, flush } => {
                    if self.error.is_none() {
                        let r = self.write_chunk(&chunk).map_err(|e| ("writing a chunk", e));
                        if r.is_ok() {
                            let before = self.chunk_ends.last().map_or(0, |c| c.1);
                            let n = (chunk.msg_index.len() / 16) as u64;
                            self.chunk_ends.push((self.out.pos, before + n));
                        }
                        let r = r.and_then(|()| match flush {
                            true => self.out.w.flush().map_err(|e| ("flushing", e)),
                            false => Ok(()),
                        });
                        self.fail_on(r.map_err(|(what, e)| (what.to_string(), e)), failed);
                    }
                    chunk.records.clear();
                    chunk.msg_index.clear();
                    chunk.times = None;
                    // A chunk that grew to the size limit should not keep its memory in a
                    // real-time run.
                    if chunk.records.capacity() > 2 * MAX_CHUNK_BYTES {
                        chunk.records.shrink_to(MAX_CHUNK_BYTES + 4096);
                    }
                    // The log's side may be gone (finishing): the buffer is then dropped.
                    let _ = free.send(chunk);
                }
                Job::Metadata { record, name } => {
                    if self.error.is_none() {
                        let offset = self.out.pos;
                        let r = self.out.write(&record);
                        if r.is_ok() {
                            self.metadata_indexes
                                .push((offset, record.len() as u64, name.clone()));
                        }
                        self.fail_on(
                            r.map_err(|e| (format!("writing metadata {name}"), e)),
                            failed,
                        );
                    }
                }
                Job::Sync(done) => {
                    if self.error.is_none() {
                        let r = self.out.w.flush();
                        self.fail_on(r.map_err(|e| ("flushing".to_string(), e)), failed);
                    }
                    let _ = done.send(());
                }
            }
        }
        self
    }

    /// The messages the file holds in whole chunks, from its length on disk (what a reader or
    /// `servo log recover` finds in a file cut short by an error).
    fn messages_in_file(&mut self) -> u64 {
        let _ = self.out.w.flush();
        let len = match self.out.w.get_ref().metadata() {
            Ok(m) => m.len(),
            Err(_) => return 0,
        };
        self.chunk_ends
            .iter()
            .take_while(|(end, _)| *end <= len)
            .last()
            .map_or(0, |c| c.1)
    }

    fn fail_on(&mut self, r: Result<(), (String, std::io::Error)>, failed: &AtomicBool) {
        if let Err(e) = r {
            self.error = Some(e);
            failed.store(true, Ordering::Release);
        }
    }

    /// Compresses a chunk and writes the chunk record and its message index.
    fn write_chunk(&mut self, chunk: &ChunkBuf) -> std::io::Result<()> {
        let Some((start_ns, end_ns)) = chunk.times else {
            return Ok(());
        };
        let uncompressed_crc = crc32fast::hash(&chunk.records);
        self.compressor
            .compress(&chunk.records, &mut self.compressed)?;
        let compression = self.compressor.name();
        let mut head = Vec::with_capacity(64);
        head.push(op::CHUNK);
        let body_len = 8 + 8 + 8 + 4 + 4 + compression.len() + 8 + self.compressed.len();
        put_u64(&mut head, body_len as u64);
        put_u64(&mut head, start_ns);
        put_u64(&mut head, end_ns);
        put_u64(&mut head, chunk.records.len() as u64);
        put_u32(&mut head, uncompressed_crc);
        put_str(&mut head, compression);
        put_u64(&mut head, self.compressed.len() as u64);
        let mut index = Vec::with_capacity(15);
        index.push(op::MESSAGE_INDEX);
        put_u64(&mut index, (2 + 4 + chunk.msg_index.len()) as u64);
        put_u16(&mut index, CHANNEL_ID);
        put_u32(&mut index, chunk.msg_index.len() as u32);
        let out = &mut self.out;
        let offset = out.pos;
        out.write(&head)?;
        out.write(&self.compressed)?;
        let message_index_offset = out.pos;
        out.write(&index)?;
        out.write(&chunk.msg_index)?;
        self.chunk_indexes.push(ChunkIndexEntry {
            start_ns,
            end_ns,
            offset,
            length: message_index_offset - offset,
            message_index_offset,
            message_index_length: out.pos - message_index_offset,
            compressed_size: self.compressed.len() as u64,
            uncompressed_size: chunk.records.len() as u64,
        });
        Ok(())
    }

    /// Data end, the summary section, the footer and the closing magic.
    fn summary_section(
        &mut self,
        schema_record: &[u8],
        channel_record: &[u8],
        messages: u64,
        times: Option<(u64, u64)>,
    ) -> std::io::Result<()> {
        let out = &mut self.out;
        let mut body = Vec::new();
        put_u32(&mut body, out.crc.clone().finalize());
        out.write(&record(op::DATA_END, &body))?;
        let summary_start = out.pos;
        out.crc = crc32fast::Hasher::new();
        let mut groups: Vec<(u8, u64, u64)> = Vec::new();
        let mut group = |out: &mut Out, opcode: u8, records: &[&[u8]]| {
            if records.is_empty() {
                return Ok(());
            }
            let start = out.pos;
            for r in records {
                out.write(r)?;
            }
            groups.push((opcode, start, out.pos - start));
            Ok::<(), std::io::Error>(())
        };
        group(out, op::SCHEMA, &[schema_record])?;
        group(out, op::CHANNEL, &[channel_record])?;
        let (start_ns, end_ns) = times.unwrap_or((0, 0));
        body.clear();
        put_u64(&mut body, messages);
        put_u16(&mut body, 1); // schemas
        put_u32(&mut body, 1); // channels
        put_u32(&mut body, 0); // attachments
        put_u32(&mut body, self.metadata_indexes.len() as u32);
        put_u32(&mut body, self.chunk_indexes.len() as u32);
        put_u64(&mut body, start_ns);
        put_u64(&mut body, end_ns);
        put_u32(&mut body, 10); // channel message counts: one (u16, u64) pair
        put_u16(&mut body, CHANNEL_ID);
        put_u64(&mut body, messages);
        group(out, op::STATISTICS, &[&record(op::STATISTICS, &body)])?;
        let compression = self.compressor.name();
        let chunk_indexes: Vec<Vec<u8>> = self
            .chunk_indexes
            .iter()
            .map(|c| {
                let mut b = Vec::with_capacity(96);
                put_u64(&mut b, c.start_ns);
                put_u64(&mut b, c.end_ns);
                put_u64(&mut b, c.offset);
                put_u64(&mut b, c.length);
                put_u32(&mut b, 10); // message index offsets: one (u16, u64) pair
                put_u16(&mut b, CHANNEL_ID);
                put_u64(&mut b, c.message_index_offset);
                put_u64(&mut b, c.message_index_length);
                put_str(&mut b, compression);
                put_u64(&mut b, c.compressed_size);
                put_u64(&mut b, c.uncompressed_size);
                record(op::CHUNK_INDEX, &b)
            })
            .collect();
        let refs: Vec<&[u8]> = chunk_indexes.iter().map(|r| &r[..]).collect();
        group(out, op::CHUNK_INDEX, &refs)?;
        let metadata_indexes: Vec<Vec<u8>> = self
            .metadata_indexes
            .iter()
            .map(|(offset, length, name)| {
                let mut b = Vec::new();
                put_u64(&mut b, *offset);
                put_u64(&mut b, *length);
                put_str(&mut b, name);
                record(op::METADATA_INDEX, &b)
            })
            .collect();
        let refs: Vec<&[u8]> = metadata_indexes.iter().map(|r| &r[..]).collect();
        group(out, op::METADATA_INDEX, &refs)?;
        let summary_offset_start = out.pos;
        for (opcode, start, length) in groups {
            body.clear();
            body.push(opcode);
            put_u64(&mut body, start);
            put_u64(&mut body, length);
            out.write(&record(op::SUMMARY_OFFSET, &body))?;
        }
        // Footer: the summary CRC covers the summary section up to the footer's CRC field.
        let mut footer = vec![op::FOOTER];
        put_u64(&mut footer, 8 + 8 + 4);
        put_u64(&mut footer, summary_start);
        put_u64(&mut footer, summary_offset_start);
        out.write(&footer)?;
        let crc = out.crc.clone().finalize();
        out.write(&crc.to_le_bytes())?;
        out.write(MAGIC)?;
        out.w.flush()
    }
}

/// The log's link to its writer thread.
struct Pipe {
    jobs: mpsc::SyncSender<Job>,
    /// Chunk buffers the writer is done with.
    free: mpsc::Receiver<ChunkBuf>,
    /// Set by the writer on its first error.
    failed: Arc<AtomicBool>,
    thread: std::thread::JoinHandle<Writer>,
}

/// An MCAP log being written. Call [`McapLog::finish`] at the end (also on Ctrl-C); a log that
/// is dropped unfinished is still readable up to its last flush.
///
/// The caller's thread only frames messages into the open chunk's buffer; a writer thread
/// compresses each closed chunk, computes the CRCs and writes the file, so that a run's loop
/// never waits for compression or a write system call. Closed chunks reach it through a queue
/// of at most [`QUEUED_CHUNKS`] (a writer that falls behind blocks the caller: memory stays
/// bounded) and their buffers come back for reuse. An error of the writer is reported by the
/// next [`McapLog::write_loop`], [`McapLog::flush`] or [`McapLog::finish`] call.
pub struct McapLog {
    /// The log's name once finished.
    path: PathBuf,
    /// The file growing as `path.partial`, renamed to `path` by [`McapLog::finish`]; `None`
    /// once renamed.
    rep: Option<crate::output::Replacement>,
    /// The messages the file holds, once its writer failed (whole chunks on disk).
    in_file: Option<u64>,
    /// The previous file at `path`, kept by [`McapLog::finish`] (`run.mcap.1`).
    backup: Option<PathBuf>,
    opts: McapLogOptions,
    sequence: u32,
    messages: u64,
    last_flush_s: f64,
    last_flush_wall: std::time::Instant,
    /// The open chunk.
    chunk: ChunkBuf,
    /// First and last log time of the whole log [ns].
    times: Option<(u64, u64)>,
    /// The writer thread; `None` once finished or failed.
    pipe: Option<Pipe>,
    /// Why the log stopped, once its writer failed (for the calls after the first report).
    failed: Option<String>,
    schema_record: Vec<u8>,
    channel_record: Vec<u8>,
}

impl std::fmt::Debug for McapLog {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapLog")
            .field("path", &self.path)
            .field("messages", &self.messages)
            .finish()
    }
}

impl McapLog {
    /// Creates `path.partial` ([`crate::output::Replacement::begin_partial`]: readable as it
    /// grows, renamed to `path` by [`McapLog::finish`]) and writes the header, the
    /// schemas/channels and the run metadata (`metadata`: key/value strings, see
    /// [`RUN_METADATA`]); flushes so that the metadata survives a kill.
    pub fn create(
        path: &Path,
        metadata: &BTreeMap<String, String>,
        opts: McapLogOptions,
    ) -> anyhow::Result<McapLog> {
        let (rep, file) = crate::output::Replacement::begin_partial(path)
            .with_context(|| format!("creating MCAP log {}", path.display()))?;
        let compressor = match (opts.compress, opts.fast_compression) {
            (false, _) => Compressor::None,
            (true, true) => Compressor::Lz4,
            // Level 1: chunks of 50-100 samples in real time, the fastest zstd level that
            // still finds the repetition between samples.
            (true, false) => Compressor::Zstd(Box::new(
                zstd::bulk::Compressor::new(1)
                    .with_context(|| format!("MCAP log {}: zstd", path.display()))?,
            )),
        };
        let (schema_name, schema_encoding, schema_data, message_encoding) = match opts.encoding {
            LogEncoding::Json => (
                LOOP_SCHEMA_NAME,
                "jsonschema",
                loop_schema().into_bytes(),
                "json",
            ),
            LogEncoding::Protobuf => (
                LOOP_PROTO_NAME,
                "protobuf",
                loop_descriptor_set(),
                "protobuf",
            ),
        };
        let mut body = Vec::new();
        put_u16(&mut body, SCHEMA_ID);
        put_str(&mut body, schema_name);
        put_str(&mut body, schema_encoding);
        put_u32(&mut body, schema_data.len() as u32);
        body.extend_from_slice(&schema_data);
        let schema_record = record(op::SCHEMA, &body);
        body.clear();
        put_u16(&mut body, CHANNEL_ID);
        put_u16(&mut body, SCHEMA_ID);
        put_str(&mut body, LOOP_TOPIC);
        put_str(&mut body, message_encoding);
        put_str_map(&mut body, &BTreeMap::new());
        let channel_record = record(op::CHANNEL, &body);
        body.clear();
        put_str(&mut body, PROFILE);
        put_str(
            &mut body,
            concat!("servo ", env!("CARGO_PKG_VERSION"), " / servo-io"),
        );
        let header = record(op::HEADER, &body);

        let mut out = Out {
            w: BufWriter::with_capacity(1 << 16, file),
            pos: 0,
            crc: crc32fast::Hasher::new(),
        };
        let written = out
            .write(MAGIC)
            .and_then(|()| out.write(&header))
            .and_then(|()| out.write(&schema_record))
            .and_then(|()| out.write(&channel_record));
        written.with_context(|| format!("MCAP log {}: writing the header", path.display()))?;
        let writer = Writer {
            out,
            compressor,
            compressed: Vec::new(),
            chunk_indexes: Vec::new(),
            metadata_indexes: Vec::new(),
            error: None,
            chunk_ends: Vec::new(),
        };
        let (jobs, job_rx) = mpsc::sync_channel(QUEUED_CHUNKS);
        let (free_tx, free) = mpsc::channel();
        let failed = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&failed);
        let thread = std::thread::Builder::new()
            .name("mcap-writer".to_string())
            .spawn(move || writer.run(job_rx, free_tx, &flag))
            .with_context(|| format!("MCAP log {}: starting its writer thread", path.display()))?;

        let mut log = McapLog {
            path: path.to_path_buf(),
            rep: Some(rep),
            in_file: None,
            backup: None,
            opts,
            sequence: 0,
            messages: 0,
            last_flush_s: f64::NEG_INFINITY,
            last_flush_wall: std::time::Instant::now(),
            chunk: ChunkBuf::default(),
            times: None,
            pipe: Some(Pipe {
                jobs,
                free,
                failed,
                thread,
            }),
            failed: None,
            schema_record,
            channel_record,
        };
        let mut metadata = metadata.clone();
        metadata.insert(START_TIME_KEY.to_string(), opts.start_unix_ns.to_string());
        log.write_metadata(RUN_METADATA, &metadata)?;
        log.flush()?;
        Ok(log)
    }

    /// The log's name (once finished: [`McapLog::writing`] is the file while it grows).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The file on disk now: `NAME.partial` while the log grows and after a failed finish
    /// (keep it for `servo log recover`), `NAME` once finished.
    pub fn writing(&self) -> &Path {
        self.rep.as_ref().map_or(&self.path, |r| r.writing())
    }

    /// Whether [`McapLog::finish`] renamed the finished log to its name.
    pub fn is_finished(&self) -> bool {
        self.rep.is_none()
    }

    /// The previous file at [`McapLog::path`], kept beside the finished log (`run.mcap.1`).
    pub fn backup(&self) -> Option<&Path> {
        self.backup.as_deref()
    }

    /// Messages written so far.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    /// The messages the file holds: all of them while it works, and after its writer failed
    /// (a full disk) those in the whole chunks that reached the file.
    pub fn messages_in_file(&self) -> u64 {
        self.in_file.unwrap_or(self.messages)
    }

    /// The error of a log that cannot take more records: finished, or its writer failed (the
    /// first call after the failure gets the I/O error itself).
    fn closed_error(&mut self) -> Error {
        if let Some(p) = self.pipe.take() {
            // The writer failed: stop it and take its error.
            drop(p.jobs);
            let what = match p.thread.join() {
                Ok(mut w) => {
                    self.in_file = Some(w.messages_in_file());
                    w.error
                }
                Err(_) => None,
            };
            let e = match what {
                Some((what, e)) => self.io_error(&what, e),
                None => anyhow!(
                    "MCAP log {}: its writer thread stopped",
                    self.path.display()
                ),
            };
            self.failed = Some(format!("{e:#}"));
            return e;
        }
        match &self.failed {
            Some(why) => anyhow!("{why} (the log stopped there)"),
            None => anyhow!("MCAP log {}: already finished", self.path.display()),
        }
    }

    /// "MCAP log PATH: `what`" caused by `e`.
    fn io_error(&self, what: &str, e: std::io::Error) -> Error {
        Error::Context {
            context: format!("MCAP log {}: {what}", self.path.display()),
            source: Box::new(Error::Io(e)),
        }
    }

    /// The writer, if it is running and has not failed.
    fn pipe(&mut self) -> Result<&Pipe, Error> {
        match &self.pipe {
            Some(p) if !p.failed.load(Ordering::Acquire) => {}
            _ => return Err(self.closed_error()),
        }
        self.pipe
            .as_ref()
            .ok_or_else(|| anyhow!("MCAP log {}: already finished", self.path.display()))
    }

    /// Hands `job` to the writer thread (waiting while its queue is full).
    fn send(&mut self, job: Job) -> anyhow::Result<()> {
        if self.pipe()?.jobs.send(job).is_err() {
            return Err(self.closed_error());
        }
        Ok(())
    }

    fn log_time_ns(&self, time_s: f64) -> u64 {
        let ns = (time_s.max(0.0) * 1e9).round();
        self.opts
            .start_unix_ns
            .saturating_add(if ns.is_finite() { ns as u64 } else { 0 })
    }

    /// Writes one loop sample; ends the chunk and flushes when `flush_period_s` of run time has
    /// passed since the last flush (of wall-clock time with `flush_on_wall_clock`), or when
    /// the chunk holds [`MAX_CHUNK_BYTES`]. Reports an earlier failure of the writer thread.
    pub fn write_loop(&mut self, msg: &LoopMsg) -> anyhow::Result<()> {
        self.pipe()?;
        let t = self.log_time_ns(msg.time_s);
        // The message record, framed in place in the chunk: the length is patched once the
        // message is encoded.
        let at = self.chunk.records.len();
        let c = &mut self.chunk.records;
        let mut head = [0u8; 31];
        head[0] = op::MESSAGE;
        head[9..11].copy_from_slice(&CHANNEL_ID.to_le_bytes());
        head[11..15].copy_from_slice(&self.sequence.to_le_bytes());
        head[15..23].copy_from_slice(&t.to_le_bytes());
        head[23..31].copy_from_slice(&t.to_le_bytes());
        c.extend_from_slice(&head);
        match self.opts.encoding {
            LogEncoding::Json => msg.write_json(c),
            LogEncoding::Protobuf => msg.write_protobuf(c),
        }
        let len = (c.len() - at - 9) as u64;
        c[at + 1..at + 9].copy_from_slice(&len.to_le_bytes());
        let mut entry = [0u8; 16];
        entry[..8].copy_from_slice(&t.to_le_bytes());
        entry[8..].copy_from_slice(&(at as u64).to_le_bytes());
        self.chunk.msg_index.extend_from_slice(&entry);
        self.chunk.times = Some(
            self.chunk
                .times
                .map_or((t, t), |(a, b)| (a.min(t), b.max(t))),
        );
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
            self.end_chunk(true)?;
            self.last_flush_s = msg.time_s;
            self.last_flush_wall = std::time::Instant::now();
        } else if self.chunk.records.len() >= MAX_CHUNK_BYTES {
            self.end_chunk(false)?;
        }
        Ok(())
    }

    /// Ends the open chunk (if any) and hands it to the writer thread, which compresses and
    /// writes it (and then flushes the file to the OS when `flush`). The next chunk starts in
    /// a buffer the writer is done with, or a new one.
    fn end_chunk(&mut self, flush: bool) -> anyhow::Result<()> {
        if self.chunk.times.is_none() {
            return Ok(());
        }
        let next = self.pipe()?.free.try_recv().unwrap_or_default();
        let chunk = std::mem::replace(&mut self.chunk, next);
        if let Some((s, e)) = chunk.times {
            self.times = Some(self.times.map_or((s, e), |(a, b)| (a.min(s), b.max(e))));
        }
        self.send(Job::Chunk { chunk, flush })
    }

    /// Writes a metadata record (after ending the open chunk: metadata lies outside chunks).
    fn write_metadata(&mut self, name: &str, map: &BTreeMap<String, String>) -> anyhow::Result<()> {
        self.end_chunk(false)?;
        let mut body = Vec::new();
        put_str(&mut body, name);
        put_str_map(&mut body, map);
        self.send(Job::Metadata {
            record: record(op::METADATA, &body),
            name: name.to_string(),
        })
    }

    /// Ends the open chunk and flushes to the OS now: returns once everything written so far
    /// is in the file (or with the writer's error).
    pub fn flush(&mut self) -> anyhow::Result<()> {
        if self.pipe.is_none() && self.failed.is_none() {
            return Ok(()); // finished
        }
        self.end_chunk(false)?;
        let (done_tx, done) = mpsc::sync_channel(1);
        self.send(Job::Sync(done_tx))?;
        if done.recv().is_err() {
            return Err(self.closed_error());
        }
        self.pipe().map(|_| ())
    }

    /// Writes the end-of-run summary metadata record ([`SUMMARY_METADATA`]).
    pub fn write_summary(&mut self, summary: &BTreeMap<String, String>) -> anyhow::Result<()> {
        self.pipe()?;
        self.write_metadata(SUMMARY_METADATA, summary)
    }

    /// Writes the summary section and the footer and closes the file. Safe to call twice; a
    /// log whose writer failed returns that error.
    pub fn finish(&mut self) -> anyhow::Result<()> {
        if self.pipe.is_none() {
            return match self.failed.is_some() {
                true => Err(self.closed_error()),
                false => Ok(()),
            };
        }
        self.end_chunk(false)?;
        let Some(p) = self.pipe.take() else {
            return Ok(());
        };
        drop(p.jobs);
        let path = self.path.display().to_string();
        let mut w = p
            .thread
            .join()
            .map_err(|_| anyhow!("MCAP log {path}: its writer thread panicked"))?;
        if let Some((what, e)) = w.error.take() {
            self.in_file = Some(w.messages_in_file());
            let e = self.io_error(&what, e);
            self.failed = Some(format!("{e:#}"));
            return Err(e);
        }
        let ended = w.summary_section(
            &self.schema_record,
            &self.channel_record,
            self.messages,
            self.times,
        );
        if let Err(e) = ended {
            self.in_file = Some(w.messages_in_file());
            let e = self.io_error("finishing", e);
            self.failed = Some(format!("{e:#}"));
            return Err(e);
        }
        // Finished: the file takes the log's name (a previous file there is kept as NAME.N).
        let Some(rep) = self.rep.take() else {
            return Ok(());
        };
        let file = w
            .out
            .w
            .into_inner()
            .map_err(|e| self.io_error("finishing", e.into_error()))?;
        let done = rep.commit(file);
        match done {
            Ok(written) => {
                if let Some(n) = written.backup_note() {
                    eprintln!("note: {n}");
                }
                self.backup = written.backup;
                Ok(())
            }
            Err(e) => {
                self.failed = Some(format!("{e:#}"));
                Err(e)
            }
        }
    }
}

impl Drop for McapLog {
    /// An unfinished log is finished on drop (errors ignored); call [`McapLog::finish`] to see them.
    fn drop(&mut self) {
        let _ = self.finish();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mcap_read::read_mcap;

    use crate::loop_msg::test_msg as msg;

    /// The writer thread's first I/O error (here the reader of a FIFO goes away after 64 KiB:
    /// EPIPE) is reported by a later `write_loop` with the file and the cause, then by `flush`
    /// and `finish`; nothing hangs and nothing panics.
    #[cfg(unix)]
    #[test]
    fn a_failing_file_is_reported_by_the_next_write_and_at_finish() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("log.fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        assert!(made.unwrap().success());
        let r = fifo.clone();
        let reader = std::thread::spawn(move || {
            let mut f = File::open(&r).unwrap();
            let mut buf = vec![0u8; 1 << 16];
            std::io::Read::read_exact(&mut f, &mut buf).unwrap();
        });
        let opts = McapLogOptions {
            compress: false,
            encoding: LogEncoding::Protobuf,
            ..McapLogOptions::default()
        };
        let mut log = McapLog::create(&fifo, &BTreeMap::new(), opts).unwrap();
        let mut failed_at = None;
        for k in 0..1_000_000 {
            if let Err(e) = log.write_loop(&msg(k)) {
                failed_at = Some((k, format!("{e:#}")));
                break;
            }
        }
        reader.join().unwrap();
        let (k, e) = failed_at.expect("the broken pipe is reported");
        // 64 KiB are about 600 messages; the error shows within a few 50-message chunks.
        assert!(k < 5_000, "reported only at message {k}");
        assert!(e.contains("MCAP log") && e.contains("log.fifo"), "{e}");
        assert!(e.to_lowercase().contains("broken pipe"), "{e}");
        for e in [log.flush().unwrap_err(), log.finish().unwrap_err()] {
            let e = format!("{e:#}").to_lowercase();
            assert!(e.contains("log.fifo") && e.contains("broken pipe"), "{e}");
        }
        assert!(log.write_loop(&msg(0)).is_err());
    }

    /// Every kind of log servo writes (three compressions, two encodings, chunks by run time,
    /// by wall clock and by size) is read by the `mcap` crate's strict readers: the linear
    /// reader checking every chunk CRC, the data-section CRC, the summary CRC and that nothing
    /// follows the end magic; the summary (statistics, schema, channel, chunk and metadata
    /// indexes); and, as a viewer seeking in the file does, every message reached through its
    /// chunk index and message index. servo's reader gets the same messages back.
    #[test]
    fn every_log_is_read_by_the_strict_mcap_readers() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("w.mcap");
        let n = 40_100; // over MAX_CHUNK_BYTES of protobuf messages in one wall-clock chunk
        for (compress, fast) in [(true, false), (true, true), (false, false)] {
            for encoding in [LogEncoding::Protobuf, LogEncoding::Json] {
                for wall in [false, true] {
                    let what = format!("compress {compress} fast {fast} {encoding:?} wall {wall}");
                    let mut meta = BTreeMap::new();
                    meta.insert("gains_toml".to_string(), "[pid]\nkp = 1.0\n".to_string());
                    let mut log = McapLog::create(
                        &path,
                        &meta,
                        McapLogOptions {
                            compress,
                            fast_compression: fast,
                            encoding,
                            flush_on_wall_clock: wall,
                            flush_period_s: if wall { 1e3 } else { 0.05 },
                            start_unix_ns: 1_000,
                        },
                    )
                    .unwrap();
                    for k in 0..n {
                        log.write_loop(&msg(k)).unwrap();
                    }
                    let mut summary = BTreeMap::new();
                    summary.insert("samples".to_string(), n.to_string());
                    log.write_summary(&summary).unwrap();
                    log.finish().unwrap();
                    log.finish().unwrap();
                    assert!(log.write_loop(&msg(0)).is_err());
                    let bytes = std::fs::read(&path).unwrap();

                    let mut reader = mcap::sans_io::LinearReader::new_with_options(
                        mcap::sans_io::LinearReaderOptions::default()
                            .with_validate_chunk_crcs(true)
                            .with_validate_data_section_crc(true)
                            .with_validate_summary_section_crc(true)
                            .with_check_finishes_after_end_magic(true),
                    );
                    let (mut rest, mut messages, mut records) = (&bytes[..], 0, 0);
                    while let Some(event) = reader.next_event() {
                        match event.unwrap_or_else(|e| panic!("{what}: {e}")) {
                            mcap::sans_io::LinearReadEvent::ReadRequest(need) => {
                                let k = need.min(rest.len());
                                reader.insert(k).copy_from_slice(&rest[..k]);
                                reader.notify_read(k);
                                rest = &rest[k..];
                            }
                            mcap::sans_io::LinearReadEvent::Record { opcode, .. } => {
                                records += 1;
                                messages += usize::from(opcode == op::MESSAGE);
                            }
                        }
                    }
                    assert_eq!(messages, n, "{what}");
                    assert!(records > n, "{what}");

                    let s = mcap::Summary::read(&bytes).unwrap().unwrap();
                    let stats = s.stats.as_ref().unwrap();
                    assert_eq!(stats.message_count, n as u64, "{what}");
                    assert_eq!(stats.channel_message_counts[&CHANNEL_ID], n as u64);
                    assert_eq!(stats.metadata_count, 2);
                    assert_eq!(stats.chunk_count as usize, s.chunk_indexes.len());
                    assert_eq!(
                        (stats.message_start_time, stats.message_end_time),
                        (1_000, 1_000 + (n as u64 - 1) * 1_000_000),
                        "{what}"
                    );
                    // Chunks: by run time every 50 samples; by wall clock (never due here)
                    // and by size, at MAX_CHUNK_BYTES.
                    let chunks = s.chunk_indexes.len();
                    if wall {
                        assert!((2..10).contains(&chunks), "{what}: {chunks} chunks");
                    } else {
                        // The first sample flushes at once (the run has started), then every 50.
                        assert_eq!(chunks, 1 + (n - 1).div_ceil(50), "{what}");
                    }
                    let ch = &s.channels[&CHANNEL_ID];
                    let schema = ch.schema.as_ref().unwrap();
                    assert_eq!(ch.topic, LOOP_TOPIC);
                    let (enc, schema_enc) = match encoding {
                        LogEncoding::Protobuf => ("protobuf", "protobuf"),
                        LogEncoding::Json => ("json", "jsonschema"),
                    };
                    assert_eq!(ch.message_encoding, enc);
                    assert_eq!(
                        (schema.name.as_str(), schema.encoding.as_str()),
                        ("servo.Loop", schema_enc)
                    );
                    let names: Vec<&str> =
                        s.metadata_indexes.iter().map(|m| m.name.as_str()).collect();
                    assert_eq!(names, [RUN_METADATA, SUMMARY_METADATA]);
                    let mut seen = 0;
                    for ci in &s.chunk_indexes {
                        let expected = if compress && fast {
                            "lz4"
                        } else if compress {
                            "zstd"
                        } else {
                            ""
                        };
                        assert_eq!(ci.compression, expected);
                        let idx = s.read_message_indexes(&bytes, ci).unwrap();
                        // seek_message decompresses the whole chunk: the first and the last
                        // message of each chunk only (every message would take minutes).
                        let entries = &idx[ch.as_ref()];
                        for (k, entry) in entries.iter().enumerate() {
                            if k == 0 || k + 1 == entries.len() {
                                let m = s.seek_message(&bytes, ci, entry).unwrap();
                                assert_eq!(m.log_time, entry.log_time);
                                assert_eq!(m.sequence as usize, seen);
                            }
                            seen += 1;
                        }
                        assert_eq!(
                            s.stream_chunk(&bytes, ci).unwrap().count(),
                            idx[ch.as_ref()].len()
                        );
                    }
                    assert_eq!(seen, n, "{what}");

                    let run = read_mcap(&path).unwrap();
                    assert!(
                        run.finished && run.notes.is_empty(),
                        "{what}: {:?}",
                        run.notes
                    );
                    assert_eq!(run.summary["samples"], n.to_string());
                    assert_eq!(run.metadata["gains_toml"], "[pid]\nkp = 1.0\n");
                    assert_eq!(run.loop_msgs.len(), n);
                    for k in [0, 1, 899, 901, n - 1] {
                        let (a, b) = (run.loop_msgs[k], msg(k));
                        assert_eq!(a.time_s, b.time_s, "{what}");
                        assert_eq!(a.u_v, b.u_v, "{what}");
                        assert_eq!(a.saturated, b.saturated, "{what}");
                        assert_eq!(
                            a.ref_omega_l_rad_s.to_bits(),
                            b.ref_omega_l_rad_s.to_bits(),
                            "{what}"
                        );
                    }
                }
            }
        }
    }
}
