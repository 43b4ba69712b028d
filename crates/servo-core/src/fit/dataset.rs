//! Preparation of records for equation-error fitting: one zero-phase filter, derivatives, the rows
//! of each equation (moving samples with a margin around stuck phases for the torque balance, every
//! sample for the electrical balance), decimation and the fit / held-out split.

use super::{FitError, FitOptions};
use crate::math;
use crate::params::PlantParams;
use crate::record::Record;
use crate::signal::{derivative, ZeroPhase};
use alloc::string::String;
use alloc::vec::Vec;

/// One record, prepared.
#[derive(Debug, Clone)]
pub struct RecData {
    /// Where it came from.
    pub source: String,
    /// Sample period [s].
    pub dt_s: f64,
    /// Time of each row [s].
    pub time_s: Vec<f64>,
    /// Logged driver input u [V], raw (row k applied from k to k+1); zeros when the record has no
    /// input (see `has_u`).
    pub u_v: Vec<f64>,
    /// Whether u was logged. A record without u (current and motion only, e.g. a speed-controlled
    /// friction staircase) serves the torque balance only: no electrical balance, no simulation.
    pub has_u: bool,
    /// Motor angle [rad], raw (measured, or N times the load angle).
    pub theta_m_rad: Vec<f64>,
    /// True when the angle measured is the load's (theta_m_rad = N theta_l).
    pub angle_is_load: bool,
    /// Unit phasor [cos, sin] of the motor angle at every row (harmonic regressors by complex
    /// powers).
    pub motor_phasor: Vec<[f64; 2]>,
    /// Motor speed [rad/s] from a lightly filtered position (for nonlinear regressors).
    pub omega_raw: Vec<f64>,
    /// Motor speed [rad/s], zero-phase filtered.
    pub omega_f: Vec<f64>,
    /// Motor acceleration [rad/s^2], zero-phase filtered.
    pub accel_f: Vec<f64>,
    /// Armature current [A], raw and filtered, and its filtered derivative [A/s].
    pub i_raw: Option<Vec<f64>>,
    pub i_f: Option<Vec<f64>>,
    pub di_f: Option<Vec<f64>>,
    /// The current that drives the motion around row k [A], filtered: the mean over the sample
    /// centred on t_k (see [`centred_current`]), for the torque balance.
    pub i_torque_f: Option<Vec<f64>>,
    /// The filter every regressor of this record goes through.
    pub filter: ZeroPhase,
}

impl RecData {
    /// Applies the record's filter to a raw full-length signal.
    pub fn filt(&self, raw: &[f64]) -> Vec<f64> {
        self.filter.apply(raw)
    }

    /// [`Self::filt`] of two signals at once (the same values, filtered in lockstep).
    pub fn filt_pair(&self, a: &[f64], b: &[f64]) -> (Vec<f64>, Vec<f64>) {
        self.filter.apply_pair(a, b)
    }

    /// The logged input with a transformation per sample (input nonlinearity), then seen through
    /// the zero-order hold shifted by `shift_s` [s] and averaged over one sample centred on each
    /// row: row k gets the mean of the held input over [t_k - dt/2 - shift, t_k + dt/2 - shift].
    /// With `shift_s` = 0 this is (u[k-1] + u[k]) / 2, the log convention.
    pub fn input_seen(&self, transform: impl Fn(f64) -> f64, shift_s: f64) -> Vec<f64> {
        let u_in: Vec<f64> = self.u_v.iter().map(|&u| transform(u)).collect();
        shift_hold(&u_in, shift_s / self.dt_s)
    }

    /// The input as a point sample at each row: what drives the current measured at t_k. The
    /// transformed input, delayed by `delay_s`, held, then passed through the first-order lag
    /// `lag_s` (driver and armature) exactly for a zero-order-hold input: with no delay and a lag
    /// much shorter than the sample period, row k sees u[k-1].
    pub fn input_point(
        &self,
        transform: impl Fn(f64) -> f64,
        delay_s: f64,
        lag_s: f64,
    ) -> Vec<f64> {
        let u_in: Vec<f64> = self.u_v.iter().map(|&u| transform(u)).collect();
        let n = u_in.len();
        let m = (delay_s / self.dt_s).max(0.0);
        let n0 = math::floor(m) as usize;
        let frac = m - n0 as f64;
        let decay = |t: f64| {
            if lag_s > 0.0 {
                math::exp(-t / lag_s)
            } else {
                0.0
            }
        };
        let (a1, a2) = (decay(frac * self.dt_s), decay((1.0 - frac) * self.dt_s));
        let at = |j: isize| u_in[j.clamp(0, n as isize - 1) as usize];
        // Over [t_{k-1}, t_k) the delayed input is u[k-2-n0] for frac dt, then u[k-1-n0]; the
        // lag's response to that piecewise-constant input is exact.
        let mut y = at(0);
        (0..n)
            .map(|k| {
                let k = k as isize - n0 as isize;
                let (v1, v2) = (at(k - 2), at(k - 1));
                let y1 = y * a1 + v1 * (1.0 - a1);
                y = y1 * a2 + v2 * (1.0 - a2);
                y
            })
            .collect()
    }
}

/// Box-averaged zero-order hold of `u` shifted by `m` samples, evaluated at every row.
pub fn shift_hold(u: &[f64], m: f64) -> Vec<f64> {
    let n = u.len();
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        let x = k as f64 - 0.5 - m;
        let j0 = math::floor(x);
        let f = x - j0;
        let at = |j: f64| -> f64 {
            let j = if j < 0.0 { 0 } else { (j as usize).min(n - 1) };
            u[j]
        };
        out.push((1.0 - f) * at(j0) + f * at(j0 + 1.0));
    }
    out
}

/// Selected rows of an equation: (record, sample) pairs and whether each is used for fitting
/// (true) or held out (false).
#[derive(Debug, Clone, Default)]
pub struct Rows {
    pub rec: Vec<usize>,
    pub k: Vec<usize>,
    pub fit: Vec<bool>,
    /// Electrical rows only: within 50 ms of a reversal of the motor torque (current) while the
    /// angle measured is the load's. With a gear play in the model the motor may be crossing the
    /// gap there, its speed unknown: such rows get no weight in the electrical balance.
    pub torque_reversal: Vec<bool>,
    /// Torque-balance rows only: the same flag. With a gear play in the model such rows get no
    /// weight in the torque balance (the rigid-body balance does not hold while the gap is
    /// crossed); the analyses of the base model's balances keep them.
    pub gap_crossing: Vec<bool>,
}

impl Rows {
    /// The rows for which `keep(i)` holds, in order.
    pub fn filtered(&self, keep: impl Fn(usize) -> bool) -> Rows {
        let pick = |v: &[bool]| -> Vec<bool> {
            v.iter()
                .enumerate()
                .filter(|(i, _)| keep(*i))
                .map(|(_, b)| *b)
                .collect()
        };
        let idx: Vec<usize> = (0..self.len()).filter(|&i| keep(i)).collect();
        Rows {
            rec: idx.iter().map(|&i| self.rec[i]).collect(),
            k: idx.iter().map(|&i| self.k[i]).collect(),
            fit: idx.iter().map(|&i| self.fit[i]).collect(),
            torque_reversal: pick(&self.torque_reversal),
            gap_crossing: pick(&self.gap_crossing),
        }
    }
    pub fn len(&self) -> usize {
        self.k.len()
    }
    pub fn is_empty(&self) -> bool {
        self.k.is_empty()
    }
}

/// Records prepared for fitting.
#[derive(Debug, Clone)]
pub struct Dataset {
    pub recs: Vec<RecData>,
    /// Every record logs the armature current (torque and electrical balances are used); else the
    /// u-driven combined equation is used.
    pub has_current: bool,
    /// Rows of the torque (or combined) equation: moving samples with a margin.
    pub mech_rows: Rows,
    /// Rows of the electrical equation: every sample away from the ends.
    pub elec_rows: Rows,
    /// Largest |u| in the logs [V] (0 when no record logs u).
    pub u_max_v: f64,
    /// At least one record logs the input u (input-side effects and the simulation need it).
    pub has_input: bool,
    /// Gear ratio N used to convert load and motor sides.
    pub gear_ratio: f64,
    /// The Coulomb regressor sign(omega)/N, filtered, at the torque-balance rows (cached).
    pub coulomb_col: Vec<f64>,
    pub opts: FitOptions,
    /// On long logs: windows of the records, spread evenly over them, for the searches over
    /// nonlinear parameters ([`Dataset::search_set`]); `None` when the logs are short enough to
    /// search on everything.
    pub search: Option<alloc::boxed::Box<Dataset>>,
}

/// Most samples (over all records) the searches over nonlinear parameters run on: longer logs
/// are searched on windows of [`SEARCH_WINDOW_S`] spread evenly over them (1 minute at 1 kHz,
/// six windows of 10 s).
///
/// A search only *locates* a nonlinear parameter (a harmonic, a speed scale, a limit, a delay);
/// its interval from a minute of data holding reversals, accelerations and slow motion is
/// already far tighter than any check needs. Every linear parameter,
/// residual and check is then computed on all the data ([`Dataset::search_set`]), so a drift
/// or a difference between the log's halves is still seen. Halving the budget from two minutes
/// halves the cost of the equation searches on long logs.
pub const SEARCH_MAX_SAMPLES: usize = 60_000;

/// Length of each search window [s].
pub const SEARCH_WINDOW_S: f64 = 10.0;

impl Dataset {
    /// Prepares `records` (gear ratio from `params`).
    pub fn new(
        records: &[Record],
        params: &PlantParams,
        opts: &FitOptions,
    ) -> Result<Dataset, FitError> {
        let mut ds = Self::prepared(records, params, opts, true, None)?;
        let stuck = Some(ds.opts.min_speed_rad_s);
        ds.search = search_windows(records, ds.recs.iter().map(|r| r.dt_s))
            .and_then(|w| Self::prepared(&w, params, opts, true, stuck).ok())
            .map(alloc::boxed::Box::new);
        Ok(ds)
    }

    /// [`Dataset::new`] without search windows; `centre_counts`: move an encoder's readings to
    /// the centre of their count cells (see [`prepare`]); `stuck`: the stuck-speed threshold
    /// [rad/s] (`None`: the rig's, [`rig_stuck_speed_rad_s`] of these records).
    fn prepared(
        records: &[Record],
        params: &PlantParams,
        opts: &FitOptions,
        centre_counts: bool,
        stuck: Option<f64>,
    ) -> Result<Dataset, FitError> {
        if records.is_empty() {
            return Err(FitError::NoData(String::from("no records given")));
        }
        let mut recs = Vec::new();
        for r in records {
            recs.push(prepare(r, params, opts, centre_counts)?);
        }
        let has_current = recs.iter().all(|r| r.i_raw.is_some());
        if !has_current {
            // The u-driven balance (used when a record lacks the current) needs u everywhere.
            if let (Some(a), Some(b)) = (
                recs.iter().find(|r| !r.has_u),
                recs.iter().find(|r| r.i_raw.is_none()),
            ) {
                return Err(FitError::BadRecord(alloc::format!(
                    "{} logs no input voltage u and {} logs no current i_a: with the current missing somewhere the fit uses the u-driven balance, which needs u in every log",
                    a.source, b.source
                )));
            }
        }
        let has_input = recs.iter().any(|r| r.has_u);
        let u_max_v = recs
            .iter()
            .filter(|r| r.has_u)
            .flat_map(|r| r.u_v.iter())
            .fold(0.0f64, |m, u| m.max(u.abs()));
        // The stuck-speed threshold of this rig (its encoder and its speeds, at the motor).
        let opts = &FitOptions {
            min_speed_rad_s: stuck.unwrap_or_else(|| rig_stuck_speed_rad_s(&recs, opts)),
            ..opts.clone()
        };
        let mut mech_rows = Rows::default();
        let mut elec_rows = Rows::default();
        for (ri, r) in recs.iter().enumerate() {
            select_rows(ri, r, opts, &mut mech_rows, &mut elec_rows);
        }
        let need = 20;
        if mech_rows.len() < need {
            return Err(FitError::NoData(alloc::format!(
                "only {} usable moving samples (speed above {} rad/s at the motor, this rig's stuck threshold from its encoder and speeds, away from stuck phases); the logs need the motor to move",
                mech_rows.len(),
                crate::math::Num(opts.min_speed_rad_s)
            )));
        }
        let mut ds = Dataset {
            recs,
            has_current,
            mech_rows,
            elec_rows,
            u_max_v,
            has_input,
            gear_ratio: params.n,
            coulomb_col: Vec::new(),
            opts: opts.clone(),
            search: None,
        };
        let n = params.n;
        ds.coulomb_col = ds.column(&ds.mech_rows, |r: &RecData| {
            r.omega_raw
                .iter()
                .map(|&w| crate::effects::coulomb::direction(w) / n)
                .collect()
        });
        Ok(ds)
    }

    /// This data set with the torque balance's pre-sliding rows left out (travel since the last
    /// reversal below `counts` encoder counts, [`presliding`]), its search windows alike (none,
    /// the searches then running on every row, when too few of theirs would be left); `None`
    /// when too few rows would be left.
    pub fn without_presliding(&self, counts: f64) -> Option<Dataset> {
        let flags: Vec<Vec<bool>> = self
            .recs
            .iter()
            .map(|r| presliding(r, counts, self.opts.min_speed_rad_s))
            .collect();
        let rows = &self.mech_rows;
        let keep = |i: usize| !flags[rows.rec[i]][rows.k[i]];
        let mech_rows = rows.filtered(keep);
        if mech_rows.len() < 20 {
            return None;
        }
        let coulomb_col = (0..rows.len())
            .filter(|&i| keep(i))
            .map(|i| self.coulomb_col[i])
            .collect();
        // Search windows left with too few sliding rows: the searches then run on every
        // sliding row (slower, never wrong), rather than losing the sliding regime.
        let search = self
            .search
            .as_ref()
            .and_then(|s| s.without_presliding(counts))
            .map(alloc::boxed::Box::new);
        Some(Dataset {
            mech_rows,
            coulomb_col,
            search,
            opts: FitOptions {
                presliding_counts: counts,
                ..self.opts.clone()
            },
            ..self.clone()
        })
    }

    /// The same records prepared again with the motor angle of each record replaced by
    /// `angle(record)` [rad] (full length; N times the load angle when the record measures the
    /// load's), e.g. the true angle recovered from a distorted sensor's reading. The new angles
    /// are taken as they are (already centred in their count cells); the rows are selected again;
    /// no search windows (see [`Dataset::search_set`]): call it on `search_set()` to search.
    pub fn with_motor_angles(
        &self,
        params: &PlantParams,
        angle: impl Fn(&RecData) -> Vec<f64>,
    ) -> Result<Dataset, FitError> {
        let mut records = Vec::with_capacity(self.recs.len());
        for r in &self.recs {
            let th = angle(r);
            if th.len() != r.theta_m_rad.len() {
                return Err(FitError::BadRecord(alloc::format!(
                    "{}: a corrected angle has {} samples for {}",
                    r.source,
                    th.len(),
                    r.theta_m_rad.len()
                )));
            }
            let (theta_l_rad, theta_m_rad) = if r.angle_is_load {
                (Some(th.iter().map(|v| v / params.n).collect()), None)
            } else {
                (None, Some(th))
            };
            records.push(Record {
                source: r.source.clone(),
                time_s: r.time_s.clone(),
                u_v: r.has_u.then(|| r.u_v.clone()),
                theta_l_rad,
                theta_m_rad,
                omega_l_rad_s: None,
                omega_m_rad_s: None,
                i_a_a: r.i_raw.clone(),
                ref_rad: None,
                enable: None,
                ..Record::default()
            });
        }
        Self::prepared(
            &records,
            params,
            &self.opts,
            false,
            Some(self.opts.min_speed_rad_s),
        )
    }

    /// The data the searches over nonlinear parameters run on: the search windows on long logs,
    /// everything otherwise.
    ///
    /// The cost of a search is the number of trial values times the samples each trial filters
    /// and solves (every regressor of a trial is built and zero-phase filtered at full rate); a
    /// nonlinear parameter (a harmonic, a speed scale, a limit, a delay) is located as well on
    /// two minutes of data spread over a long log as on all of it. The linear parameters, the
    /// residuals and every judgement are then computed on all the data.
    pub fn search_set(&self) -> &Dataset {
        self.search.as_deref().unwrap_or(self)
    }

    /// Samples a filtered full-rate signal of each record at `rows`.
    pub fn sample(&self, rows: &Rows, sig: impl Fn(&RecData) -> &[f64]) -> Vec<f64> {
        let mut out = Vec::with_capacity(rows.len());
        let mut cur: Option<(usize, &[f64])> = None;
        for (&ri, &k) in rows.rec.iter().zip(&rows.k) {
            let s = match cur {
                Some((c, s)) if c == ri => s,
                _ => {
                    let s = sig(&self.recs[ri]);
                    cur = Some((ri, s));
                    s
                }
            };
            out.push(s[k]);
        }
        out
    }

    /// Builds a raw full-rate signal per record with `raw`, filters it with the record's filter
    /// and samples it at `rows`.
    pub fn column(&self, rows: &Rows, raw: impl Fn(&RecData) -> Vec<f64>) -> Vec<f64> {
        let mut out = self.columns_with(rows, 1, |r| alloc::vec![raw(r)]);
        out.pop().unwrap_or_default()
    }

    /// As [`Dataset::column`] for two signals built together by `raw` (one pass over each
    /// record, e.g. a sin/cos pair).
    pub fn column_pair(
        &self,
        rows: &Rows,
        raw: impl Fn(&RecData) -> (Vec<f64>, Vec<f64>),
    ) -> (Vec<f64>, Vec<f64>) {
        let mut out = self.columns_with(rows, 2, |r| {
            let (a, b) = raw(r);
            alloc::vec![a, b]
        });
        let b = out.pop().unwrap_or_default();
        let a = out.pop().unwrap_or_default();
        (a, b)
    }

    /// As [`Dataset::column`] for `nc` signals built together by `raw` (one pass over each
    /// record; `raw` returns `nc` signals of the record's length).
    ///
    /// The records are taken two at a time and their signals filtered two at a time, across
    /// the records too ([`filt_many`]): a column of two logs costs one lockstep pass instead of
    /// two passes of a recursion that leaves the core mostly idle. The values are those of each
    /// signal filtered alone.
    pub fn columns_with(
        &self,
        rows: &Rows,
        nc: usize,
        raw: impl Fn(&RecData) -> Vec<Vec<f64>>,
    ) -> Vec<Vec<f64>> {
        let mut out: Vec<Vec<f64>> = (0..nc).map(|_| Vec::with_capacity(rows.len())).collect();
        // The runs of consecutive rows on one record: (record, first row, end row).
        let mut runs: Vec<(usize, usize, usize)> = Vec::new();
        for (i, &ri) in rows.rec.iter().enumerate() {
            match runs.last_mut() {
                Some((r, _, end)) if *r == ri => *end = i + 1,
                _ => runs.push((ri, i, i + 1)),
            }
        }
        for two in runs.chunks(2) {
            let mut signals: Vec<(&ZeroPhase, Vec<f64>)> = Vec::with_capacity(2 * nc);
            for &(ri, _, _) in two {
                let r = &self.recs[ri];
                let mut made = raw(r);
                made.resize_with(nc, Vec::new);
                signals.extend(made.into_iter().map(|c| (&r.filter, c)));
            }
            let filtered = filt_many(signals);
            for (j, &(_, from, to)) in two.iter().enumerate() {
                for (c, o) in out.iter_mut().enumerate() {
                    let Some(s) = filtered.get(j * nc + c) else {
                        continue;
                    };
                    o.extend(
                        rows.k[from..to]
                            .iter()
                            .map(|&k| s.get(k).copied().unwrap_or(0.0)),
                    );
                }
            }
        }
        out
    }
}

/// Each signal filtered by its filter, in order: four at a time where four neighbours share a
/// filter and a length, else two, else alone ([`ZeroPhase::apply_lanes`]: the values of each
/// filtered alone; a filter's recursion alone leaves most of a core idle).
fn filt_many(signals: Vec<(&ZeroPhase, Vec<f64>)>) -> Vec<Vec<f64>> {
    let mut out = Vec::with_capacity(signals.len());
    let mut i = 0;
    while let Some((f, a)) = signals.get(i) {
        let like = |j: usize| {
            signals
                .get(j)
                .filter(|(g, b)| *g == *f && b.len() == a.len())
                .map(|(_, b)| &b[..])
        };
        if let (Some(b), Some(c), Some(d)) = (like(i + 1), like(i + 2), like(i + 3)) {
            if let Some(four) = f.apply_lanes([&a[..], b, c, d]) {
                out.extend(four);
                i += 4;
                continue;
            }
        }
        if let Some(b) = like(i + 1) {
            if let Some(two) = f.apply_lanes([&a[..], b]) {
                out.extend(two);
                i += 2;
                continue;
            }
        }
        out.push(f.apply(a));
        i += 1;
    }
    out
}

/// Windows of `records` for the searches ([`Dataset::search_set`]), `None` when the records hold
/// at most [`SEARCH_MAX_SAMPLES`]: every record is cut in windows of [`SEARCH_WINDOW_S`] (at its
/// sample period `dt_s`), and as many windows as fit in the budget are taken, spread evenly over
/// all of them (over the records and along each).
fn search_windows(records: &[Record], dt_s: impl Iterator<Item = f64>) -> Option<Vec<Record>> {
    let total: usize = records.iter().map(Record::len).sum();
    if total <= SEARCH_MAX_SAMPLES {
        return None;
    }
    let mut tiles: Vec<(usize, usize, usize)> = Vec::new();
    for (ri, (r, dt)) in records.iter().zip(dt_s).enumerate() {
        let n = r.len();
        let w = ((SEARCH_WINDOW_S / dt) as usize).max(200);
        let mut a = 0;
        while a < n {
            let b = (a + w).min(n);
            // A short tail joins nothing: it holds too few rows past the filter's edges.
            if b - a >= w / 2 || (a == 0 && b - a >= 50) {
                tiles.push((ri, a, b));
            }
            a = b;
        }
    }
    let longest = tiles.iter().map(|t| t.2 - t.1).max()?;
    let take = (SEARCH_MAX_SAMPLES / longest).max(1);
    if take >= tiles.len() {
        return None;
    }
    Some(
        (0..take)
            .map(|j| {
                let (ri, a, b) = tiles[j * tiles.len() / take + tiles.len() / (2 * take)];
                slice(&records[ri], a, b)
            })
            .collect(),
    )
}

/// Rows `a..b` of a record.
fn slice(r: &Record, a: usize, b: usize) -> Record {
    let cut = |v: &Option<Vec<f64>>| v.as_ref().map(|v| v[a..b].to_vec());
    Record {
        source: r.source.clone(),
        time_s: r.time_s[a..b].to_vec(),
        u_v: cut(&r.u_v),
        theta_l_rad: cut(&r.theta_l_rad),
        theta_m_rad: cut(&r.theta_m_rad),
        omega_l_rad_s: cut(&r.omega_l_rad_s),
        omega_m_rad_s: cut(&r.omega_m_rad_s),
        i_a_a: cut(&r.i_a_a),
        ref_rad: cut(&r.ref_rad),
        enable: cut(&r.enable),
        i_ref_a: cut(&r.i_ref_a),
        duty: cut(&r.duty),
        v_supply_v: cut(&r.v_supply_v),
    }
}

fn prepare(
    r: &Record,
    params: &PlantParams,
    opts: &FitOptions,
    centre_counts: bool,
) -> Result<RecData, FitError> {
    let n = r.len();
    let src = r.source.clone();
    if n < 50 {
        return Err(FitError::NoData(alloc::format!("{src}: only {n} samples")));
    }
    let dt = r.sample_period_s();
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(FitError::BadRecord(alloc::format!(
            "{src}: time_s is not increasing"
        )));
    }
    let has_u = r.u_v.is_some();
    if !has_u && r.i_a_a.is_none() {
        return Err(FitError::BadRecord(alloc::format!(
            "{src}: neither the input voltage u nor the armature current i_a is logged; the fit needs one of them"
        )));
    }
    let u = r.u_v.clone().unwrap_or_else(|| alloc::vec![0.0; n]);
    let angle_is_load = r.theta_m_rad.is_none() && r.theta_l_rad.is_some();
    let theta_m: Vec<f64> = if let Some(t) = &r.theta_m_rad {
        t.clone()
    } else if let Some(t) = &r.theta_l_rad {
        t.iter().map(|v| v * params.n).collect()
    } else if let Some(w) = r.omega_m_rad_s.as_ref().or(r.omega_l_rad_s.as_ref()) {
        let scale = if r.omega_m_rad_s.is_some() {
            1.0
        } else {
            params.n
        };
        let mut acc = 0.0;
        w.iter()
            .map(|v| {
                let x = acc;
                acc += v * scale * dt;
                x
            })
            .collect()
    } else {
        return Err(FitError::BadRecord(alloc::format!(
            "{src}: neither a position nor a speed is logged"
        )));
    };
    // An encoder reads floor(theta / q) q: during motion its reading lies q/2 below the angle on
    // average. The centre of the count cell is the unbiased estimate; without it a position-
    // periodic torque (a magnetic detent, h = 12, 4096 counts/rev, N = 14) is fitted 0.13 rad out of
    // phase and a simulation started from a reading starts half a count behind.
    let angle_logged = r.theta_m_rad.is_some() || r.theta_l_rad.is_some();
    let mut theta_m = theta_m;
    if angle_logged && centre_counts {
        if let Some(q) = crate::signal::quantum::encoder_quantum(&theta_m) {
            for v in theta_m.iter_mut() {
                *v += 0.5 * q;
            }
        }
    }
    for (name, sig) in [("u", &u), ("theta", &theta_m)] {
        if let Some(k) = sig.iter().position(|v| !v.is_finite()) {
            return Err(FitError::BadRecord(alloc::format!(
                "{src}: {name} is not finite at row {k}"
            )));
        }
    }
    // A cut-off beyond the filter's range (the light one is 3x the user's) is clamped into it.
    let filter = ZeroPhase::clamped(opts.filter_hz, dt);
    let light = ZeroPhase::clamped(opts.filter_hz * 3.0, dt);
    if let Some(k) = r
        .i_a_a
        .as_ref()
        .and_then(|i| i.iter().position(|v| !v.is_finite()))
    {
        return Err(FitError::BadRecord(alloc::format!(
            "{src}: i_a is not finite at row {k}"
        )));
    }
    let tau_e = params.t_drv() + params.l_a / params.r_eq();
    // Two independent halves (on two threads when a core is idle, the same values either way):
    // the motion and the torque current that needs its acceleration; the light speed, the
    // filtered current and the motor angle's phasor.
    let ((omega_f, accel_f, i_torque_f), (omega_raw, i_filtered, motor_phasor)) = crate::par::join(
        || {
            let omega_f = filter.derivative(&theta_m);
            let accel_f = derivative(&omega_f, dt);
            let t = r.i_a_a.as_ref().map(|i| {
                torque_current_f(&filter, i, &accel_f, dt, tau_e, params.k_e / params.r_eq())
            });
            (omega_f, accel_f, t)
        },
        || {
            let omega_raw = light.derivative(&theta_m);
            let f = r.i_a_a.as_ref().map(|i| {
                let f = filter.apply(i);
                let d = derivative(&f, dt);
                (f, d)
            });
            let phasor: Vec<[f64; 2]> = theta_m
                .iter()
                .map(|&t| [math::cos(t), math::sin(t)])
                .collect();
            (omega_raw, f, phasor)
        },
    );
    let i_raw = r.i_a_a.clone();
    let (i_f, di_f) = match i_filtered {
        Some((f, d)) => (Some(f), Some(d)),
        None => (None, None),
    };
    Ok(RecData {
        source: src,
        dt_s: dt,
        time_s: r.time_s.clone(),
        u_v: u,
        has_u,
        motor_phasor,
        theta_m_rad: theta_m,
        angle_is_load,
        omega_raw,
        omega_f,
        accel_f,
        i_raw,
        i_f,
        di_f,
        i_torque_f,
        filter,
    })
}

/// The mean armature current over the sample centred on each row [A], filtered with `filter`:
/// [`centred_current`] plus the back-EMF drift w (k_e/R_eq) alpha_m dt, with `k_e_over_r`
/// [A s/rad] and the motor acceleration `accel_f` [rad/s^2] already filtered (the filter is linear: adding it after filtering the current is the same as
/// filtering the sum).
pub fn torque_current_f(
    filter: &ZeroPhase,
    i: &[f64],
    accel_f: &[f64],
    dt_s: f64,
    tau_s: f64,
    k_e_over_r: f64,
) -> Vec<f64> {
    let c = filter.apply(&centred_current(i, dt_s, tau_s));
    let w = centring_weight(dt_s, tau_s) * k_e_over_r * dt_s;
    c.iter().zip(accel_f).map(|(c, a)| c + w * a).collect()
}

/// Weight of the next sample in the mean armature current over the sample centred on a row, for
/// a zero-order-hold input with period `dt_s` [s] and electrical time constant `tau_s` [s]
/// (driver lag plus L_a / R_eq): w = (1 - (2 tau/dt)(1 - exp(-dt/(2 tau)))) / 2. 0.32 for the
/// SRV-02 at 1 kHz (tau = 0.19 ms), 1/2 for an instantaneous current, 0 for a slow one.
pub fn centring_weight(dt_s: f64, tau_s: f64) -> f64 {
    if tau_s > 0.0 {
        let x = dt_s / (2.0 * tau_s);
        0.5 * (1.0 - (1.0 - math::exp(-x)) / x)
    } else {
        0.5
    }
}

/// The step part of the mean armature current over the sample centred on each row [A], from
/// point samples `i` taken at the end of each hold period (the log convention), period `dt_s` [s]
/// and electrical time constant `tau_s` [s]: i[k] + w (i[k+1] - i[k]) ([`centring_weight`]).
///
/// After an input update at t_k the current moves from i[k] towards its new level with time
/// constant tau, while the back-EMF makes that level drift by -(k_e/R_eq) alpha_m per second;
/// the full mean adds w (k_e/R_eq) alpha_m dt ([`torque_current_f`]). The motion (speed,
/// acceleration by central differences) is centred on t_k, so the torque balance must use this
/// mean, not the point sample: with the point sample the current lags the motion and, on exact
/// simulated states, J_eq comes out 0.85 % low and B_eq 1.7 % high; with the step part alone
/// B_eq is right and J_eq still 0.85 % low (the drift term).
pub fn centred_current(i: &[f64], dt_s: f64, tau_s: f64) -> Vec<f64> {
    let w = centring_weight(dt_s, tau_s);
    let n = i.len();
    (0..n)
        .map(|k| {
            let next = i[(k + 1).min(n.saturating_sub(1))];
            i[k] + w * (next - i[k])
        })
        .collect()
}

/// The speed [rad/s, motor side] below which a sample of these records counts as stuck: what the
/// rig's encoder can resolve through the fit's filter, 2 q f_c for a motor-side count q [rad]
/// and cut-off f_c [Hz] (a count per half period of the filter), and at least 1 % of the rig's
/// running speed (the 95th percentile of |omega_m|), both taken from the logs; never above
/// [`FitOptions::min_speed_rad_s`] (the bound; 1 rad/s by default, what 2 q f_c gives on the
/// handout's SRV-02: 4096 counts per load revolution, N = 14, 25 Hz). A smart servo seen at its
/// output (N = 1, 4096 counts, a few rad/s) gets 0.08 rad/s; a rig whose speed the bound
/// already resolves (the SRV-02) keeps it, and selects the rows it always did.
pub fn rig_stuck_speed_rad_s(recs: &[RecData], opts: &FitOptions) -> f64 {
    let bound = opts.min_speed_rad_s;
    let mut floor = 0.0f64;
    let mut speeds: Vec<f64> = Vec::new();
    for r in recs {
        if let Some(q) = crate::signal::quantum::encoder_quantum(&r.theta_m_rad) {
            floor = floor.max(2.0 * q * opts.filter_hz);
        }
        speeds.extend(r.omega_f.iter().map(|w| w.abs()));
    }
    let at = (0.95 * speeds.len() as f64) as usize;
    let w95 = math::order_statistic(&mut speeds, at).unwrap_or(0.0);
    let t = floor.max(0.01 * w95);
    if t > 0.0 && t.is_finite() {
        t.min(bound)
    } else {
        bound
    }
}

/// Samples at either end of record `r` that no balance uses (the zero-phase filter's edge:
/// two periods of its cut-off, and two more).
pub fn edge_samples(r: &RecData, opts: &FitOptions) -> usize {
    libm::ceil((2.0 / opts.filter_hz) * (1.0 / r.dt_s)) as usize + 2
}

fn select_rows(ri: usize, r: &RecData, opts: &FitOptions, mech: &mut Rows, elec: &mut Rows) {
    let n = r.omega_f.len();
    let fs = 1.0 / r.dt_s;
    let edge = edge_samples(r, opts);
    let dec = (math::floor(fs / (4.0 * opts.filter_hz)) as usize).max(1);
    let margin = libm::ceil(opts.margin_s * fs) as usize;
    // Stuck samples, dilated by the margin.
    let mut near_stuck = alloc::vec![false; n];
    let mut last_stuck: Option<usize> = None;
    for (k, flag) in near_stuck.iter_mut().enumerate() {
        if r.omega_f[k].abs() < opts.min_speed_rad_s
            || r.omega_raw[k].abs() < 0.5 * opts.min_speed_rad_s
        {
            last_stuck = Some(k);
        }
        if let Some(s) = last_stuck {
            if k - s <= margin {
                *flag = true;
            }
        }
    }
    let mut next_stuck: Option<usize> = None;
    for k in (0..n).rev() {
        if r.omega_f[k].abs() < opts.min_speed_rad_s
            || r.omega_raw[k].abs() < 0.5 * opts.min_speed_rad_s
        {
            next_stuck = Some(k);
        }
        if let Some(s) = next_stuck {
            if s - k <= margin {
                near_stuck[k] = true;
            }
        }
    }
    let (near_rev, near_irev) = reversal_windows(r, opts);
    let presliding = presliding(r, opts.presliding_counts, opts.min_speed_rad_s);
    // Fit / held-out blocks: the record is cut in blocks of `holdout_block_s`; every
    // `holdout_every`-th block is held out.
    let block = ((opts.holdout_block_s * fs) as usize).max(1);
    let mut k = edge;
    while k + edge < n {
        let b = k / block;
        let fit = opts.holdout_every == 0 || b % opts.holdout_every != opts.holdout_every - 1;
        if !near_stuck[k] && !presliding[k] {
            mech.rec.push(ri);
            mech.k.push(k);
            mech.fit.push(fit);
            mech.gap_crossing.push(near_irev[k]);
        }
        if r.has_u && !near_rev[k] {
            elec.rec.push(ri);
            elec.k.push(k);
            elec.fit.push(fit);
            elec.torque_reversal.push(near_irev[k]);
        }
        k += dec;
    }
}

/// Windows of 50 ms either side of the reversals of record `r` while the angle measured is the
/// load's (all false otherwise): (velocity reversals: sign changes of the filtered speed between
/// samples moving faster than `opts.min_speed_rad_s`; torque reversals: sign changes of the
/// filtered current, when logged). With a gear play the motor leaves one flank for the other
/// there while the load coasts on, so its speed is not the measured one: the electrical balance
/// (which uses it) keeps away from the velocity reversals, and a play's rows are flagged at the
/// torque reversals.
pub fn reversal_windows(r: &RecData, opts: &FitOptions) -> (Vec<bool>, Vec<bool>) {
    let n = r.omega_f.len();
    let win = libm::ceil(0.05 * (1.0 / r.dt_s)) as usize;
    let velocity = if r.angle_is_load {
        sign_change_windows(&r.omega_f, opts.min_speed_rad_s, win)
    } else {
        alloc::vec![false; n]
    };
    let torque = match (r.angle_is_load, r.i_f.as_ref()) {
        (true, Some(i)) => sign_change_windows(i, 0.0, win),
        _ => alloc::vec![false; n],
    };
    (velocity, torque)
}

/// True within `win` samples of every sign change of `x` between two samples with |x| >
/// `min_abs` (from `win` before the last sample of the old sign to `win` after the first of the
/// new one).
fn sign_change_windows(x: &[f64], min_abs: f64, win: usize) -> Vec<bool> {
    let n = x.len();
    let mut out = alloc::vec![false; n];
    let mut last: Option<(usize, f64)> = None;
    for (k, &v) in x.iter().enumerate() {
        if v.abs() > min_abs {
            let s = math::sign(v);
            if let Some((k0, s0)) = last {
                if s0 != s {
                    for f in out
                        .iter_mut()
                        .take((k + win).min(n))
                        .skip(k0.saturating_sub(win))
                    {
                        *f = true;
                    }
                }
            }
            last = Some((k, s));
        }
    }
    out
}

/// Travel of the motor angle since the last reversal of the motion of record `r`, in encoder
/// counts, at every sample (infinite before the first reversal, and when the angle is not
/// quantised). A reversal is a sign change of the filtered speed between two samples moving
/// faster than the stuck threshold `stuck_rad_s` [rad/s]; the turning point is the extreme angle
/// reached before it.
pub fn travel_counts(r: &RecData, stuck_rad_s: f64) -> Vec<f64> {
    let n = r.omega_f.len();
    let mut out = alloc::vec![f64::INFINITY; n];
    let Some(q) = crate::signal::quantum::encoder_quantum(&r.theta_m_rad).filter(|q| *q > 0.0)
    else {
        return out;
    };
    let mut last_sign = 0.0;
    let mut turn: Option<f64> = None;
    let mut extreme = r.theta_m_rad.first().copied().unwrap_or(0.0);
    for (k, o) in out.iter_mut().enumerate() {
        let w = r.omega_f[k];
        let th = r.theta_m_rad[k];
        if w.abs() > stuck_rad_s {
            let s = math::sign(w);
            if last_sign != 0.0 && s != last_sign {
                turn = Some(extreme);
            }
            last_sign = s;
        }
        // The extreme reached in the current direction so far (the turning point once the
        // direction changes).
        if last_sign == 0.0 || (th - extreme) * last_sign > 0.0 {
            extreme = th;
        }
        if let Some(t0) = turn {
            *o = (th - t0).abs() / q;
        }
    }
    out
}

/// The pre-sliding rows of record `r`: the travel since the last reversal of the motion is below
/// `counts` encoder counts ([`travel_counts`]). After a reversal a dynamic friction's bristles
/// wind up from one side's level to the other's over a travel of about twice the breakaway
/// torque over their stiffness: the friction there is a spring torque, not the sliding curve.
/// All false when `counts` is 0 or the angle is not quantised.
pub fn presliding(r: &RecData, counts: f64, stuck_rad_s: f64) -> Vec<bool> {
    if counts.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
        return alloc::vec![false; r.omega_f.len()];
    }
    travel_counts(r, stuck_rad_s)
        .into_iter()
        .map(|t| t < counts)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shift_hold_follows_the_log_convention() {
        let u = [0.0, 1.0, 2.0, 3.0, 4.0];
        let s = shift_hold(&u, 0.0);
        assert!((s[2] - 1.5).abs() < 1e-12);
        let s = shift_hold(&u, 1.0);
        assert!((s[3] - 1.5).abs() < 1e-12);
        let s = shift_hold(&u, 0.25);
        assert!((s[2] - 1.25).abs() < 1e-12);
    }
}
