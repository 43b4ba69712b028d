//! Whether a board loop keeps its period: the host's watch over the first samples of a run and
//! every sample after, from what the protocol already carries (the board's `MISSED_DEADLINE`
//! flag, its sample clock) and the host's own arrival times.
//!
//! A loop that cannot keep its period fails in one of two ways, and both end in a run away:
//! * **missed deadlines**: the host's answer to sample k reaches the board after sample k+1 was
//!   due, so the board holds the previous command another period (a longer, irregular delay in
//!   the loop than the one its gains were designed for);
//! * **a growing backlog**: the host (or an emulated board that runs slower than its own clock)
//!   gets through fewer samples per second than the board's clock makes, so every sample is
//!   older than the last when the host answers it: a delay that grows without bound.
//!
//! [`StarvationWatch`] judges each sample against [`STARVED_MISSED_FRACTION`] over the last
//! [`WINDOW_SAMPLES`] (from the [`MIN_SAMPLES`]-th on) and [`STARVED_BACKLOG_PERIODS`] /
//! [`STARVED_BACKLOG_MIN_S`], and when it trips names the period the loop did hold:
//! [`Starved::suggested_period_ms`], twice the time a sample really took, rounded up to 1, 2, 5
//! x 10^n ms.

use std::collections::VecDeque;
use std::time::Instant;

/// Share of missed deadlines over the window above which the loop is starved: most commands
/// reach the board after the next sample was due, so the loop runs with at least one period of
/// delay more than its gains were designed for, and the late periods come in bursts (an
/// emulated board descheduled for several periods runs its plant on a stale command, then
/// catches up).
pub const STARVED_MISSED_FRACTION: f64 = 0.5;
/// Samples of the sliding window [samples].
pub const WINDOW_SAMPLES: usize = 100;
/// Samples before the first verdict [samples]: the first answers of a run may be late while the
/// host warms up, so one or two misses alone do not stop a run.
pub const MIN_SAMPLES: usize = 20;
/// Growth of the samples' age on arrival (host clock minus board clock, over its smallest
/// value so far) that stops the run [periods]: ten periods of delay is far beyond any design's
/// phase margin at the crossover servo designs for.
pub const STARVED_BACKLOG_PERIODS: f64 = 10.0;
/// ... and at least this long [s], so that a short period's scheduler hiccup (a few ms on a
/// busy machine, caught up at once) does not stop a run.
pub const STARVED_BACKLOG_MIN_S: f64 = 0.02;
/// The suggested period is this multiple of the time a sample really took (headroom).
pub const SUGGESTED_HEADROOM: f64 = 2.0;
/// How long the host answers 0 V after Start, watching the loop, before a run's first sample
/// [s] ([`settle_samples`]): a loop that cannot keep its period is refused before any voltage.
pub const SETTLE_S: f64 = 0.2;

/// Share of missed deadlines in the 0 V settle phase above which a run is refused before it
/// moves: a loop that misses this many at rest, with nothing to compute, has little room left
/// for a busier moment. Half the running watch's [`STARVED_MISSED_FRACTION`]; a loop under a
/// passing load (the odd scheduler hiccup: a tenth of the deadlines on a busy 2-core machine)
/// still runs.
pub const SETTLE_MAX_MISSED_FRACTION: f64 = 0.25;

/// Samples of the 0 V settle phase at period `period_s` [s]: [`SETTLE_S`] worth, at least twice
/// [`MIN_SAMPLES`] (two verdicts) and at most one [`WINDOW_SAMPLES`] window.
pub fn settle_samples(period_s: f64) -> usize {
    let n = if period_s.is_finite() && period_s > 0.0 {
        (SETTLE_S / period_s).ceil()
    } else {
        0.0
    };
    (n.min(WINDOW_SAMPLES as f64) as usize).max(2 * MIN_SAMPLES)
}

/// Why the loop is starved, with the figures measured.
#[derive(Debug, Clone, PartialEq)]
pub struct Starved {
    /// The board's period [s].
    pub period_s: f64,
    /// Samples watched.
    pub samples: u64,
    /// Missed deadlines in the window and the window's length.
    pub missed_in_window: usize,
    pub window: usize,
    /// The samples' age on arrival beyond its smallest value [s].
    pub backlog_s: f64,
    /// Mean host time per sample over the window [s] (the period the loop really ran at).
    pub time_per_sample_s: f64,
    /// A period the loop can hold here [ms].
    pub suggested_period_ms: f64,
    /// Whether the watch tripped in the settle phase, while the host answered 0 V: the loop
    /// never moved.
    pub at_rest: bool,
}

impl std::fmt::Display for Starved {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the board is starved: use --period-ms {} (at {} ms, {} of the last {} samples missed \
             their deadline and answers lagged {:.1} ms behind the board's clock; a sample took \
             {:.2} ms; {} at sample {} {})",
            self.suggested_period_ms,
            self.period_s * 1e3,
            self.missed_in_window,
            self.window,
            self.backlog_s * 1e3,
            self.time_per_sample_s * 1e3,
            if self.at_rest { "refused" } else { "stopped" },
            self.samples,
            if self.at_rest {
                "of the 0 V settle phase, before the loop moved"
            } else {
                "before the error grew"
            }
        )
    }
}

/// The smallest of 1, 2, 5 x 10^n ms that is >= `ms` (at least 1 ms).
pub fn nice_period_ms(ms: f64) -> f64 {
    let ms = if ms.is_finite() { ms.max(1.0) } else { 1000.0 };
    let mut decade = 1.0;
    loop {
        for m in [1.0, 2.0, 5.0] {
            if m * decade >= ms - 1e-9 {
                return m * decade;
            }
        }
        decade *= 10.0;
    }
}

/// The host's watch over a run's samples (see the module documentation).
#[derive(Debug, Clone)]
pub struct StarvationWatch {
    period_s: f64,
    /// (arrival [s since the first sample], missed) of the last samples.
    window: VecDeque<(f64, bool)>,
    first_arrival: Option<Instant>,
    /// Smallest (arrival - board time) so far [s].
    min_age_s: f64,
    /// The last sample's (arrival - board time) [s].
    last_age_s: f64,
    samples: u64,
}

impl StarvationWatch {
    /// A watch over a loop of period `period_s` [s].
    pub fn new(period_s: f64) -> StarvationWatch {
        StarvationWatch {
            period_s,
            window: VecDeque::with_capacity(WINDOW_SAMPLES + 1),
            first_arrival: None,
            min_age_s: f64::INFINITY,
            last_age_s: 0.0,
            samples: 0,
        }
    }

    /// Samples seen.
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// One sample: its board time `board_time_s` [s since Start], when it arrived, and whether
    /// the board flagged the previous period's command as missed. `Err` when the loop is starved.
    pub fn push(&mut self, board_time_s: f64, at: Instant, missed: bool) -> Result<(), Starved> {
        let first = *self.first_arrival.get_or_insert(at);
        let arrival_s = at.duration_since(first).as_secs_f64();
        let age_s = arrival_s - board_time_s;
        self.min_age_s = self.min_age_s.min(age_s);
        self.last_age_s = age_s;
        self.samples += 1;
        self.window.push_back((arrival_s, missed));
        if self.window.len() > WINDOW_SAMPLES {
            self.window.pop_front();
        }
        if (self.samples as usize) < MIN_SAMPLES {
            return Ok(());
        }
        self.verdict(STARVED_MISSED_FRACTION, age_s)
    }

    /// The verdict at the end of the 0 V settle phase ([`settle_samples`]): stricter than a
    /// running loop's, at most [`SETTLE_MAX_MISSED_FRACTION`] of the samples so far missed, so
    /// that a loop that only just keeps its period at rest is refused before it moves.
    pub fn settle_verdict(&self) -> Result<(), Starved> {
        let age_s = self.last_age_s;
        self.verdict(SETTLE_MAX_MISSED_FRACTION, age_s)
    }

    fn verdict(&self, max_missed_fraction: f64, age_s: f64) -> Result<(), Starved> {
        let missed_n = self.window.iter().filter(|w| w.1).count();
        let n = self.window.len();
        let backlog_s = age_s - self.min_age_s;
        let backlog_limit_s = (STARVED_BACKLOG_PERIODS * self.period_s).max(STARVED_BACKLOG_MIN_S);
        let missed_too_often = missed_n as f64 > max_missed_fraction * n as f64;
        if !(missed_too_often || backlog_s > backlog_limit_s) {
            return Ok(());
        }
        let span_s =
            self.window.back().map_or(0.0, |b| b.0) - self.window.front().map_or(0.0, |f| f.0);
        let time_per_sample_s = if n > 1 { span_s / (n - 1) as f64 } else { 0.0 };
        // Missed deadlines say the answer took longer than a period; how much longer the board
        // does not say (its round trip is unknown for a missed period), so twice the period is
        // the least that was needed.
        let needed_s = if missed_too_often {
            time_per_sample_s.max(2.0 * self.period_s)
        } else {
            time_per_sample_s.max(self.period_s)
        };
        Err(Starved {
            period_s: self.period_s,
            samples: self.samples,
            missed_in_window: missed_n,
            window: n,
            backlog_s,
            time_per_sample_s,
            suggested_period_ms: nice_period_ms(SUGGESTED_HEADROOM * needed_s * 1e3),
            at_rest: false,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn the_settle_phase_gives_the_watch_two_verdicts_within_a_window() {
        let got: Vec<usize> = [1e-3, 2e-3, 5e-3, 10e-3, 0.1, f64::NAN]
            .iter()
            .map(|&p| settle_samples(p))
            .collect();
        assert_eq!(got, [100, 100, 40, 40, 40, 40]);
    }

    #[test]
    fn a_settle_phase_with_a_few_misses_too_many_is_refused() {
        let t0 = Instant::now();
        let mut w = StarvationWatch::new(1e-3);
        // One in three missed: a running loop goes on, a loop at rest is refused.
        for k in 0..99 {
            let at = t0 + Duration::from_secs_f64(k as f64 * 1e-3);
            assert!(w.push(k as f64 * 1e-3, at, k % 3 == 1).is_ok());
        }
        let s = w.settle_verdict().unwrap_err();
        assert_eq!((s.missed_in_window, s.window), (33, 99), "{s}");
        assert!(s.at_rest || s.to_string().contains("--period-ms"), "{s}");
        // One in five: a busy machine's hiccups, not a starved loop.
        let mut busy = StarvationWatch::new(1e-3);
        for k in 0..100 {
            let at = t0 + Duration::from_secs_f64(k as f64 * 1e-3);
            assert!(busy.push(k as f64 * 1e-3, at, k % 5 == 1).is_ok());
        }
        assert!(busy.settle_verdict().is_ok());
    }

    #[test]
    fn nice_periods() {
        let got: Vec<f64> = [0.2, 1.0, 1.01, 2.0, 3.9, 5.0, 7.0, 11.0, 150.0]
            .iter()
            .map(|&m| nice_period_ms(m))
            .collect();
        assert_eq!(got, [1.0, 1.0, 2.0, 2.0, 5.0, 5.0, 10.0, 20.0, 200.0]);
    }

    /// Feeds `n` samples of a 1 ms board; sample k arrives at `arrive(k)` [s] and is flagged
    /// missed by `missed(k)`. Returns the sample at which the watch tripped and why.
    fn feed(
        n: usize,
        arrive: impl Fn(usize) -> f64,
        missed: impl Fn(usize) -> bool,
    ) -> Option<(usize, Starved)> {
        let t0 = Instant::now();
        let mut w = StarvationWatch::new(1e-3);
        for k in 0..n {
            let at = t0 + Duration::from_secs_f64(arrive(k));
            if let Err(s) = w.push(k as f64 * 1e-3, at, missed(k)) {
                return Some((k, s));
            }
        }
        None
    }

    #[test]
    fn a_loop_that_keeps_its_period_runs_on() {
        // Jitter of +-0.4 ms, a 15 ms hiccup caught up at once, one miss in ten, one in three.
        let jitter = |k: usize| 1e-3 + k as f64 * 1e-3 + 4e-4 * ((k * 7919) % 3) as f64 - 4e-4;
        let hiccup = |k: usize| {
            let t = k as f64 * 1e-3;
            if (500..515).contains(&k) {
                0.515
            } else {
                t
            }
        };
        assert_eq!(feed(5000, jitter, |k| k % 10 == 3), None);
        assert_eq!(feed(5000, jitter, |k| k % 3 == 1), None);
        assert_eq!(feed(5000, hiccup, |k| (500..516).contains(&k)), None);
    }

    #[test]
    fn missed_deadlines_stop_the_run_within_the_first_samples() {
        let (k, s) = feed(5000, |k| k as f64 * 1e-3, |k| k % 3 != 0).unwrap();
        assert_eq!(k, MIN_SAMPLES - 1, "{s}");
        assert_eq!(
            s.suggested_period_ms, 5.0,
            "twice the two periods needed: {s}"
        );
        let text = s.to_string();
        assert!(
            text.starts_with("the board is starved: use --period-ms 5 "),
            "{text}"
        );
    }

    #[test]
    fn a_growing_backlog_stops_the_run_and_names_the_period_the_loop_held() {
        // The host gets through a sample every 1.6 ms of a 1 ms board: the answers lag 0.6 ms
        // more each sample, beyond 20 ms after ~34 samples; no deadline flagged.
        let (k, s) = feed(5000, |k| k as f64 * 1.6e-3, |_| false).unwrap();
        assert!((33..=36).contains(&k), "{k}: {s}");
        assert!((s.time_per_sample_s - 1.6e-3).abs() < 1e-6, "{s}");
        assert_eq!(s.suggested_period_ms, 5.0, "2 x 1.6 ms -> 5 ms: {s}");
    }
}
