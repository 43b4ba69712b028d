//! Reading a servo MCAP log back: the `/servo/loop` messages into a [`Record`], the run metadata,
//! robust to a truncated file (a killed run): everything up to the last complete chunk is read and
//! the notes say what was lost.

use super::loop_msg::{LoopMsg, LOOP_TOPIC};
use super::mcap_write::{RUN_METADATA, SUMMARY_METADATA};
use super::units::Signal;
use crate::error::{self as anyhow, anyhow, bail, Context};
use mcap::records::Record as McapRecord;
use servo_core::record::Record;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// A servo MCAP log as read.
#[derive(Debug, Clone, Default)]
pub struct McapRun {
    /// Signals in SI units (u, theta_l, omega_l estimate, i_a, ref when present).
    pub record: Record,
    /// Every loop message, as written.
    pub loop_msgs: Vec<LoopMsg>,
    /// The run metadata record ([`RUN_METADATA`]).
    pub metadata: BTreeMap<String, String>,
    /// The end-of-run summary record ([`SUMMARY_METADATA`]), if the run got that far.
    pub summary: BTreeMap<String, String>,
    /// True when the file ends properly (footer and end magic).
    pub finished: bool,
    /// What was lost and why, for a truncated or damaged file.
    pub notes: Vec<String>,
    /// The feedforward part of u per sample [V] (`ff_v`; `None` when no sample has one or it
    /// was not asked for).
    pub feedforward_v: Option<Vec<f64>>,
}

/// The records of MCAP bytes, chunks flattened, read incrementally by the library's streaming
/// reader with every buffer bounded by `limit` bytes (the file's size): a corrupted length or
/// `uncompressed_size` field gives an error instead of a huge allocation. (mcap's own
/// `ChunkFlattener` sets no limit.) Chunk CRCs are checked after each chunk's records.
pub struct BoundedRecords<'a> {
    reader: mcap::sans_io::LinearReader,
    rest: &'a [u8],
}

impl<'a> BoundedRecords<'a> {
    /// `with_magic`: `bytes` starts with the MCAP magic (a whole file) rather than at a record.
    pub fn new(bytes: &'a [u8], with_magic: bool, limit: usize) -> BoundedRecords<'a> {
        BoundedRecords {
            reader: mcap::sans_io::LinearReader::new_with_options(
                mcap::sans_io::LinearReaderOptions::default()
                    .with_skip_start_magic(!with_magic)
                    .with_skip_end_magic(true)
                    .with_record_length_limit(limit)
                    .with_validate_chunk_crcs(true),
            ),
            rest: bytes,
        }
    }
}

impl Iterator for BoundedRecords<'_> {
    type Item = mcap::McapResult<McapRecord<'static>>;

    fn next(&mut self) -> Option<Self::Item> {
        use mcap::sans_io::LinearReadEvent;
        while let Some(event) = self.reader.next_event() {
            match event {
                Ok(LinearReadEvent::ReadRequest(need)) => {
                    let n = need.min(self.rest.len());
                    self.reader.insert(n).copy_from_slice(&self.rest[..n]);
                    self.reader.notify_read(n);
                    self.rest = &self.rest[n..];
                }
                Ok(LinearReadEvent::Record { data, opcode }) => {
                    return Some(parse_record_checked(opcode, data).map(|r| r.into_owned()))
                }
                Err(e) => return Some(Err(e)),
            }
        }
        None
    }
}

/// One field of a record body, for [`check_lengths`].
#[derive(Clone, Copy)]
enum Field {
    /// Fixed size [bytes].
    Fixed(usize),
    /// u32 length + bytes (a string or a byte array of fixed-size items).
    Str,
    /// u32 length + string/string pairs.
    StrMap,
    /// u64 length + bytes.
    Bytes64,
}

/// Checks every length prefix of an MCAP record body against the bytes that remain, so that
/// `mcap::parse_record` (binrw reserves each string's declared length up front, up to 4 GiB)
/// allocates nothing beyond the record's own size.
pub fn check_lengths(opcode: u8, body: &[u8]) -> Result<(), String> {
    use Field::*;
    let fields: &[Field] = match opcode {
        0x01 => &[Str, Str],                                 // header
        0x03 => &[Fixed(2), Str, Str, Str],                  // schema
        0x04 => &[Fixed(4), Str, Str, StrMap],               // channel
        0x06 => &[Fixed(28), Str, Bytes64],                  // chunk
        0x07 => &[Fixed(2), Str],                            // message index
        0x08 => &[Fixed(32), Str, Fixed(8), Str, Fixed(16)], // chunk index
        0x09 => &[Fixed(16), Str, Str, Bytes64],             // attachment
        0x0A => &[Fixed(40), Str, Str],                      // attachment index
        0x0B => &[Fixed(42), Str],                           // statistics
        0x0C => &[Str, StrMap],                              // metadata
        0x0D => &[Fixed(16), Str],                           // metadata index
        _ => return Ok(()), // fixed-size or opaque records (message, footer, ...)
    };
    let mut at = 0usize;
    let left = |at: usize| body.len().saturating_sub(at);
    let take = |at: &mut usize, n: usize| -> Result<usize, String> {
        if n > left(*at) {
            return Err(format!(
                "record 0x{opcode:02X}: a field declares {n} bytes but only {} remain",
                left(*at)
            ));
        }
        let start = *at;
        *at += n;
        Ok(start)
    };
    let u32_at = |b: &[u8], at: usize| -> usize {
        let mut x = [0u8; 4];
        x.copy_from_slice(&b[at..at + 4]);
        u32::from_le_bytes(x) as usize
    };
    for f in fields {
        match *f {
            Fixed(n) => {
                take(&mut at, n)?;
            }
            Str => {
                let p = take(&mut at, 4)?;
                take(&mut at, u32_at(body, p))?;
            }
            Bytes64 => {
                let p = take(&mut at, 8)?;
                let mut x = [0u8; 8];
                x.copy_from_slice(&body[p..p + 8]);
                take(
                    &mut at,
                    usize::try_from(u64::from_le_bytes(x)).unwrap_or(usize::MAX),
                )?;
            }
            StrMap => {
                let p = take(&mut at, 4)?;
                let start = take(&mut at, u32_at(body, p))?;
                let map = &body[start..at];
                let mut q = 0usize;
                while q < map.len() {
                    if map.len() - q < 4 {
                        return Err(format!("record 0x{opcode:02X}: a map entry is cut short"));
                    }
                    let n = u32_at(map, q);
                    if n > map.len() - q - 4 {
                        return Err(format!(
                            "record 0x{opcode:02X}: a map string declares {n} bytes but only {} remain",
                            map.len() - q - 4
                        ));
                    }
                    q += 4 + n;
                }
            }
        }
    }
    Ok(())
}

/// `mcap::parse_record` after [`check_lengths`].
pub fn parse_record_checked(opcode: u8, body: &[u8]) -> mcap::McapResult<McapRecord<'_>> {
    check_lengths(opcode, body).map_err(|e| {
        mcap::McapError::from(std::io::Error::new(std::io::ErrorKind::InvalidData, e))
    })?;
    mcap::parse_record(opcode, body)
}

/// servo's reader of its MCAP logs (`.mcap`, the `/servo/loop` channel and the run metadata).
pub struct McapReader;

impl crate::log_reader::LogReader for McapReader {
    fn name(&self) -> &'static str {
        "MCAP"
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["mcap"]
    }
    /// `.mcap`, and `.mcap.partial`: a log still growing, or left by a run that was killed.
    fn can_read(&self, path: &Path) -> bool {
        let name = path.to_string_lossy().to_ascii_lowercase();
        crate::log_reader::extension(path) == "mcap" || name.ends_with(".mcap.partial")
    }
    /// Refuses a `--columns` map: an MCAP log names its own signals (and holds the equivalent
    /// rotation itself on a linear axis: `axis` is not used).
    fn read(
        &self,
        path: &Path,
        columns: Option<&str>,
        want: Option<&[Signal]>,
        _axis: &servo_core::Transmission,
    ) -> anyhow::Result<(Record, crate::LogMeta)> {
        if columns.is_some() {
            bail!(
                "{}: --columns applies to CSV logs only; an MCAP log names its own signals",
                path.display()
            );
        }
        let run = read_mcap_signals(path, want)?;
        let meta = crate::LogMeta {
            columns: None,
            entries: run.metadata,
            summary: run.summary,
            notes: run.notes,
            feedforward_v: run.feedforward_v,
        };
        Ok((run.record, meta))
    }
    /// The channels (encoding, schema, message count), then the log as servo reads it
    /// (samples, duration, signals, metadata keys, notes) or why it cannot.
    fn inspect(&self, path: &Path) -> anyhow::Result<Vec<String>> {
        let source = path.display().to_string();
        let bytes = read_mcap_bytes(path)?;
        let mut out = vec![format!("{source}: MCAP")];
        let mut topics = Vec::new();
        match mcap::read::Summary::read(&bytes) {
            Ok(Some(s)) => {
                let counts = s.stats.as_ref().map(|st| st.channel_message_counts.clone());
                for (id, c) in &s.channels {
                    let n = counts
                        .as_ref()
                        .and_then(|m| m.get(id))
                        .map(|n| format!(", {n} messages"))
                        .unwrap_or_default();
                    topics.push(c.topic.clone());
                    out.push(format!(
                        "  channel {}: encoding {}, schema {}{n}",
                        c.topic,
                        c.message_encoding,
                        c.schema.as_ref().map(|s| s.name.as_str()).unwrap_or("-")
                    ));
                }
            }
            Ok(None) => out.push("  (no summary section: an unfinished log?)".to_string()),
            Err(e) => out.push(format!("  (summary unreadable: {e})")),
        }
        let (rec, meta) = parse_mcap_signals(&bytes, &source, None)
            .map(|run| {
                let meta = crate::LogMeta {
                    columns: None,
                    entries: run.metadata,
                    summary: run.summary,
                    notes: run.notes,
                    feedforward_v: run.feedforward_v,
                };
                (run.record, meta)
            })
            .with_context(|| {
                format!(
                    "{source}: an MCAP file{}, not readable as a servo log",
                    if topics.is_empty() {
                        String::new()
                    } else {
                        format!(
                            " with channels {}",
                            crate::excerpt::join_excerpt(
                                &topics,
                                ", ",
                                crate::excerpt::HEADER_CHARS
                            )
                        )
                    }
                )
            })?;
        out.push(format!(
            "  {} samples, {:.3} s, signals {}",
            rec.len(),
            rec.time_s.last().copied().unwrap_or(0.0) - rec.time_s.first().copied().unwrap_or(0.0),
            rec.signals().join(", ")
        ));
        if !meta.entries.is_empty() {
            let keys: Vec<&str> = meta.entries.keys().map(String::as_str).collect();
            out.push(format!("  metadata: {}", keys.join(", ")));
        }
        for n in &meta.notes {
            out.push(format!("  note: {n}"));
        }
        Ok(out)
    }
}

/// The bytes of the MCAP file `path`, read after its first 8 bytes were found to be the MCAP
/// magic (a large file that is not an MCAP is refused after its first bytes).
pub fn read_mcap_bytes(path: &Path) -> anyhow::Result<Vec<u8>> {
    use std::io::Read;
    let source = path.display();
    let file = std::fs::File::open(path).with_context(|| format!("reading MCAP log {source}"))?;
    let mut bytes = Vec::new();
    (&file)
        .take(mcap::MAGIC.len() as u64)
        .read_to_end(&mut bytes)
        .with_context(|| format!("reading MCAP log {source}"))?;
    if bytes != mcap::MAGIC {
        bail!("{source}: not an MCAP file (bad magic bytes at the start)");
    }
    (&file)
        .read_to_end(&mut bytes)
        .with_context(|| format!("reading MCAP log {source}"))?;
    Ok(bytes)
}

/// The notes servo's reader gives on MCAP `bytes` (the log was not finished, what was lost),
/// without keeping its samples; none when the bytes are not a servo log.
pub fn notes_of(bytes: &[u8], source: &str) -> Vec<String> {
    walk_mcap(bytes, source, &mut |_| {})
        .map(|run| run.notes)
        .unwrap_or_default()
}

/// Reads the MCAP file `path`.
pub fn read_mcap(path: &Path) -> anyhow::Result<McapRun> {
    let bytes = read_mcap_bytes(path)?;
    parse_mcap(&bytes, &path.display().to_string())
}

/// Parses MCAP `bytes`; `source` names the file in messages. Every loop message is kept in
/// [`McapRun::loop_msgs`] and every signal in the record.
pub fn parse_mcap(bytes: &[u8], source: &str) -> anyhow::Result<McapRun> {
    let mut msgs = Vec::new();
    let mut run = walk_mcap(bytes, source, &mut |m: &LoopMsg| msgs.push(*m))?;
    run.record = record_of(&msgs, source);
    run.feedforward_v = column_if_any(msgs.iter().map(|m| m.ff_v).collect());
    run.loop_msgs = msgs;
    Ok(run)
}

/// Reads the MCAP file `path`, building only the signals in `want` (time always; `None`: every
/// signal and the feedforward). [`McapRun::loop_msgs`] stays empty: the fast path of the
/// commands that read a log (`servo frf` reads 10 minutes at 1 kHz in about 0.1 s).
pub fn read_mcap_signals(path: &Path, want: Option<&[Signal]>) -> anyhow::Result<McapRun> {
    let bytes = read_mcap_bytes(path)?;
    parse_mcap_signals(&bytes, &path.display().to_string(), want)
}

/// [`read_mcap_signals`] on bytes; `source` names the file in messages.
pub fn parse_mcap_signals(
    bytes: &[u8],
    source: &str,
    want: Option<&[Signal]>,
) -> anyhow::Result<McapRun> {
    let wants = |s: Signal| want.is_none_or(|w| w.contains(&s));
    // (signal, field of the message, column).
    type Getter = fn(&LoopMsg) -> f64;
    let mut cols: Vec<(Signal, Getter, Vec<f64>)> = [
        (Signal::U, (|m: &LoopMsg| m.u_v) as Getter),
        (Signal::ThetaL, |m| m.theta_l_rad),
        (Signal::OmegaL, |m| m.omega_l_rad_s),
        (Signal::IA, |m| m.i_a_a),
        (Signal::Ref, |m| m.ref_rad),
        (Signal::IRef, |m| m.i_ref_a),
        (Signal::Duty, |m| m.duty),
    ]
    .into_iter()
    .filter(|(s, _)| wants(*s))
    .map(|(s, f)| (s, f, Vec::new()))
    .collect();
    let mut time = Vec::new();
    let mut ff = Vec::new();
    let keep_ff = want.is_none();
    let mut run = walk_mcap(bytes, source, &mut |m: &LoopMsg| {
        time.push(m.time_s);
        for (_, f, c) in cols.iter_mut() {
            c.push(f(m));
        }
        if keep_ff {
            ff.push(m.ff_v);
        }
    })?;
    run.record = Record {
        source: source.to_string(),
        time_s: time,
        ..Record::default()
    };
    for (s, _, c) in cols {
        if let Some(c) = column_if_any(c) {
            s.store(&mut run.record, c);
        }
    }
    run.feedforward_v = column_if_any(ff);
    Ok(run)
}

/// A column, or `None` when no sample has a value.
fn column_if_any(v: Vec<f64>) -> Option<Vec<f64>> {
    v.iter().any(|x| x.is_finite()).then_some(v)
}

/// Largest factor by which a chunk may inflate relative to the whole file: a declared
/// `uncompressed_size` beyond `MAX_INFLATION x` the file's size is refused (servo's logs inflate
/// 1.5-2 times; the bound stops a decompression bomb or a corrupted size field).
pub const MAX_INFLATION: usize = 64;

/// Why reading stopped early.
enum Stop {
    /// The file is cut short or damaged at a record: keep what was read, with a note.
    Damage(String),
    /// A record is readable but its content is wrong (a loop message that does not decode).
    Fatal(anyhow::Error),
}
use Stop::{Damage, Fatal};

/// State of one pass over a file by [`walk_mcap`].
struct Walk<'a, 'f> {
    source: &'a str,
    /// Bound of a chunk's decompressed size [bytes].
    inflate_limit: usize,
    /// Channel id -> (topic, is the loop topic, protobuf encoding).
    channels: HashMap<u16, (String, bool, bool)>,
    run: McapRun,
    data_end: bool,
    other_topics: BTreeMap<String, u64>,
    count: usize,
    last_time_s: Option<f64>,
    /// Decompression buffer, reused across chunks.
    inflated: Vec<u8>,
    on_loop: &'f mut dyn FnMut(&LoopMsg),
}

/// Reads the records of a whole file `bytes` in place (no copy, no allocation per message):
/// channels, metadata, and every `/servo/loop` message, decoded and passed to `on_loop`. A file
/// cut short or damaged keeps what was read before the damage, with a note measuring what was
/// lost; a message that is not a servo loop message is an error.
fn walk_mcap(
    bytes: &[u8],
    source: &str,
    on_loop: &mut dyn FnMut(&LoopMsg),
) -> anyhow::Result<McapRun> {
    if bytes.len() < mcap::MAGIC.len() || &bytes[..mcap::MAGIC.len()] != mcap::MAGIC {
        bail!("{source}: not an MCAP file (bad magic bytes at the start)");
    }
    let mut w = Walk {
        source,
        inflate_limit: bytes.len().saturating_mul(MAX_INFLATION),
        channels: HashMap::new(),
        run: McapRun::default(),
        data_end: false,
        other_topics: BTreeMap::new(),
        count: 0,
        last_time_s: None,
        inflated: Vec::new(),
        on_loop,
    };
    let body = &bytes[mcap::MAGIC.len()..];
    match w.records(body, 0, mcap::MAGIC.len()) {
        Ok(()) => {}
        Err(Fatal(e)) => return Err(e),
        Err(Damage(_)) if w.data_end => {}
        Err(Damage(e)) => {
            let upto = w
                .last_time_s
                .map(|t| format!("{t} s"))
                .unwrap_or_else(|| "the start".into());
            let start_ns = w
                .run
                .metadata
                .get(super::mcap_write::START_TIME_KEY)
                .and_then(|v| v.parse::<u64>().ok())
                .unwrap_or(0);
            // Measured, not assumed: the chunk headers left in the file say up to which log time
            // messages were written.
            let lost = match (last_chunk_end_ns(bytes), w.last_time_s) {
                (Some(end_ns), Some(t)) => {
                    let end_s = end_ns.saturating_sub(start_ns) as f64 * 1e-9;
                    if end_s > t {
                        format!(
                            "the damaged part held samples up to {end_s} s: {:.3} s of the run are lost",
                            end_s - t
                        )
                    } else {
                        "no whole chunk after it is lost".into()
                    }
                }
                _ => "how much is lost cannot be told from the file".into(),
            };
            w.run.notes.push(format!(
                "{source}: the log is truncated or damaged ({e}); read {} samples up to {upto}; {lost}",
                w.count
            ));
        }
    }
    let mut run = w.run;
    if !run.finished && run.notes.is_empty() {
        let t = w.last_time_s.unwrap_or(0.0);
        let planned = run
            .metadata
            .get(super::meta_keys::DURATION_S)
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|d| *d > t);
        run.notes.push(format!(
            "{source}: the log was not finished (run killed?); read {} samples up to {t} s{}",
            w.count,
            match planned {
                Some(d) => format!(
                    "; the run was planned for {d} s: samples after the last flush were never written (up to {:.3} s if it ran on)",
                    d - t
                ),
                None => String::new(),
            }
        ));
    }
    if w.count == 0 {
        let others: Vec<String> = w
            .other_topics
            .iter()
            .map(|(t, n)| format!("{t} ({n})"))
            .collect();
        bail!(
            "{source}: no {LOOP_TOPIC} messages{}{}",
            if others.is_empty() {
                String::new()
            } else {
                format!("; topics found: {}", others.join(", "))
            },
            run.notes
                .first()
                .map(|n| format!("; {n}"))
                .unwrap_or_default()
        );
    }
    Ok(run)
}
fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut x = [0u8; 8];
    x.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(x)
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    let mut x = [0u8; 4];
    x.copy_from_slice(&b[at..at + 4]);
    u32::from_le_bytes(x)
}

const OP_HEADER: u8 = 0x01;
const OP_FOOTER: u8 = 0x02;
const OP_CHANNEL: u8 = 0x04;
const OP_MESSAGE: u8 = 0x05;
const OP_CHUNK: u8 = 0x06;
const OP_METADATA: u8 = 0x0C;
const OP_DATA_END: u8 = 0x0F;

impl Walk<'_, '_> {
    /// The records of `buf` (top level at `depth` 0, a chunk's records at 1); `offset` is the
    /// position of `buf` in the file, for messages.
    fn records(&mut self, buf: &[u8], depth: u8, offset: usize) -> Result<(), Stop> {
        let mut pos = 0usize;
        while pos < buf.len() {
            let at = offset + pos;
            if buf.len() - pos < 9 {
                return Err(Damage(format!(
                    "record header at byte {at} cut short ({} bytes left)",
                    buf.len() - pos
                )));
            }
            let op = buf[pos];
            let len = u64_at(buf, pos + 1);
            let start = pos + 9;
            let avail = buf.len() - start;
            let len = match usize::try_from(len) {
                Ok(l) if l <= avail => l,
                _ => {
                    return Err(Damage(format!(
                        "record 0x{op:02X} at byte {at} declares {len} bytes, only {avail} follow"
                    )))
                }
            };
            let body = &buf[start..start + len];
            pos = start + len;
            match op {
                OP_MESSAGE => self.message(body, at)?,
                OP_CHUNK if depth == 0 => self.chunk(body, at)?,
                OP_HEADER | OP_CHANNEL | OP_METADATA | OP_FOOTER | OP_DATA_END => {
                    let rec = parse_record_checked(op, body).map_err(|e| {
                        Damage(format!("unreadable record 0x{op:02X} at byte {at}: {e}"))
                    })?;
                    match rec {
                        McapRecord::Channel(c) => {
                            let is_loop = c.topic == LOOP_TOPIC;
                            let pb = c.message_encoding == "protobuf";
                            self.channels.insert(c.id, (c.topic, is_loop, pb));
                        }
                        McapRecord::Metadata(m) if m.name == RUN_METADATA => {
                            self.run.metadata = m.metadata
                        }
                        McapRecord::Metadata(m) if m.name == SUMMARY_METADATA => {
                            self.run.summary = m.metadata
                        }
                        McapRecord::Metadata(m) if m.name == RECOVERY_METADATA => {
                            self.run.notes.push(recovery_note(self.source, &m.metadata))
                        }
                        McapRecord::DataEnd(_) => self.data_end = true,
                        McapRecord::Footer(_) => {
                            self.run.finished = true;
                            // The end magic follows; nothing after the footer is read.
                            return Ok(());
                        }
                        _ => {}
                    }
                }
                // Schemas, indexes, statistics, attachments: not needed to read the run.
                _ => {}
            }
        }
        Ok(())
    }

    /// One message record (channel id u16, sequence u32, log and publish times u64, data).
    fn message(&mut self, body: &[u8], at: usize) -> Result<(), Stop> {
        if self.data_end {
            return Ok(());
        }
        if body.len() < 22 {
            return Err(Damage(format!(
                "message record at byte {at} of {} bytes, shorter than its 22-byte header",
                body.len()
            )));
        }
        let channel = u16::from_le_bytes([body[0], body[1]]);
        let data = &body[22..];
        match self.channels.get(&channel) {
            Some((_, true, pb)) => {
                let m = if *pb {
                    LoopMsg::from_protobuf(data)
                } else {
                    serde_json::from_slice(data).map_err(|e| e.to_string())
                }
                .map_err(|e| {
                    Fatal(anyhow!(
                        "{}: message {} on {LOOP_TOPIC} ({}) is not a servo loop message: {e}",
                        self.source,
                        u32_at(body, 2),
                        if *pb { "protobuf" } else { "json" }
                    ))
                })?;
                self.count += 1;
                self.last_time_s = Some(m.time_s);
                (self.on_loop)(&m);
            }
            Some((topic, false, _)) => {
                if let Some(n) = self.other_topics.get_mut(topic) {
                    *n += 1;
                } else {
                    self.other_topics.insert(topic.clone(), 1);
                }
            }
            None => *self.other_topics.entry(String::new()).or_default() += 1,
        }
        Ok(())
    }

    /// One chunk: message_start_time u64, message_end_time u64, uncompressed_size u64,
    /// uncompressed_crc u32, compression (u32 length + string), records (u64 length + bytes).
    /// The records are decompressed whole into a reused buffer that grows with the output
    /// actually produced (never beyond the declared size, itself bounded by
    /// [`MAX_INFLATION`] x the file), and their CRC is checked.
    fn chunk(&mut self, body: &[u8], at: usize) -> Result<(), Stop> {
        let cut = || Damage(format!("chunk at byte {at}: header cut short"));
        if body.len() < 32 {
            return Err(cut());
        }
        let declared = u64_at(body, 16);
        let crc = u32_at(body, 24);
        let clen = u32_at(body, 28) as usize;
        let comp_end = 32usize.checked_add(clen).filter(|e| *e + 8 <= body.len());
        let Some(comp_end) = comp_end else {
            return Err(cut());
        };
        let compression = &body[32..comp_end];
        let rlen = u64_at(body, comp_end);
        let records = &body[comp_end + 8..];
        if rlen != records.len() as u64 {
            return Err(Damage(format!(
                "chunk at byte {at}: its records declare {rlen} bytes, the chunk holds {}",
                records.len()
            )));
        }
        let declared = match usize::try_from(declared) {
            Ok(d) if d <= self.inflate_limit => d,
            _ => {
                return Err(Damage(format!(
                    "chunk at byte {at} declares {declared} bytes uncompressed, more than {MAX_INFLATION} times the file's size"
                )))
            }
        };
        let inflate = |e: String| Damage(format!("chunk at byte {at}: {e}"));
        let mut inflated = std::mem::take(&mut self.inflated);
        inflated.clear();
        let data: &[u8] = match compression {
            b"" => records,
            b"zstd" => {
                let d = zstd::stream::read::Decoder::with_buffer(records)
                    .map_err(|e| inflate(format!("zstd: {e}")))?;
                inflate_into(d, declared, records.len(), &mut inflated).map_err(inflate)?;
                &inflated
            }
            b"lz4" => {
                let d = lz4::Decoder::new(records).map_err(|e| inflate(format!("lz4: {e}")))?;
                inflate_into(d, declared, records.len(), &mut inflated).map_err(inflate)?;
                &inflated
            }
            other => {
                return Err(inflate(format!(
                    "unsupported compression `{}`",
                    String::from_utf8_lossy(other)
                )))
            }
        };
        if data.len() != declared {
            return Err(inflate(format!(
                "{} bytes of records where the header declares {declared}",
                data.len()
            )));
        }
        if crc != 0 && crc32fast::hash(data) != crc {
            return Err(inflate("records fail their CRC check".into()));
        }
        let r = self.records(data, 1, at);
        self.inflated = inflated;
        r
    }
}

/// Decompresses `reader` into `out` (cleared): at most `declared` bytes (more is an error); the
/// buffer starts at a few times the compressed size and grows with the output.
fn inflate_into(
    reader: impl std::io::Read,
    declared: usize,
    compressed: usize,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    use std::io::Read;
    out.reserve(declared.min(compressed.saturating_mul(4).saturating_add(4096)));
    let n = reader
        .take(declared as u64 + 1)
        .read_to_end(out)
        .map_err(|e| format!("cannot decompress: {e}"))?;
    if n > declared {
        return Err(format!(
            "decompresses to more than the {declared} bytes its header declares"
        ));
    }
    Ok(())
}

/// The latest `message_end_time` [ns] of the chunk headers found walking the top-level records
/// of `bytes` (a chunk cut short counts when its header is whole); no allocation.
pub fn last_chunk_end_ns(bytes: &[u8]) -> Option<u64> {
    let mut pos = mcap::MAGIC.len();
    let mut end: Option<u64> = None;
    let u64_at = |at: usize| {
        let mut x = [0u8; 8];
        x.copy_from_slice(&bytes[at..at + 8]);
        u64::from_le_bytes(x)
    };
    while bytes.len().saturating_sub(pos) >= 9 {
        let op = bytes[pos];
        let len = u64_at(pos + 1);
        let body = pos + 9;
        if op == 0x06 && bytes.len().saturating_sub(body) >= 16 {
            let e = u64_at(body + 8);
            end = Some(end.map_or(e, |x| x.max(e)));
        }
        match usize::try_from(len).ok().and_then(|l| body.checked_add(l)) {
            Some(next) if next <= bytes.len() => pos = next,
            _ => break,
        }
    }
    end
}

/// The [`Record`] of a sequence of loop messages (a signal only when some sample has it).
pub fn record_of(msgs: &[LoopMsg], source: &str) -> Record {
    let col = |f: fn(&LoopMsg) -> f64| {
        let v: Vec<f64> = msgs.iter().map(f).collect();
        v.iter().any(|x| x.is_finite()).then_some(v)
    };
    Record {
        source: source.to_string(),
        time_s: msgs.iter().map(|m| m.time_s).collect(),
        u_v: col(|m| m.u_v),
        theta_l_rad: col(|m| m.theta_l_rad),
        omega_l_rad_s: col(|m| m.omega_l_rad_s),
        i_a_a: col(|m| m.i_a_a),
        ref_rad: col(|m| m.ref_rad),
        i_ref_a: col(|m| m.i_ref_a),
        duty: col(|m| m.duty),
        ..Record::default()
    }
}

/// Loop messages for a [`Record`] (e.g. a CSV converted to MCAP): signals the record lacks are
/// null; controller terms are null (unknown).
pub fn loop_msgs_of(rec: &Record) -> Vec<LoopMsg> {
    let get = |v: &Option<Vec<f64>>, k: usize| v.as_ref().map_or(f64::NAN, |v| v[k]);
    (0..rec.len())
        .map(|k| {
            let r = get(&rec.ref_rad, k);
            let y = get(&rec.theta_l_rad, k);
            LoopMsg {
                time_s: rec.time_s[k],
                ref_rad: r,
                theta_l_rad: y,
                omega_l_rad_s: get(&rec.omega_l_rad_s, k),
                err_rad: r - y,
                u_v: get(&rec.u_v, k),
                ff_v: f64::NAN,
                p_v: f64::NAN,
                i_v: f64::NAN,
                d_v: f64::NAN,
                i_a_a: get(&rec.i_a_a, k),
                saturated: false,
                ref_omega_l_rad_s: f64::NAN,
                i_ref_a: get(&rec.i_ref_a, k),
                duty: get(&rec.duty, k),
            }
        })
        .collect()
}

/// Name of the metadata record a recovery of an unfinished log adds to its output:
/// `recovered_from` (the input file), `read_bytes` (`N of M`), `stopped_because`, and `note_1`,
/// `note_2`, ... (what servo's reader said of the input: the run was killed, what was lost).
/// Servo's reader turns it into a note on the recovered log.
pub const RECOVERY_METADATA: &str = "servo_recovery";

/// The note servo's reader gives on a recovered log, from its [`RECOVERY_METADATA`] record.
pub fn recovery_note(source: &str, m: &std::collections::BTreeMap<String, String>) -> String {
    let from = m
        .get("recovered_from")
        .map_or("an unfinished log", String::as_str);
    let mut note = format!("{source}: recovered by `servo log recover` from {from}");
    if let Some(r) = m.get("read_bytes") {
        note.push_str(&format!(" (read {r} bytes"));
        if let Some(w) = m.get("stopped_because") {
            note.push_str(&format!("; stopped: {w}"));
        }
        note.push(')');
    }
    for k in 1.. {
        match m.get(&format!("note_{k}")) {
            Some(n) => note.push_str(&format!("; {n}")),
            None => break,
        }
    }
    note
}

#[cfg(test)]
mod tests {
    use super::super::mcap_write::{McapLog, McapLogOptions};
    use super::*;

    use crate::loop_msg::test_msg as msg;

    fn write(path: &Path, n: usize, finish: bool) {
        let mut meta = BTreeMap::new();
        meta.insert(
            "gains_toml".to_string(),
            "[pid]\nkp = 1.0\nki = 0.0\nkd = 0.0\n".to_string(),
        );
        let mut log = McapLog::create(
            path,
            &meta,
            McapLogOptions {
                start_unix_ns: 5,
                ..McapLogOptions::default()
            },
        )
        .unwrap();
        for k in 0..n {
            log.write_loop(&msg(k)).unwrap();
        }
        if finish {
            log.finish().unwrap();
        } else {
            log.flush().unwrap();
            std::mem::forget(log);
        }
    }

    fn same(a: &LoopMsg, b: &LoopMsg) -> bool {
        let eq = |x: f64, y: f64| x == y || (x.is_nan() && y.is_nan());
        eq(a.time_s, b.time_s)
            && eq(a.ref_rad, b.ref_rad)
            && eq(a.theta_l_rad, b.theta_l_rad)
            && eq(a.omega_l_rad_s, b.omega_l_rad_s)
            && eq(a.err_rad, b.err_rad)
            && eq(a.u_v, b.u_v)
            && eq(a.ff_v, b.ff_v)
            && eq(a.p_v, b.p_v)
            && eq(a.i_v, b.i_v)
            && eq(a.d_v, b.d_v)
            && eq(a.i_a_a, b.i_a_a)
            && eq(a.ref_omega_l_rad_s, b.ref_omega_l_rad_s)
            && eq(a.i_ref_a, b.i_ref_a)
            && eq(a.duty, b.duty)
            && a.saturated == b.saturated
    }

    #[test]
    fn round_trip_equal() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.mcap");
        write(&p, 1000, true);
        let run = read_mcap(&p).unwrap();
        assert!(run.finished && run.notes.is_empty(), "{:?}", run.notes);
        assert_eq!(run.loop_msgs.len(), 1000);
        for (k, m) in run.loop_msgs.iter().enumerate() {
            assert!(same(m, &msg(k)), "message {k}: {m:?} != {:?}", msg(k));
        }
        assert_eq!(
            run.metadata["gains_toml"],
            "[pid]\nkp = 1.0\nki = 0.0\nkd = 0.0\n"
        );
        assert_eq!(run.record.len(), 1000);
        assert_eq!(run.record.u_v.as_ref().unwrap()[10], msg(10).u_v);
        assert!(run.record.ref_rad.as_ref().unwrap()[0].is_nan());
        // Also readable by the library's strict reader (proper summary and footer).
        let bytes = std::fs::read(&p).unwrap();
        assert_eq!(mcap::MessageStream::new(&bytes).unwrap().count(), 1000);
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert_eq!(summary.stats.unwrap().message_count, 1000);
    }

    #[test]
    fn truncated_file_keeps_flushed_chunks() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.mcap");
        write(&p, 1000, true);
        let full = std::fs::read(&p).unwrap();
        // Cut anywhere: what is read is always a prefix of what was written.
        let mut last = 0;
        for cut in (200..full.len()).step_by(full.len() / 37) {
            match parse_mcap(&full[..cut], "cut") {
                Ok(run) => {
                    assert!(!run.finished);
                    assert!(!run.notes.is_empty());
                    assert!(run.loop_msgs.len() >= last);
                    last = run.loop_msgs.len();
                    for (k, m) in run.loop_msgs.iter().enumerate() {
                        assert!(same(m, &msg(k)));
                    }
                }
                Err(e) => assert!(
                    format!("{e:#}").contains("no /servo/loop messages"),
                    "{e:#}"
                ),
            }
        }
        assert!(last > 800, "{last}");
        // An unfinished (dropped without footer) log, still under its `.partial` name, reads
        // up to its last flush.
        let p2 = dir.path().join("u.mcap");
        write(&p2, 1000, false);
        assert!(!p2.exists());
        let run = read_mcap(&dir.path().join("u.mcap.partial")).unwrap();
        assert!(!run.finished);
        assert_eq!(run.loop_msgs.len(), 1000);
        assert!(run.notes[0].contains("not finished"), "{:?}", run.notes);
    }

    #[test]
    fn protobuf_log_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("pb.mcap");
        let mut log = McapLog::create(
            &p,
            &BTreeMap::new(),
            McapLogOptions {
                encoding: crate::LogEncoding::Protobuf,
                fast_compression: true,
                ..McapLogOptions::default()
            },
        )
        .unwrap();
        for k in 0..500 {
            log.write_loop(&msg(k)).unwrap();
        }
        log.finish().unwrap();
        let run = read_mcap(&p).unwrap();
        assert_eq!(run.loop_msgs.len(), 500);
        for (k, m) in run.loop_msgs.iter().enumerate() {
            assert!(same(m, &msg(k)), "message {k}");
        }
        let bytes = std::fs::read(&p).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let ch = summary.channels.values().next().unwrap();
        assert_eq!(ch.message_encoding, "protobuf");
        let schema = ch.schema.as_ref().unwrap();
        assert_eq!(
            (schema.name.as_str(), schema.encoding.as_str()),
            ("servo.Loop", "protobuf")
        );
    }

    #[test]
    fn damaged_log_measures_the_lost_span() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.mcap");
        write(&p, 1000, true);
        let mut b = std::fs::read(&p).unwrap();
        // Damage a byte inside a chunk about a third into the file: reading stops there, the
        // chunks after it are intact but not trusted; the note measures what they held.
        let mut at = b.len() / 3;
        while b[at] == 0 {
            at += 1;
        }
        b[at] ^= 0x55;
        let run = parse_mcap(&b, "d.mcap").unwrap();
        let t_last = run.loop_msgs.last().unwrap().time_s;
        let note = &run.notes[0];
        let lost: f64 = note
            .split(": ")
            .last()
            .and_then(|x| x.split(' ').next())
            .and_then(|x| x.parse().ok())
            .unwrap_or_else(|| panic!("{note}"));
        // Messages went up to 0.999 s.
        assert!((lost - (0.999 - t_last)).abs() < 1e-6, "{note}");
        assert!(lost > 0.3, "{note}");
    }

    #[test]
    fn not_mcap() {
        let e = format!("{:#}", parse_mcap(b"time_s,u_V\n", "x.mcap").unwrap_err());
        assert!(e.contains("not an MCAP file"), "{e}");
    }
}
