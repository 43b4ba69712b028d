//! MCAP recovery (`servo log recover`): salvages an unfinished MCAP log (the recorder was killed, the disk
//! filled, the machine lost power) into a finished, indexed file.
//!
//! The input is read record by record from the start (opcode u8, length u64 LE, body), chunks
//! are opened and read record by record too, until the first record that is cut short or
//! unreadable. Everything before it (schemas, channels, messages, metadata, attachments) is
//! rewritten with the original ids into a new file with a summary and footer. An uncompressed
//! chunk cut short is salvaged record by record as well; a compressed chunk cut short is lost
//! (its messages are counted as "unreadable tail bytes").

use crate::error::{self as anyhow, bail, Context};
use mcap::records::Record;
use std::collections::BTreeSet;
use std::io::BufWriter;
use std::path::Path;

/// What a recovery saved.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RecoveryReport {
    /// Messages written to the output.
    pub messages: u64,
    /// Channels (topics) that carried messages.
    pub topics: BTreeSet<String>,
    /// First and last message log time [ns].
    pub first_log_time_ns: Option<u64>,
    pub last_log_time_ns: Option<u64>,
    /// Metadata records and attachments copied.
    pub metadata: u64,
    pub attachments: u64,
    /// Bytes of the input that could be read.
    pub good_bytes: u64,
    /// Input size [bytes].
    pub total_bytes: u64,
    /// The input already had its footer (it was not broken).
    pub was_complete: bool,
    /// Why reading stopped before the end, if it did.
    pub stopped_because: Option<String>,
    /// The notes servo's reader gives on the input (the run was killed, what was lost), kept
    /// in the output's [`RECOVERY_METADATA`] record.
    pub notes: Vec<String>,
}

pub use crate::mcap_read::{recovery_note, RECOVERY_METADATA};

impl RecoveryReport {
    /// Time span of the recovered messages [s].
    pub fn span_s(&self) -> f64 {
        match (self.first_log_time_ns, self.last_log_time_ns) {
            (Some(a), Some(b)) => b.saturating_sub(a) as f64 * 1e-9,
            _ => 0.0,
        }
    }
}

const MAGIC: &[u8] = b"\x89MCAP0\r\n";
const OP_CHUNK: u8 = 0x06;

struct Sink<W: std::io::Write + std::io::Seek> {
    w: mcap::Writer<W>,
    report: RecoveryReport,
    channel_topics: std::collections::BTreeMap<u16, String>,
    /// Largest buffer a length field may ask for [bytes]: the input's size.
    limit: usize,
}

impl<W: std::io::Write + std::io::Seek> Sink<W> {
    /// Copies one complete record; returns Ok(false) at the end of the data section.
    fn record(&mut self, rec: Record<'_>, depth: u32) -> anyhow::Result<bool> {
        match rec {
            Record::Schema { header, data } => {
                self.w
                    .add_schema_with_id(header.id, &header.name, &header.encoding, &data)?;
            }
            Record::Channel(c) => {
                self.w.add_channel_with_id(
                    c.id,
                    c.schema_id,
                    &c.topic,
                    &c.message_encoding,
                    &c.metadata,
                )?;
                self.channel_topics.insert(c.id, c.topic.clone());
            }
            Record::Message { header, data } => {
                let Some(topic) = self.channel_topics.get(&header.channel_id) else {
                    bail!(
                        "message on channel {} that was never declared",
                        header.channel_id
                    );
                };
                self.report.topics.insert(topic.clone());
                self.w.write_to_known_channel(&header, &data)?;
                self.report.messages += 1;
                let t = header.log_time;
                self.report.first_log_time_ns =
                    Some(self.report.first_log_time_ns.map_or(t, |f| f.min(t)));
                self.report.last_log_time_ns =
                    Some(self.report.last_log_time_ns.map_or(t, |l| l.max(t)));
            }
            Record::Chunk { header, data } => {
                if depth > 0 {
                    bail!("chunk inside a chunk");
                }
                for inner in mcap::read::ChunkReader::new(header, &data)? {
                    self.record(inner?, depth + 1)?;
                }
            }
            Record::Metadata(m) => {
                self.w.write_metadata(&m)?;
                self.report.metadata += 1;
            }
            Record::Attachment { header, data, .. } => {
                self.w.attach(&mcap::Attachment {
                    log_time: header.log_time,
                    create_time: header.create_time,
                    name: header.name,
                    media_type: header.media_type,
                    data,
                })?;
                self.report.attachments += 1;
            }
            Record::DataEnd(_) | Record::Footer(_) => return Ok(false),
            // Indexes, statistics and summary offsets are regenerated by the writer.
            _ => {}
        }
        Ok(true)
    }
}

/// Reads `buf[pos..]` as a sequence of records; returns (bytes consumed, reason it stopped early
/// or None at a clean end, reached the data end).
fn walk<W: std::io::Write + std::io::Seek>(
    buf: &[u8],
    sink: &mut Sink<W>,
    depth: u32,
) -> (usize, Option<String>, bool) {
    let mut pos = 0usize;
    while pos < buf.len() {
        if buf.len() - pos < 9 {
            return (
                pos,
                Some(format!(
                    "record header cut short ({} bytes left)",
                    buf.len() - pos
                )),
                false,
            );
        }
        let op = buf[pos];
        let mut len_b = [0u8; 8];
        len_b.copy_from_slice(&buf[pos + 1..pos + 9]);
        let len = u64::from_le_bytes(len_b);
        let body_start = pos + 9;
        let avail = (buf.len() - body_start) as u64;
        if len > avail {
            if op == OP_CHUNK && depth == 0 {
                let (n, why) = partial_chunk(&buf[body_start..], sink);
                let why = why.unwrap_or_else(|| format!("chunk of {len} bytes cut short"));
                return (body_start + n, Some(why), false);
            }
            return (
                pos,
                Some(format!(
                    "record 0x{op:02X} of {len} bytes cut short after {avail} bytes"
                )),
                false,
            );
        }
        let body = &buf[body_start..body_start + len as usize];
        if op == OP_CHUNK && depth == 0 {
            // Chunks are read record by record through the streaming reader, whose buffers are
            // bounded by the input's size: a corrupted `uncompressed_size` cannot make it
            // allocate more than that.
            if let Err(e) = chunk_records(&buf[pos..body_start + len as usize], sink) {
                return (pos, Some(format!("chunk: {e:#}")), false);
            }
            pos = body_start + len as usize;
            continue;
        }
        let rec = match crate::mcap_read::parse_record_checked(op, body) {
            Ok(r) => r,
            Err(e) => {
                return (
                    pos,
                    Some(format!("unreadable record 0x{op:02X}: {e}")),
                    false,
                )
            }
        };
        match sink.record(rec, depth) {
            Ok(true) => {}
            Ok(false) => return (body_start + len as usize, None, true),
            Err(e) => return (pos, Some(format!("record 0x{op:02X}: {e:#}")), false),
        }
        pos = body_start + len as usize;
    }
    (pos, None, false)
}

/// Copies the records of one whole chunk record (`chunk`: opcode, length and body) to `sink`,
/// decompressing incrementally with every buffer bounded by [`Sink::limit`].
fn chunk_records<W: std::io::Write + std::io::Seek>(
    chunk: &[u8],
    sink: &mut Sink<W>,
) -> anyhow::Result<()> {
    for rec in crate::mcap_read::BoundedRecords::new(chunk, false, sink.limit) {
        sink.record(rec?, 1)?;
    }
    Ok(())
}

/// Salvages the records of an uncompressed chunk that was cut short; returns (bytes of the
/// chunk body consumed, reason).
fn partial_chunk<W: std::io::Write + std::io::Seek>(
    body: &[u8],
    sink: &mut Sink<W>,
) -> (usize, Option<String>) {
    // message_start_time u64, message_end_time u64, uncompressed_size u64, uncompressed_crc u32,
    // compression string (u32 length + bytes), records length u64, records.
    let fixed = 8 + 8 + 8 + 4;
    if body.len() < fixed + 4 {
        return (0, Some("chunk header cut short".into()));
    }
    let mut l = [0u8; 4];
    l.copy_from_slice(&body[fixed..fixed + 4]);
    let clen = u32::from_le_bytes(l) as usize;
    let recs_at = fixed + 4 + clen + 8;
    if body.len() < recs_at {
        return (0, Some("chunk header cut short".into()));
    }
    let compression = String::from_utf8_lossy(&body[fixed + 4..fixed + 4 + clen]).into_owned();
    if !compression.is_empty() {
        return (
            0,
            Some(format!(
                "last chunk ({compression}-compressed, {} bytes) cut short: its messages are lost",
                body.len()
            )),
        );
    }
    let (n, why, _) = walk(&body[recs_at..], sink, 1);
    let why = why.map(|w| format!("inside the last (uncompressed, cut short) chunk: {w}"));
    (
        recs_at + n,
        why.or_else(|| Some("last chunk cut short after a whole record".into())),
    )
}

/// Recovers `input` into `output`.
pub fn recover(input: &Path, output: &Path) -> anyhow::Result<RecoveryReport> {
    let buf = std::fs::read(input).with_context(|| format!("reading {}", input.display()))?;
    // Atomically ([`crate::output`]): a failed recovery leaves no half-written output.
    let (rep, file) = crate::output::Replacement::begin(output)?;
    let mut w = BufWriter::new(file);
    let unchanged = crate::output::unchanged_sentence(output);
    let report = recover_noting(&buf, &mut w, &input.display().to_string()).with_context(|| {
        format!(
            "recovering {} into {} ({unchanged})",
            input.display(),
            output.display()
        )
    })?;
    let file = w
        .into_inner()
        .map_err(|e| crate::Error::Io(e.into_error()))
        .and_then(|f| rep.commit(f))
        .with_context(|| format!("writing {} ({unchanged})", output.display()))?;
    if let Some(n) = file.backup_note() {
        eprintln!("note: {n}");
    }
    Ok(report)
}

/// [`recover_bytes`] that keeps, in a [`RECOVERY_METADATA`] record of the output, where the
/// log came from (`source`, the input's name) and the notes servo's reader gives on it.
pub fn recover_noting<W: std::io::Write + std::io::Seek>(
    buf: &[u8],
    out: W,
    source: &str,
) -> anyhow::Result<RecoveryReport> {
    let notes = crate::mcap_read::notes_of(buf, source);
    recover_inner(buf, out, Some((source, notes)))
}

/// Recovers the MCAP bytes `buf` into `out` (a file, or a `Cursor<Vec<u8>>` in tests).
///
/// Never panics and allocates nothing sized by the input's length fields beyond the input's
/// own size (records longer than the rest of the input are "cut short"; chunks decompress
/// record by record).
pub fn recover_bytes<W: std::io::Write + std::io::Seek>(
    buf: &[u8],
    out: W,
) -> anyhow::Result<RecoveryReport> {
    recover_inner(buf, out, None)
}

fn recover_inner<W: std::io::Write + std::io::Seek>(
    buf: &[u8],
    out: W,
    noting: Option<(&str, Vec<String>)>,
) -> anyhow::Result<RecoveryReport> {
    if buf.len() < MAGIC.len() || &buf[..MAGIC.len()] != MAGIC {
        bail!("not an MCAP file (no MCAP magic at its start)");
    }
    let w = mcap::WriteOptions::new()
        .library(concat!("servo log recover ", env!("CARGO_PKG_VERSION")))
        .create(out)
        .context("writing the recovered file")?;
    let mut sink = Sink {
        w,
        report: RecoveryReport::default(),
        channel_topics: Default::default(),
        limit: buf.len(),
    };
    let (n, why, data_end) = walk(&buf[MAGIC.len()..], &mut sink, 0);
    sink.report.total_bytes = buf.len() as u64;
    sink.report.good_bytes = (MAGIC.len() + n) as u64;
    sink.report.was_complete = data_end && buf.ends_with(MAGIC) && buf.len() > 2 * MAGIC.len();
    sink.report.stopped_because = why;
    if let (Some((source, notes)), false) = (noting, sink.report.was_complete) {
        let mut m = std::collections::BTreeMap::new();
        m.insert("recovered_from".to_string(), source.to_string());
        m.insert(
            "read_bytes".to_string(),
            format!("{} of {}", sink.report.good_bytes, sink.report.total_bytes),
        );
        if let Some(w) = &sink.report.stopped_because {
            m.insert("stopped_because".to_string(), w.clone());
        }
        for (k, n) in notes.iter().enumerate() {
            m.insert(format!("note_{}", k + 1), n.clone());
        }
        sink.w
            .write_metadata(&mcap::records::Metadata {
                name: RECOVERY_METADATA.to_string(),
                metadata: m,
            })
            .context("writing the recovery's metadata")?;
        sink.report.notes = notes;
    }
    sink.w.finish().context("finishing the recovered file")?;
    Ok(sink.report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    fn write_log(path: &Path, n: u64, opts: mcap::WriteOptions) -> Vec<u8> {
        let f = std::fs::File::create(path).unwrap();
        let mut w = opts.create(BufWriter::new(f)).unwrap();
        let schema = w.add_schema("servo.Sample", "jsonschema", b"{}").unwrap();
        let ch = w
            .add_channel(schema, "/sample", "json", &BTreeMap::new())
            .unwrap();
        for i in 0..n {
            let data = format!("{{\"k\":{i}}}");
            let h = mcap::records::MessageHeader {
                channel_id: ch,
                sequence: i as u32,
                log_time: i * 1_000_000,
                publish_time: i * 1_000_000,
            };
            w.write_to_known_channel(&h, data.as_bytes()).unwrap();
        }
        w.finish().unwrap();
        drop(w);
        std::fs::read(path).unwrap()
    }

    fn count(path: &Path) -> usize {
        let b = std::fs::read(path).unwrap();
        let msgs: Result<Vec<_>, _> = mcap::MessageStream::new(&b).unwrap().collect();
        msgs.unwrap().len()
    }

    #[test]
    fn recovers_truncated_uncompressed_and_compressed_logs() {
        let dir = tempfile::tempdir().unwrap();
        let full = dir.path().join("full.mcap");
        // Small uncompressed chunks: a cut loses at most the record it cuts.
        let bytes = write_log(
            &full,
            1000,
            mcap::WriteOptions::new()
                .compression(None)
                .chunk_size(Some(4096)),
        );
        let broken = dir.path().join("broken.mcap");
        let fixed = dir.path().join("fixed.mcap");
        let cut = bytes.len() * 6 / 10;
        std::fs::write(&broken, &bytes[..cut]).unwrap();
        let r = recover(&broken, &fixed).unwrap();
        assert!(r.messages > 400 && r.messages < 1000, "{r:?}");
        assert!(r.stopped_because.is_some());
        assert_eq!(count(&fixed), r.messages as usize);
        assert!((r.span_s() - (r.messages - 1) as f64 * 1e-3).abs() < 1e-9);
        // The salvaged messages are exactly the first ones.
        let b = std::fs::read(&fixed).unwrap();
        for (i, m) in mcap::MessageStream::new(&b).unwrap().enumerate() {
            assert_eq!(m.unwrap().sequence as usize, i);
        }
        // A complete file passes through whole.
        let r = recover(&full, &fixed).unwrap();
        assert_eq!(r.messages, 1000);
        assert!(r.was_complete);
        // zstd chunks: whole chunks before the cut survive.
        let zfull = dir.path().join("z.mcap");
        let zb = write_log(
            &zfull,
            1000,
            mcap::WriteOptions::new().chunk_size(Some(2048)),
        );
        std::fs::write(&broken, &zb[..zb.len() * 7 / 10]).unwrap();
        let r = recover(&broken, &fixed).unwrap();
        assert!(r.messages > 0 && r.messages < 1000, "{r:?}");
        assert_eq!(count(&fixed), r.messages as usize);
        // Not an MCAP.
        std::fs::write(&broken, b"hello").unwrap();
        assert!(recover(&broken, &fixed).is_err());
    }
}
