//! ROS 2 bags (rosbag2, MCAP storage): the bag's folder (with `metadata.yaml`) or its `.mcap`,
//! its CDR messages decoded into named series, and the log reader.
//!
//! Decoded messages: `sensor_msgs/msg/JointState` (the header stamp, and per joint named in
//! `name[]` its `position`, `velocity`, `effort`: the series `/TOPIC/JOINT/position`, as
//! PlotJuggler names them), and the `std_msgs/msg` scalars (`Float64`, `Float32`, the integers,
//! `Bool`: the series `/TOPIC/data`). A message's time is its header stamp where it has one
//! (nonzero), else the bag's log time. Other message types are listed by `servo inspect` and
//! not read.
//!
//! CDR (OMG DDS-XTypes, the classic plain encoding rosbag2 writes): a 4-byte encapsulation
//! header (`00 01` little-endian, `00 00` big-endian), then the fields, each aligned to its own
//! size from the end of that header; a string is a u32 length (with the terminating NUL) and
//! its bytes, a sequence a u32 count and its elements. Every count and length is checked
//! against the bytes left: a damaged message is an error naming the topic and the message,
//! never a panic or an allocation beyond the message's size.

use crate::error::{self as anyhow, anyhow, bail, Context};
use crate::series::{self, Series};
use crate::units::Signal;
use mcap::records::Record as McapRecord;
use servo_core::record::Record;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// An example `--columns` value for a ROS 2 bag.
pub const EXAMPLE: &str = "theta_l=/joint_states/arm/position:rad,u=/cmd_voltage/data:V";

/// A CDR reader over one message's bytes.
pub struct Cdr<'a> {
    b: &'a [u8],
    at: usize,
    little: bool,
}

impl<'a> Cdr<'a> {
    /// After the encapsulation header; an error for an encoding other than plain CDR.
    pub fn new(b: &'a [u8]) -> Result<Cdr<'a>, String> {
        if b.len() < 4 {
            return Err(format!("{} bytes: shorter than the CDR header", b.len()));
        }
        let little = match (b[0], b[1]) {
            (0, 1) => true,
            (0, 0) => false,
            (x, y) => {
                return Err(format!(
                    "CDR encapsulation {x:02x} {y:02x}; servo reads plain CDR (00 00, 00 01)"
                ))
            }
        };
        Ok(Cdr { b, at: 4, little })
    }
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        let left = self.b.len() - self.at;
        if n > left {
            return Err(format!("{what}: needs {n} bytes, {left} remain"));
        }
        let s = &self.b[self.at..self.at + n];
        self.at += n;
        Ok(s)
    }
    fn align(&mut self, n: usize) -> Result<(), String> {
        let pad = (n - (self.at - 4) % n) % n;
        self.take(pad, "padding").map(|_| ())
    }
    fn uint(&mut self, n: usize, what: &str) -> Result<u64, String> {
        self.align(n)?;
        let s = self.take(n, what)?;
        let it: Box<dyn Iterator<Item = &u8>> = if self.little {
            Box::new(s.iter().rev())
        } else {
            Box::new(s.iter())
        };
        Ok(it.fold(0u64, |a, &x| (a << 8) | u64::from(x)))
    }
    /// A u32.
    pub fn u32(&mut self, what: &str) -> Result<u32, String> {
        Ok(self.uint(4, what)? as u32)
    }
    /// A float64.
    pub fn f64(&mut self, what: &str) -> Result<f64, String> {
        Ok(f64::from_bits(self.uint(8, what)?))
    }
    /// A string (u32 length with the NUL, bytes).
    pub fn string(&mut self, what: &str) -> Result<String, String> {
        let n = self.u32(what)? as usize;
        let s = self.take(n, what)?;
        let s = s.strip_suffix(&[0]).unwrap_or(s);
        Ok(String::from_utf8_lossy(s).into_owned())
    }
    /// A sequence count, checked against the bytes left (`each` bytes per element at least).
    pub fn count(&mut self, each: usize, what: &str) -> Result<usize, String> {
        let n = self.u32(what)? as usize;
        let left = self.b.len() - self.at;
        if n.saturating_mul(each.max(1)) > left {
            return Err(format!(
                "{what}: {n} elements declared, {left} bytes remain"
            ));
        }
        Ok(n)
    }
    /// A float64 sequence.
    pub fn f64s(&mut self, what: &str) -> Result<Vec<f64>, String> {
        let n = self.count(8, what)?;
        (0..n).map(|_| self.f64(what)).collect()
    }
    /// One std_msgs scalar of the type `name` (`Float64`, `Int32`, `Bool`, ...) as f64.
    pub fn scalar(&mut self, name: &str) -> Result<Option<f64>, String> {
        let w = "data";
        Ok(Some(match name {
            "Float64" => self.f64(w)?,
            "Float32" => f64::from(f32::from_bits(self.uint(4, w)? as u32)),
            "Int8" => f64::from(self.uint(1, w)? as u8 as i8),
            "Int16" => f64::from(self.uint(2, w)? as u16 as i16),
            "Int32" => f64::from(self.uint(4, w)? as u32 as i32),
            "Int64" => self.uint(8, w)? as i64 as f64,
            "UInt8" | "Byte" | "Char" | "Bool" => self.uint(1, w)? as f64,
            "UInt16" => self.uint(2, w)? as f64,
            "UInt32" => self.uint(4, w)? as f64,
            "UInt64" => self.uint(8, w)? as f64,
            _ => return Ok(None),
        }))
    }
}

/// One joint of a JointState: its name and its position, velocity and effort.
pub type Joint = (String, [f64; 3]);

/// A decoded JointState: the header stamp [ns] (None when zero) and per joint its position,
/// velocity and effort (NaN where the array is shorter).
pub fn joint_state(b: &[u8]) -> Result<(Option<i64>, Vec<Joint>), String> {
    let mut c = Cdr::new(b)?;
    let sec = c.u32("header.stamp.sec")? as i32;
    let nsec = c.u32("header.stamp.nanosec")?;
    c.string("header.frame_id")?;
    let n = c.count(4, "name")?;
    let names: Vec<String> = (0..n).map(|_| c.string("name")).collect::<Result<_, _>>()?;
    let arrays = [c.f64s("position")?, c.f64s("velocity")?, c.f64s("effort")?];
    let stamp = (sec != 0 || nsec != 0).then(|| i64::from(sec) * 1_000_000_000 + i64::from(nsec));
    let joints = names
        .into_iter()
        .enumerate()
        .map(|(k, name)| {
            let v = [0, 1, 2].map(|a| arrays[a].get(k).copied().unwrap_or(f64::NAN));
            (name, v)
        })
        .collect();
    Ok((stamp, joints))
}

/// A topic of the bag.
#[derive(Debug, Clone, Default)]
pub struct Topic {
    pub name: String,
    /// The ROS type (`sensor_msgs/msg/JointState`).
    pub type_name: String,
    pub messages: usize,
    /// Joint names of a JointState topic, in order of appearance.
    pub joints: Vec<String>,
    /// Messages' times [s].
    pub t_s: Vec<f64>,
}

/// A decoded bag: its topics and the series of the decoded messages.
#[derive(Debug, Clone, Default)]
pub struct Bag {
    pub topics: Vec<Topic>,
    pub series: Vec<Series>,
    /// The first message's log time [ns]: times are counted from it.
    pub base_ns: Option<i64>,
}

const JOINT_STATE: &str = "sensor_msgs/msg/JointState";
const FIELDS: [&str; 3] = ["position", "velocity", "effort"];

/// The `.mcap` files of a bag: the folder's (sorted) for a folder or its `metadata.yaml`, else
/// the file itself.
pub fn bag_files(path: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let dir = if path.is_dir() {
        Some(path.to_path_buf())
    } else if path.file_name().is_some_and(|n| n == "metadata.yaml") {
        path.parent().map(Path::to_path_buf)
    } else {
        None
    };
    let Some(dir) = dir else {
        return Ok(vec![path.to_path_buf()]);
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .with_context(|| format!("reading the bag folder {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| crate::log_reader::extension(p) == "mcap")
        .collect();
    files.sort();
    if files.is_empty() {
        bail!(
            "{}: a rosbag2 folder without .mcap files (servo reads bags with MCAP storage; \
             convert a sqlite3 bag with `ros2 bag convert`)",
            dir.display()
        );
    }
    Ok(files)
}

/// Whether MCAP bytes are a ROS 2 bag: the header's profile `ros2`, or a channel in CDR.
pub fn is_ros2(bytes: &[u8]) -> bool {
    let limit = bytes.len();
    for r in crate::mcap_read::BoundedRecords::new(bytes, true, limit).take(64) {
        match r {
            Ok(McapRecord::Header(h)) if h.profile == "ros2" => return true,
            Ok(McapRecord::Channel(c)) => return c.message_encoding == "cdr",
            Ok(_) => {}
            Err(_) => return false,
        }
    }
    false
}

/// The first 64 KiB of `path` (its header, schema and channel records).
fn prefix(path: &Path) -> anyhow::Result<Vec<u8>> {
    use std::io::Read;
    let mut b = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(1 << 16).read_to_end(&mut b))
        .with_context(|| format!("reading {}", path.display()))?;
    Ok(b)
}

/// Decodes the messages of one bag file into `bag`.
pub fn decode_into(bag: &mut Bag, bytes: &[u8], source: &str) -> anyhow::Result<()> {
    let mut schemas: BTreeMap<u16, String> = BTreeMap::new();
    // channel id -> index into bag.topics
    let mut channels: BTreeMap<u16, usize> = BTreeMap::new();
    let mut index: BTreeMap<String, usize> = bag
        .series
        .iter()
        .enumerate()
        .map(|(k, s)| (s.name.clone(), k))
        .collect();
    let mut push = |bag: &mut Bag, name: String, t: f64, v: f64| {
        let k = *index.entry(name.clone()).or_insert_with(|| {
            bag.series.push(Series {
                name,
                ..Series::default()
            });
            bag.series.len() - 1
        });
        bag.series[k].t_s.push(t);
        bag.series[k].v.push(v);
    };
    for r in crate::mcap_read::BoundedRecords::new(bytes, true, bytes.len()) {
        let r = r.map_err(|e| anyhow!("{source}: damaged MCAP: {e}"))?;
        match r {
            McapRecord::Schema { header, .. } => {
                schemas.insert(header.id, header.name);
            }
            McapRecord::Channel(c) => {
                if channels.contains_key(&c.id) {
                    continue;
                }
                let type_name = schemas.get(&c.schema_id).cloned().unwrap_or_default();
                let k = match bag.topics.iter().position(|t| t.name == c.topic) {
                    Some(k) => k,
                    None => {
                        bag.topics.push(Topic {
                            name: c.topic.clone(),
                            type_name,
                            ..Topic::default()
                        });
                        bag.topics.len() - 1
                    }
                };
                channels.insert(c.id, k);
            }
            McapRecord::Message { header, data } => {
                let Some(&k) = channels.get(&header.channel_id) else {
                    continue;
                };
                // Times in integer ns from the bag's first message (an epoch time in f64
                // seconds would keep only 0.2 us).
                let base = *bag.base_ns.get_or_insert(header.log_time as i64);
                let secs = |ns: i64| ns.wrapping_sub(base) as f64 * 1e-9;
                let log_t = secs(header.log_time as i64);
                let topic = &bag.topics[k];
                let (name, ty) = (topic.name.clone(), topic.type_name.clone());
                let at = topic.messages;
                let err = |e: String| anyhow!("{source}: topic {name}, message {at}: {e}");
                let t = if ty == JOINT_STATE {
                    let (stamp, joints) = joint_state(&data).map_err(err)?;
                    let t = stamp.map_or(log_t, secs);
                    for (j, vals) in joints {
                        for (f, v) in FIELDS.iter().zip(vals) {
                            if v.is_finite() {
                                push(bag, format!("{name}/{j}/{f}"), t, v);
                            }
                        }
                        if !bag.topics[k].joints.contains(&j) {
                            bag.topics[k].joints.push(j);
                        }
                    }
                    t
                } else if let Some(scalar) = ty.strip_prefix("std_msgs/msg/") {
                    let mut c = Cdr::new(&data).map_err(err)?;
                    if let Some(v) = c.scalar(scalar).map_err(err)? {
                        push(bag, format!("{name}/data"), log_t, v);
                    }
                    log_t
                } else {
                    log_t
                };
                bag.topics[k].messages += 1;
                bag.topics[k].t_s.push(t);
            }
            _ => {}
        }
    }
    Ok(())
}

/// Reads the bag at `path` (a folder, its `metadata.yaml` or an `.mcap`); `Error::Incompatible`
/// for an `.mcap` that is not a ROS 2 bag.
pub fn read_bag(path: &Path) -> anyhow::Result<Bag> {
    let mut bag = Bag::default();
    for f in bag_files(path)? {
        // servo's own MCAP is told from a bag by its first records: not read twice.
        if f == path && !is_ros2(&prefix(&f)?) {
            return Err(crate::Error::Incompatible {
                path: path.to_path_buf(),
                format: "ROS 2 bag",
            });
        }
        let bytes = crate::mcap_read::read_mcap_bytes(&f)?;
        if !is_ros2(&bytes) {
            if f == path {
                return Err(crate::Error::Incompatible {
                    path: path.to_path_buf(),
                    format: "ROS 2 bag",
                });
            }
            bail!(
                "{}: not a ROS 2 bag file (no ros2 profile, no CDR channel)",
                f.display()
            );
        }
        decode_into(&mut bag, &bytes, &f.display().to_string())?;
    }
    Ok(bag)
}

impl Bag {
    /// The map of a bag with one JointState topic of one joint: its position (and velocity)
    /// in rad (rad/s), and the voltage from the one std_msgs topic, if exactly one.
    pub fn guess(&self) -> Result<String, String> {
        let js: Vec<&Topic> = self
            .topics
            .iter()
            .filter(|t| t.type_name == JOINT_STATE)
            .collect();
        let [t] = js.as_slice() else {
            return Err(format!(
                "{} JointState topics: servo guesses a map for one; name the series, e.g. --columns {EXAMPLE}",
                js.len()
            ));
        };
        let [j] = t.joints.as_slice() else {
            return Err(format!(
                "topic {} holds the joints {}: name the one to read, e.g. --columns theta_l={}/JOINT/position:rad",
                t.name,
                t.joints.join(", "),
                t.name
            ));
        };
        let has = |n: &str| self.series.iter().any(|s| s.name == n && s.t_s.len() > 1);
        let mut map = format!("theta_l={}/{j}/position", t.name);
        if !has(&format!("{}/{j}/position", t.name)) {
            return Err(format!("joint {j} of topic {} has no positions", t.name));
        }
        if has(&format!("{}/{j}/velocity", t.name)) {
            map.push_str(&format!(",omega_l={}/{j}/velocity", t.name));
        }
        let scalars: Vec<&Topic> = self
            .topics
            .iter()
            .filter(|t| t.type_name.starts_with("std_msgs/msg/"))
            .collect();
        // The voltage: the one scalar topic, or the one named for a voltage; the current: the
        // one named for a current.
        let named = |words: &[&str]| -> Vec<&Topic> {
            scalars
                .iter()
                .copied()
                .filter(|t| {
                    words
                        .iter()
                        .any(|w| t.name.to_ascii_lowercase().contains(w))
                })
                .collect()
        };
        match (scalars.as_slice(), named(&["volt"]).as_slice()) {
            ([u], _) | (_, [u]) => map.push_str(&format!(",u={}/data:V", u.name)),
            _ => {}
        }
        if let [i] = named(&["current", "amp"]).as_slice() {
            if scalars.len() > 1 {
                map.push_str(&format!(",i_a={}/data:A", i.name));
            }
        }
        Ok(map)
    }

    /// The earliest sample time [s].
    fn start_s(&self) -> f64 {
        let t = self
            .series
            .iter()
            .filter_map(|s| s.t_s.first().copied())
            .fold(f64::INFINITY, f64::min);
        if t.is_finite() {
            t
        } else {
            0.0
        }
    }
}

/// servo's reader of ROS 2 bags with MCAP storage.
pub struct RosBagReader;

impl crate::log_reader::LogReader for RosBagReader {
    fn name(&self) -> &'static str {
        "ROS 2 bag"
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["mcap"]
    }
    /// A folder with a `metadata.yaml`, that file, or an `.mcap` (read only when a ROS 2 bag).
    fn can_read(&self, path: &Path) -> bool {
        (path.is_dir() && path.join("metadata.yaml").is_file())
            || path.file_name().is_some_and(|n| n == "metadata.yaml")
            || crate::log_reader::extension(path) == "mcap"
    }
    fn read(
        &self,
        path: &Path,
        columns: Option<&str>,
        want: Option<&[Signal]>,
        axis: &servo_core::Transmission,
    ) -> anyhow::Result<(Record, crate::LogMeta)> {
        let source = path.display().to_string();
        let bag = read_bag(path)?;
        let mut notes = Vec::new();
        let text = match columns {
            Some(c) => c.to_string(),
            None => {
                let m = bag
                    .guess()
                    .map_err(|e| anyhow!("{source}: a ROS 2 bag: {e}"))?;
                notes.push(format!("{source}: guessed the column map --columns {m}"));
                m
            }
        };
        let map = series::parse_map(&text, "ROS 2 bag", EXAMPLE)?;
        let (rec, n) = series::build(&bag.series, &map, want, axis, bag.start_s(), &source)?;
        notes.extend(n);
        let meta = crate::LogMeta {
            columns: Some(map.to_string()),
            notes,
            ..crate::LogMeta::default()
        };
        Ok((rec, meta))
    }
    fn inspect(&self, path: &Path) -> anyhow::Result<Vec<String>> {
        let source = path.display().to_string();
        let bag = read_bag(path)?;
        let mut out = vec![format!(
            "{source}: ROS 2 bag (MCAP storage), {} topics",
            bag.topics.len()
        )];
        for t in &bag.topics {
            out.push(format!(
                "  topic {}: {}, {} messages, {}{}",
                t.name,
                if t.type_name.is_empty() {
                    "-"
                } else {
                    &t.type_name
                },
                t.messages,
                series::rate_text(&t.t_s),
                if t.joints.is_empty() {
                    String::new()
                } else {
                    format!(", joints {}", t.joints.join(", "))
                }
            ));
        }
        out.push(crate::log_reader::guessed(
            bag.guess().map_err(crate::Error::Invalid),
        ));
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A little-endian CDR JointState.
    pub fn joint_state_cdr(sec: i32, nsec: u32, names: &[&str], pos: &[f64]) -> Vec<u8> {
        let mut b = vec![0, 1, 0, 0];
        let pad = |b: &mut Vec<u8>, n: usize| {
            while !(b.len() - 4).is_multiple_of(n) {
                b.push(0);
            }
        };
        b.extend_from_slice(&sec.to_le_bytes());
        b.extend_from_slice(&nsec.to_le_bytes());
        b.extend_from_slice(&1u32.to_le_bytes());
        b.push(0);
        pad(&mut b, 4);
        b.extend_from_slice(&(names.len() as u32).to_le_bytes());
        for n in names {
            pad(&mut b, 4);
            b.extend_from_slice(&(n.len() as u32 + 1).to_le_bytes());
            b.extend_from_slice(n.as_bytes());
            b.push(0);
        }
        for arr in [pos, &[], &[]] {
            pad(&mut b, 4);
            b.extend_from_slice(&(arr.len() as u32).to_le_bytes());
            for v in arr {
                pad(&mut b, 8);
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        b
    }

    #[test]
    fn decodes_a_joint_state() {
        let b = joint_state_cdr(3, 500_000_000, &["arm", "wrist"], &[0.25, -1.5]);
        let (stamp, joints) = joint_state(&b).unwrap();
        assert_eq!(stamp, Some(3_500_000_000));
        assert_eq!(joints[0].0, "arm");
        assert_eq!(joints[1].1[0], -1.5);
        assert!(joints[1].1[1].is_nan());
        // A zero stamp: the log time is used.
        assert_eq!(
            joint_state(&joint_state_cdr(0, 0, &["a"], &[1.0]))
                .unwrap()
                .0,
            None
        );
    }

    #[test]
    fn decodes_scalars_both_ways() {
        let mut le = vec![0, 1, 0, 0];
        le.extend_from_slice(&2.5f64.to_le_bytes());
        assert_eq!(Cdr::new(&le).unwrap().scalar("Float64").unwrap(), Some(2.5));
        let mut be = vec![0, 0, 0, 0];
        be.extend_from_slice(&(-7i32).to_be_bytes());
        assert_eq!(Cdr::new(&be).unwrap().scalar("Int32").unwrap(), Some(-7.0));
        assert_eq!(Cdr::new(&le).unwrap().scalar("String").unwrap(), None);
    }

    #[test]
    fn truncated_and_hostile_messages_are_errors() {
        let b = joint_state_cdr(1, 2, &["arm"], &[0.5]);
        for cut in 0..b.len() {
            assert!(joint_state(&b[..cut]).is_err(), "cut at {cut}");
        }
        // A name sequence claiming 2^32-1 strings.
        let mut bad = b[..20].to_vec();
        bad.extend_from_slice(&u32::MAX.to_le_bytes());
        let e = joint_state(&bad).unwrap_err();
        assert!(e.contains("elements declared"), "{e}");
        assert!(Cdr::new(&[0, 7, 0, 0]).is_err());
    }
}
