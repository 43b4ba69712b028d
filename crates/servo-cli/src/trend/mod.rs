//! `servo trend` as a library: many logs of a fleet, each fitted against one model file, each
//! parameter followed over time per actuator, and what changes said in words (the command file
//! `cmd/trend.rs` parses, calls [`run`] and prints; the Python package reaches it through
//! [`crate::api::run_json`]).
//!
//! - The logs ([`walk`]) are fitted on a fixed number of worker threads that each take the next
//!   path when done ([`fit_log`]); a worker holds one log in memory at a time and hands back a
//!   small [`fit_log::LogFit`], so memory is bounded by the work in flight, not by the fleet.
//! - Each fit is cached by the log's content hash, the model and servo's version ([`cache`]);
//!   a re-run fits only the new logs, an interrupted run resumes.
//! - The time of each log comes from its content, its name or its modification time ([`when`]).
//! - The statistics (trend, step, verdict, forecast) are servo-core's [`servo_core::trend`].

pub mod cache;
pub mod fit_log;
pub mod report;
pub mod walk;
pub mod when;

use crate::model_file::ModelFile;
use fit_log::{LogFit, ParamValue};
use servo_core::trend::{
    analyse, forecast_crossing, Crossing, Point, Trend, TrendOptions, Verdict,
};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
pub use when::TimeFrom;

/// How logs are grouped into actuators (`--group-by`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum GroupBy {
    /// The name of the folder the log is in (the default: `fleet/arm-3/20260105.csv` is `arm-3`).
    Dir,
    /// The file name up to its first `_` (`arm-3_20260105.csv` is `arm-3`).
    File,
    /// The value of this metadata entry of the log (an MCAP run's key/values) or, for a CSV,
    /// the first value of this column; a log without it is grouped by its folder (and said so).
    Field(String),
}

impl std::str::FromStr for GroupBy {
    type Err = String;
    fn from_str(s: &str) -> Result<GroupBy, String> {
        match s {
            "" => Err("--group-by: expected dir, file or a metadata field / column name".into()),
            "dir" => Ok(GroupBy::Dir),
            "file" => Ok(GroupBy::File),
            f => Ok(GroupBy::Field(f.to_string())),
        }
    }
}

/// What `servo trend` is asked.
#[derive(Debug, Clone)]
pub struct TrendConfig {
    /// Logs and directories of logs.
    pub inputs: Vec<PathBuf>,
    pub model: PathBuf,
    /// Column map of foreign CSV and MAT logs (`--columns`).
    pub columns: Option<String>,
    pub group_by: GroupBy,
    pub time_from: TimeFrom,
    /// Limits given on the command line (`--limit KEY=VALUE`); they override the model file's.
    pub limits: BTreeMap<String, f64>,
    /// The cache directory (`None`: [`cache::default_dir`]).
    pub cache_dir: Option<PathBuf>,
    /// Worker threads (at least 1).
    pub workers: usize,
    pub options: TrendOptions,
    /// A progress line on stderr.
    pub progress: bool,
}

/// One log as the report shows it.
#[derive(Debug, Clone)]
pub struct LogEntry {
    pub path: PathBuf,
    pub time_unix_s: f64,
    /// Where the time came from: `mcap`, `mat`, `column:NAME`, `name:PATTERN`, `mtime`.
    pub time_from: String,
    /// Read from the cache (not fitted in this run).
    pub cached: bool,
    pub fit: LogFit,
}

/// A log that could not be used.
#[derive(Debug, Clone)]
pub struct Failed {
    pub path: PathBuf,
    pub error: String,
}

/// One parameter of one actuator over time.
#[derive(Debug, Clone)]
pub struct ParamTrend {
    pub parameter: String,
    pub unit: String,
    /// (log index in the actuator's logs, estimate), in time order.
    pub points: Vec<(usize, ParamValue)>,
    pub trend: Trend,
    /// The limit, and whether it came from the command line (`--limit`) or the model file.
    pub limit: Option<(f64, &'static str)>,
    pub crossing: Option<Crossing>,
}

/// One actuator: its logs in time order and its parameters' trends.
#[derive(Debug, Clone)]
pub struct Actuator {
    pub name: String,
    /// How the group was found (`dir`, `file`, `field:NAME`, or `dir (no NAME)`).
    pub grouped_by: String,
    pub logs: Vec<LogEntry>,
    pub params: Vec<ParamTrend>,
}

/// The cache's counts of a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CacheCounts {
    /// Logs read from the cache.
    pub hits: usize,
    /// Logs fitted in this run (and stored).
    pub new: usize,
    /// Logs that could not be read or fitted.
    pub failed: usize,
}

/// Everything `servo trend` found.
#[derive(Debug, Clone)]
pub struct TrendReport {
    pub model: PathBuf,
    pub cache_dir: PathBuf,
    pub counts: CacheCounts,
    pub logs_found: usize,
    pub actuators: Vec<Actuator>,
    pub failed: Vec<Failed>,
    pub workers: usize,
    pub elapsed_s: f64,
    pub notes: Vec<String>,
}

/// What a worker hands back for one path.
enum Outcome {
    Ok {
        path: PathBuf,
        fit: Box<LogFit>,
        cached: bool,
    },
    Failed(Failed),
}

/// The cache key of the model and the options that change a fit or a log's cached content.
fn model_key(model_text: &str, cfg: &TrendConfig) -> String {
    let mut h = cache::fnv1a(cache::FNV_OFFSET, model_text.as_bytes());
    h = cache::fnv1a(h, cfg.columns.as_deref().unwrap_or("").as_bytes());
    if let TimeFrom::Column(c) = &cfg.time_from {
        h = cache::fnv1a(h, c.as_bytes());
    }
    format!("{h:016x}")
}

/// One path: its bytes hashed, its fit from the cache or made and stored.
fn process(
    path: &Path,
    model: &ModelFile,
    cache: &cache::Cache,
    cfg: &TrendConfig,
    cache_errors: &std::sync::Mutex<Vec<String>>,
) -> Outcome {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) => {
            return Outcome::Failed(Failed {
                path: path.to_path_buf(),
                error: format!("cannot read it: {e}"),
            })
        }
    };
    let key = cache::content_key(&bytes);
    if let Some(fit) = cache.get::<LogFit>(&key) {
        return Outcome::Ok {
            path: path.to_path_buf(),
            fit: Box::new(fit),
            cached: true,
        };
    }
    let column = match &cfg.time_from {
        TimeFrom::Column(c) => Some(c.as_str()),
        _ => None,
    };
    match fit_log::fit_log(path, &bytes, model, cfg.columns.as_deref(), column) {
        Ok(fit) => {
            if let Err(e) = cache.put(&key, &fit) {
                if let Ok(mut v) = cache_errors.lock() {
                    v.push(format!("{e:#}"));
                }
            }
            Outcome::Ok {
                path: path.to_path_buf(),
                fit: Box::new(fit),
                cached: false,
            }
        }
        Err(e) => Outcome::Failed(Failed {
            path: path.to_path_buf(),
            error: format!("{e:#}"),
        }),
    }
}

/// The time of a log and where it came from.
fn log_time(path: &Path, fit: &LogFit, how: &TimeFrom) -> Option<(f64, String)> {
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    let from_mtime = || when::mtime(path).map(|t| (t, "mtime".to_string()));
    match how {
        TimeFrom::Name(p) => when::time_from_name(name, p).map(|t| (t, format!("name:{p}"))),
        TimeFrom::Mtime => from_mtime(),
        TimeFrom::Column(_) => fit.content_time.clone(),
        TimeFrom::Auto => fit.content_time.clone().or_else(from_mtime),
    }
}

/// The group of a log and how it was found.
fn log_group(path: &Path, fit: &LogFit, by: &GroupBy) -> (String, String) {
    let dir = || {
        path.parent()
            .and_then(|p| p.file_name())
            .and_then(|n| n.to_str())
            .unwrap_or(".")
            .to_string()
    };
    match by {
        GroupBy::Dir => (dir(), "dir".into()),
        GroupBy::File => {
            let stem = path.file_stem().and_then(|n| n.to_str()).unwrap_or("");
            let head = stem.split('_').next().unwrap_or(stem);
            (head.to_string(), "file".into())
        }
        GroupBy::Field(f) => match fit.meta.get(f) {
            Some(v) => (v.clone(), format!("field:{f}")),
            None => (dir(), format!("dir (no {f})")),
        },
    }
}

/// Runs the trend analysis of `cfg`.
pub fn run(cfg: &TrendConfig) -> anyhow::Result<TrendReport> {
    let started = std::time::Instant::now();
    let model_text = std::fs::read_to_string(&cfg.model)
        .map_err(|e| anyhow::anyhow!("reading model file {}: {e}", cfg.model.display()))?;
    let model = ModelFile::parse(&model_text)
        .map_err(|e| anyhow::anyhow!("in model file {}: {e:#}", cfg.model.display()))?;
    model.plant()?;
    let cache_dir = cfg.cache_dir.clone().unwrap_or_else(cache::default_dir);
    let cache = cache::Cache::open(&cache_dir, model_key(&model_text, cfg))?;
    let paths = walk::collect(&cfg.inputs, Some(&cache_dir))?;
    if paths.is_empty() {
        anyhow::bail!(
            "no logs found in {} (files ending in .{})",
            cfg.inputs
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
            walk::LOG_EXTENSIONS.join(", .")
        );
    }
    let workers = cfg.workers.max(1).min(paths.len());
    let next = AtomicUsize::new(0);
    let cache_errors = std::sync::Mutex::new(Vec::new());
    let (tx, rx) = std::sync::mpsc::channel::<Outcome>();
    let mut outcomes = Vec::with_capacity(paths.len());
    let mut counts = CacheCounts::default();
    std::thread::scope(|s| {
        for _ in 0..workers {
            let tx = tx.clone();
            let (next, paths, model, cache, cache_errors) =
                (&next, &paths, &model, &cache, &cache_errors);
            s.spawn(move || loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(path) = paths.get(i) else { break };
                let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    process(path, model, cache, cfg, cache_errors)
                }))
                .unwrap_or_else(|_| {
                    Outcome::Failed(Failed {
                        path: path.clone(),
                        error: "internal error while fitting it (a bug in servo, please report it)"
                            .into(),
                    })
                });
                if tx.send(out).is_err() {
                    break;
                }
            });
        }
        drop(tx);
        for out in rx {
            match &out {
                Outcome::Ok { cached: true, .. } => counts.hits += 1,
                Outcome::Ok { cached: false, .. } => counts.new += 1,
                Outcome::Failed(_) => counts.failed += 1,
            }
            if cfg.progress {
                eprint!(
                    "\rtrend: {}/{} logs ({} from the cache, {} fitted, {} failed) {:.0} s  ",
                    counts.hits + counts.new + counts.failed,
                    paths.len(),
                    counts.hits,
                    counts.new,
                    counts.failed,
                    started.elapsed().as_secs_f64()
                );
            }
            outcomes.push(out);
        }
    });
    if cfg.progress {
        eprintln!();
    }
    let mut notes: Vec<String> = cache_errors.into_inner().unwrap_or_default();
    notes.truncate(5);
    let mut failed = Vec::new();
    let mut groups: BTreeMap<String, (String, Vec<LogEntry>)> = BTreeMap::new();
    for out in outcomes {
        match out {
            Outcome::Failed(f) => failed.push(f),
            Outcome::Ok { path, fit, cached } => {
                let Some((t, from)) = log_time(&path, &fit, &cfg.time_from) else {
                    failed.push(Failed {
                        error: match &cfg.time_from {
                            TimeFrom::Name(p) => {
                                format!("its name does not match --time-from name:{p}")
                            }
                            TimeFrom::Column(c) => format!("it has no date in column {c}"),
                            _ => "it has no time (no date in its content, no modification time)"
                                .into(),
                        },
                        path,
                    });
                    continue;
                };
                let (group, how) = log_group(&path, &fit, &cfg.group_by);
                let g = groups
                    .entry(group)
                    .or_insert_with(|| (how.clone(), Vec::new()));
                if g.0 != how && !g.0.contains(&how) {
                    g.0 = format!("{}, {how}", g.0);
                }
                g.1.push(LogEntry {
                    path,
                    time_unix_s: t,
                    time_from: from,
                    cached,
                    fit: *fit,
                });
            }
        }
    }
    failed.sort_by(|a, b| a.path.cmp(&b.path));
    let mut limits = model.limits.clone();
    let mut limit_source: BTreeMap<String, &'static str> =
        limits.keys().map(|k| (k.clone(), "model file")).collect();
    for (k, v) in &cfg.limits {
        limits.insert(k.clone(), *v);
        limit_source.insert(k.clone(), "--limit");
    }
    let actuators = groups
        .into_iter()
        .map(|(name, (grouped_by, mut logs))| {
            logs.sort_by(|a, b| {
                a.time_unix_s
                    .total_cmp(&b.time_unix_s)
                    .then_with(|| a.path.cmp(&b.path))
            });
            let params = param_trends(&logs, &limits, &limit_source, &cfg.options);
            Actuator {
                name,
                grouped_by,
                logs,
                params,
            }
        })
        .collect();
    Ok(TrendReport {
        model: cfg.model.clone(),
        cache_dir,
        counts,
        logs_found: paths.len(),
        actuators,
        failed,
        workers,
        elapsed_s: started.elapsed().as_secs_f64(),
        notes,
    })
}

/// The trend of every parameter of one actuator's logs (sorted by time), in the order the fits
/// name them.
fn param_trends(
    logs: &[LogEntry],
    limits: &BTreeMap<String, f64>,
    source: &BTreeMap<String, &'static str>,
    opts: &TrendOptions,
) -> Vec<ParamTrend> {
    let mut order: Vec<(String, String)> = Vec::new();
    for l in logs {
        for e in &l.fit.estimates {
            if !order.iter().any(|(p, _)| *p == e.parameter) {
                order.push((e.parameter.clone(), e.unit.clone()));
            }
        }
    }
    let t0 = logs.first().map_or(0.0, |l| l.time_unix_s);
    order
        .into_iter()
        .map(|(parameter, unit)| {
            let points: Vec<(usize, ParamValue)> = logs
                .iter()
                .enumerate()
                .filter_map(|(i, l)| {
                    l.fit
                        .estimates
                        .iter()
                        .find(|e| e.parameter == parameter)
                        .map(|e| (i, e.clone()))
                })
                .collect();
            // Days since the first log: small numbers keep the sums exact.
            let series: Vec<Point> = points
                .iter()
                .map(|(i, e)| Point {
                    t_day: (logs[*i].time_unix_s - t0) / 86_400.0,
                    value: e.value,
                    std_err: e.std_err,
                })
                .collect();
            let limit = limits
                .get(&parameter)
                .map(|v| (*v, source.get(&parameter).copied().unwrap_or("model file")));
            let opts = TrendOptions {
                scale_floor: limit.map_or(opts.scale_floor, |l| l.0.abs()),
                ..*opts
            };
            let trend = analyse(&series, &opts);
            let crossing = match (&trend.linear, limit) {
                (Some(lin), Some((v, _)))
                    if matches!(trend.verdict, Verdict::Rising | Verdict::Falling) =>
                {
                    Some(forecast_crossing(lin, v))
                }
                _ => None,
            };
            ParamTrend {
                parameter,
                unit,
                points,
                trend,
                limit,
                crossing,
            }
        })
        .collect()
}

/// Parses `--limit KEY=VALUE`.
pub fn parse_limit(s: &str) -> Result<(String, f64), String> {
    let (k, v) = s.split_once('=').ok_or_else(|| {
        format!("--limit: expected PARAMETER=VALUE (e.g. tau_sf=0.02), got `{s}`")
    })?;
    let v: f64 = v
        .trim()
        .parse()
        .map_err(|_| format!("--limit {s}: `{v}` is not a number (the limit in SI units)"))?;
    if !v.is_finite() {
        return Err(format!("--limit {s}: the limit must be finite"));
    }
    Ok((k.trim().to_string(), v))
}
