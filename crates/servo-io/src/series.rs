//! Logs made of named time series (a ROS 2 bag's topic fields, a WPILib DataLog's entries): the
//! column map that names a series per signal, and the record built on one time grid.
//!
//! Each series has its own timestamps. When every mapped series has the same timestamps, they
//! are the record's time. Otherwise the series are aligned on one grid, said in a note: from the
//! latest start to the earliest end of the mapped series, at the median period of the fastest
//! one; a command (`u`, `i_ref`, `duty`, `ref`, `enable`) is held from its last sample (it acts
//! until the next one), a measurement is interpolated linearly between its two neighbours.

use crate::columns::ColumnMap;
use crate::error::{self as anyhow, anyhow, bail};
use crate::units::Signal;
use servo_core::record::Record;

/// One named series: its samples' times [s] (non-decreasing) and values.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Series {
    /// The name users give in `--columns` (`/joint_states/arm/position`, `voltage-arm`).
    pub name: String,
    /// Sample times [s].
    pub t_s: Vec<f64>,
    /// Values, in the series' own unit.
    pub v: Vec<f64>,
}

/// Parses a `--columns` map of a series log: `signal=NAME[:unit]`, without `time` (the time is
/// the series' own); `format` and `example` name the log's format in messages.
pub fn parse_map(text: &str, format: &str, example: &str) -> anyhow::Result<ColumnMap> {
    let has_time = text
        .split(',')
        .any(|e| e.split_once('=').is_some_and(|(s, _)| s.trim() == "time"));
    if has_time {
        bail!(
            "--columns: a {format} has its own time (each sample's timestamp): leave `time=` out \
             (example: --columns {example})"
        );
    }
    let mut map = ColumnMap::parse(&format!("time=<timestamps>,{text}"))
        .map_err(|e| anyhow!("{e:#} (a {format}: --columns {example})"))?;
    map.entries.retain(|e| e.signal != Signal::Time);
    Ok(map)
}

/// The record of `map`'s series (found by name in `all`), in SI units on `axis`; time starts
/// where the log's first series starts (`t0_s`). Returns the record and the notes (the grid).
pub fn build(
    all: &[Series],
    map: &ColumnMap,
    want: Option<&[Signal]>,
    axis: &servo_core::Transmission,
    t0_s: f64,
    source: &str,
) -> anyhow::Result<(Record, Vec<String>)> {
    let factors = map.factors_on(axis)?;
    let wanted = |s: Signal| want.is_none_or(|w| w.contains(&s) || s == Signal::Enable);
    let mut chosen: Vec<(Signal, &Series, f64)> = Vec::new();
    for (e, f) in map.entries.iter().zip(factors) {
        let s = all.iter().find(|s| s.name == e.column).ok_or_else(|| {
            let names: Vec<&str> = all.iter().map(|s| s.name.as_str()).collect();
            anyhow!(
                "{source}: no series `{}` (for `{}`); the log holds {}",
                e.column,
                e.signal,
                crate::excerpt::join_excerpt(&names, ", ", crate::excerpt::HEADER_CHARS)
            )
        })?;
        if s.t_s.len() < 2 {
            bail!(
                "{source}: series `{}` (for `{}`) has {} sample(s); at least 2 are needed",
                s.name,
                e.signal,
                s.t_s.len()
            );
        }
        if wanted(e.signal) {
            chosen.push((e.signal, s, f));
        }
    }
    let Some((_, first, _)) = chosen.first() else {
        bail!("{source}: the column map names no signal to read");
    };
    let mut notes = Vec::new();
    let same = chosen.iter().all(|(_, s, _)| s.t_s == first.t_s);
    let grid: Vec<f64> = if same {
        first.t_s.clone()
    } else {
        let start = chosen
            .iter()
            .map(|(_, s, _)| s.t_s[0])
            .fold(f64::MIN, f64::max);
        let end = chosen
            .iter()
            .map(|(_, s, _)| s.t_s[s.t_s.len() - 1])
            .fold(f64::MAX, f64::min);
        let period = chosen
            .iter()
            .map(|(_, s, _)| median_period(&s.t_s))
            .fold(f64::MAX, f64::min);
        if !(end > start && period > 0.0 && period.is_finite()) {
            bail!(
                "{source}: the mapped series do not overlap in time (or have no time step): \
                 nothing to align"
            );
        }
        let n = ((end - start) / period).floor() as usize + 1;
        // As many grid points as the samples of the series, at most: bounded by the file.
        let most: usize = chosen.iter().map(|(_, s, _)| s.t_s.len()).sum();
        if n > most {
            bail!(
                "{source}: aligning the series would make {n} samples from {most}: their times \
                 are too irregular to share a grid"
            );
        }
        notes.push(format!(
            "{source}: the mapped series have different times; aligned on one grid at {} Hz \
             (the fastest series' median period, {} ms), {:.3} .. {:.3} s; commands held from \
             their last sample, measurements interpolated linearly",
            servo_core::math::sig(1.0 / period, 4),
            servo_core::math::sig(period * 1e3, 4),
            start - t0_s,
            end - t0_s
        ));
        (0..n).map(|k| start + k as f64 * period).collect()
    };
    let mut rec = Record {
        source: source.to_string(),
        time_s: grid.iter().map(|t| t - t0_s).collect(),
        ..Record::default()
    };
    for (signal, s, f) in chosen {
        let col: Vec<f64> = if same {
            s.v.iter().map(|v| v * f).collect()
        } else {
            let hold = matches!(
                signal,
                Signal::U | Signal::IRef | Signal::Duty | Signal::Ref | Signal::Enable
            );
            resample(s, &grid, hold)
                .into_iter()
                .map(|v| v * f)
                .collect()
        };
        signal.store(&mut rec, col);
    }
    Ok((rec, notes))
}

/// The median time step of `t` [s] (0 for fewer than 2 samples).
pub fn median_period(t: &[f64]) -> f64 {
    let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    if d.is_empty() {
        return 0.0;
    }
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

/// `s` on `grid`: the last sample at or before each time (`hold`), or the linear interpolation
/// between the neighbours.
fn resample(s: &Series, grid: &[f64], hold: bool) -> Vec<f64> {
    let mut k = 0usize;
    grid.iter()
        .map(|&t| {
            while k + 1 < s.t_s.len() && s.t_s[k + 1] <= t {
                k += 1;
            }
            if hold || k + 1 >= s.t_s.len() {
                return s.v[k];
            }
            let (t0, t1) = (s.t_s[k], s.t_s[k + 1]);
            if t1 > t0 && t >= t0 {
                s.v[k] + (s.v[k + 1] - s.v[k]) * (t - t0) / (t1 - t0)
            } else {
                s.v[k]
            }
        })
        .collect()
}

/// The rate of a series for `servo inspect` (`100 Hz`, or `-` for fewer than 2 samples).
pub fn rate_text(t: &[f64]) -> String {
    let p = median_period(t);
    if p > 0.0 {
        format!("{} Hz", servo_core::math::sig(1.0 / p, 4))
    } else {
        "-".to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series(name: &str, t: &[f64], v: &[f64]) -> Series {
        Series {
            name: name.into(),
            t_s: t.to_vec(),
            v: v.to_vec(),
        }
    }

    #[test]
    fn aligns_on_the_fastest_grid() {
        let fast_t: Vec<f64> = (0..=10).map(|k| k as f64 * 0.1).collect();
        let theta = series(
            "th",
            &fast_t,
            &fast_t.iter().map(|t| 2.0 * t).collect::<Vec<_>>(),
        );
        let u = series("u", &[0.0, 0.5, 1.0], &[1.0, 3.0, 5.0]);
        let map = parse_map("theta_l=th:rot,u=u", "test log", "x").unwrap();
        let (rec, notes) = build(
            &[theta, u],
            &map,
            None,
            &servo_core::Transmission::GEAR,
            0.0,
            "t",
        )
        .unwrap();
        assert_eq!(rec.len(), 11);
        assert!(notes[0].contains("10.00 Hz"), "{notes:?}");
        let th = rec.theta_l_rad.unwrap();
        assert!((th[3] - 0.6 * 2.0 * std::f64::consts::PI).abs() < 1e-9);
        // held, not interpolated
        assert_eq!(rec.u_v.unwrap()[4], 1.0);
    }

    #[test]
    fn refuses_time_and_unknown_series() {
        assert!(parse_map("time=x,u=v", "test log", "x").is_err());
        let map = parse_map("u=nope", "test log", "x").unwrap();
        let e = build(&[], &map, None, &servo_core::Transmission::GEAR, 0.0, "t").unwrap_err();
        assert!(e.to_string().contains("no series `nope`"), "{e}");
    }
}
