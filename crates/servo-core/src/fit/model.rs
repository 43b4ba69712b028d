//! Assembly and solution of the equations of one model configuration (every nonlinear parameter
//! fixed): torque balance (current logged), electrical balance (current logged) or the u-driven
//! combined equation (no current). Linear parameters by constrained least squares.

use super::dataset::{Dataset, RecData, Rows};
use super::lsq::{self, Sign};
use crate::effects::{CoefSign, EffectKind, Sample, SimRole, MAX_PARAMS};
use crate::math;
use crate::plant::Plant;
use alloc::vec::Vec;

/// The equations servo fits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Equation {
    /// k_t i_a = J_eq dw_m/dt + B_eq w_m + friction/N + tau_motor_side + tau_load_side/N (current
    /// logged) [N m].
    Torque,
    /// k_drv u_in = R_eq i_a + k_e w_m with u_in seen through the driver and armature lags,
    /// written per unit k_drv (current logged) [V].
    Electrical,
    /// k_drv k_t u_in / R_eq = J_eq dw_m/dt + (B_eq + k_t k_e / R_eq) w_m + friction/N + ... (no
    /// current logged) [N m].
    Combined,
}

impl Equation {
    pub const fn name(self) -> &'static str {
        match self {
            Equation::Torque => "torque balance",
            Equation::Electrical => "electrical balance",
            Equation::Combined => "u-driven torque balance",
        }
    }
    pub const fn unit(self) -> &'static str {
        match self {
            Equation::Electrical => "V",
            _ => "N m",
        }
    }
}

/// An effect of the configuration with the parameters to fit marked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slot {
    pub kind: EffectKind,
    pub values: [f64; MAX_PARAMS],
    pub fit: [bool; MAX_PARAMS],
}

impl Slot {
    pub fn get(&self, key: &str) -> f64 {
        self.kind
            .params()
            .iter()
            .position(|p| p.key == key)
            .map_or(f64::NAN, |i| self.values[i])
    }
    pub fn set(&mut self, key: &str, v: f64) {
        if let Some(i) = self.kind.params().iter().position(|p| p.key == key) {
            self.values[i] = v;
        }
    }
    /// The values in parameter order.
    pub fn param_values(&self) -> &[f64] {
        &self.values[..self.kind.params().len()]
    }
    /// True when every value is set (not NaN).
    pub fn values_set(&self) -> bool {
        self.param_values().iter().all(|v| !v.is_nan())
    }
    /// True when every nonlinear parameter is finite (the regressors can be built).
    pub fn nonlinear_set(&self) -> bool {
        self.kind
            .params()
            .iter()
            .zip(self.param_values())
            .all(|(p, v)| !p.nonlinear || v.is_finite())
    }
    pub fn fits(&self, key: &str) -> bool {
        self.kind
            .params()
            .iter()
            .position(|p| p.key == key)
            .is_some_and(|i| self.fit[i])
    }
}

/// What a column's coefficient means.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Coef {
    JEq,
    BEq,
    TauSf,
    AsymPos(usize),
    AsymNeg(usize),
    /// Linear coefficient j of the effect of slot i ([`crate::effects::EffectModel::regressor`]).
    Effect(usize, usize),
    /// R_eq / k_drv.
    ROverK,
    /// k_e / k_drv.
    KeOverK,
    /// Parameter `.1` of user effect `.0` (index among the plant's user effects).
    Custom(usize, usize),
}

/// The fit of one equation.
#[derive(Debug, Clone)]
pub struct EqSolution {
    pub equation: Equation,
    pub coefs: Vec<Coef>,
    pub theta: Vec<f64>,
    /// Standard errors with the residuals taken as white (0 for fixed coefficients).
    pub std_err: Vec<f64>,
    /// Standard errors robust to correlated residuals ([`super::lsq::LsSolution::std_err_robust`]).
    pub std_err_robust: Vec<f64>,
    /// Residual at every row of the equation (fit and held out).
    pub resid: Vec<f64>,
    /// Residual sum of squares on fit rows / held-out rows, and their counts.
    pub rss_fit: f64,
    pub rss_hold: f64,
    pub n_fit: usize,
    pub n_hold: usize,
    /// Free coefficients estimated.
    pub p: usize,
}

impl EqSolution {
    pub fn coef(&self, c: Coef) -> Option<(f64, f64)> {
        self.coefs
            .iter()
            .position(|&q| q == c)
            .map(|i| (self.theta[i], self.std_err[i]))
    }
    /// RMS of the residual on every row.
    pub fn rms(&self) -> f64 {
        let n = (self.n_fit + self.n_hold).max(1);
        math::sqrt((self.rss_fit + self.rss_hold) / n as f64)
    }
}

struct Term {
    col: Vec<f64>,
    coef: Coef,
    sign: Sign,
    /// Value when the coefficient is not fitted.
    fixed: Option<f64>,
}

/// A model configuration: the base plant, its effects as slots, whether to refit the base.
#[derive(Debug, Clone)]
pub struct Config {
    pub base: Plant,
    pub slots: Vec<Slot>,
    pub refit_base: bool,
}

impl Config {
    pub fn slot(&self, kind: EffectKind) -> Option<&Slot> {
        self.slots.iter().find(|s| s.kind == kind)
    }
    pub fn has(&self, kind: EffectKind) -> bool {
        self.slot(kind).is_some()
    }
    /// Input transformation of the configuration: its input maps (effects of role
    /// [`SimRole::InputMap`] whose values are all set) in increasing order.
    fn input_transform(&self) -> impl Fn(f64) -> f64 {
        let mut maps: Vec<(u8, &Slot)> = self
            .slots
            .iter()
            .filter_map(|s| match s.kind.sim_role() {
                SimRole::InputMap { order } if s.values_set() => Some((order, s)),
                _ => None,
            })
            .collect();
        maps.sort_by_key(|m| m.0);
        let maps: Vec<(&'static dyn crate::effects::EffectModel, Slot)> = maps
            .into_iter()
            .map(|(_, s)| (s.kind.model(), *s))
            .collect();
        let custom = self.base.custom;
        let input = custom.has(crate::custom::ActsOn::Input);
        move |u| {
            let u = maps
                .iter()
                .fold(u, |u, (m, s)| m.input_v(s.param_values(), u));
            // Then the user's input effects (which see u only here; see crate::fit::custom).
            if input {
                custom.input(&[0.0, 0.0, 0.0, 0.0, 0.0, u, 0.0])
            } else {
                u
            }
        }
    }
    fn delay_s(&self) -> f64 {
        self.slots
            .iter()
            .find(|s| s.kind.sim_role() == SimRole::InputDelay)
            .map(|s| s.kind.model().input_delay_s(s.param_values()))
            .filter(|v| v.is_finite())
            .unwrap_or(0.0)
    }
    /// Equation of an effect kind.
    pub fn equation_of(kind: EffectKind, has_current: bool) -> Equation {
        match (kind.is_mechanical(), has_current) {
            (_, false) => Equation::Combined,
            (true, true) => Equation::Torque,
            (false, true) => Equation::Electrical,
        }
    }
}

/// The current of the torque balance at `rows` [A]: the mean over the sample centred on each
/// row ([`super::dataset::centred_current`]). An input delay d moves the current's transitions
/// to d mod T_s after each update; the mean then sees a lag of tau + (d mod T_s).
fn torque_current(ds: &Dataset, cfg: &Config, rows: &super::dataset::Rows) -> Vec<f64> {
    let d = cfg.delay_s();
    if d <= 0.0 {
        return ds.sample(rows, |r| r.i_torque_f.as_deref().unwrap_or(&[]));
    }
    let p = &cfg.base.params;
    let tau = p.t_drv() + p.l_a / p.r_eq();
    let ke_r = p.k_e / p.r_eq();
    let mut out = Vec::with_capacity(rows.len());
    let mut cur: Option<(usize, Vec<f64>)> = None;
    for (&ri, &k) in rows.rec.iter().zip(&rows.k) {
        if cur.as_ref().map(|(c, _)| *c) != Some(ri) {
            let r = &ds.recs[ri];
            let s = d - math::floor(d / r.dt_s) * r.dt_s;
            let col = match &r.i_raw {
                Some(i) => super::dataset::torque_current_f(
                    &r.filter,
                    i,
                    &r.accel_f,
                    r.dt_s,
                    tau + s,
                    ke_r,
                ),
                None => Vec::new(),
            };
            cur = Some((ri, col));
        }
        if let Some((_, c)) = &cur {
            out.push(c.get(k).copied().unwrap_or(0.0));
        }
    }
    out
}

/// Which of the fit rows a solution uses: all, the first or second half of them in time order,
/// or the slower or faster half by motor speed (the halves' disagreement is folded into the
/// printed intervals).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Half {
    All,
    First,
    Second,
    Slow,
    Fast,
}

/// Solves the mechanical (torque or combined) equation of `cfg`.
pub fn solve_mech(ds: &Dataset, cfg: &Config) -> Option<EqSolution> {
    solve_mech_on(ds, cfg, Half::All)
}

/// [`solve_mech`] on `half` of the fit rows.
pub fn solve_mech_on(ds: &Dataset, cfg: &Config, half: Half) -> Option<EqSolution> {
    let rows = &ds.mech_rows;
    let p = &cfg.base.params;
    let n = p.n;
    let mut terms: Vec<Term> = Vec::new();
    let base_fixed = |v: f64| if cfg.refit_base { None } else { Some(v) };
    terms.push(Term {
        col: ds.sample(rows, |r| &r.accel_f),
        coef: Coef::JEq,
        sign: Sign::NonNegative,
        fixed: base_fixed(p.j_eq()),
    });
    terms.push(Term {
        col: ds.sample(rows, |r| &r.omega_f),
        coef: Coef::BEq,
        sign: Sign::NonNegative,
        fixed: base_fixed(cfg.base.b_eq()),
    });
    let asym = cfg
        .slots
        .iter()
        .position(|s| s.kind == EffectKind::Asymmetry);
    let coulomb_col = || ds.coulomb_col.clone();
    if asym.is_none() && cfg.base.effects.contains(EffectKind::Coulomb) {
        terms.push(Term {
            col: coulomb_col(),
            coef: Coef::TauSf,
            sign: Sign::NonNegative,
            fixed: base_fixed(cfg.base.tau_sf()),
        });
    }
    for (si, s) in cfg.slots.iter().enumerate() {
        match s.kind {
            EffectKind::Coulomb if asym.is_none() => {
                let fixed = if s.fit[0] { None } else { Some(s.values[0]) };
                terms.push(Term {
                    col: coulomb_col(),
                    coef: Coef::TauSf,
                    sign: Sign::NonNegative,
                    fixed,
                });
            }
            EffectKind::Asymmetry => {
                let pos = ds.column(rows, |r: &RecData| {
                    r.omega_raw
                        .iter()
                        .map(|&w| if w > 0.0 { 1.0 / n } else { 0.0 })
                        .collect()
                });
                let neg = ds.column(rows, |r: &RecData| {
                    r.omega_raw
                        .iter()
                        .map(|&w| if w < 0.0 { -1.0 / n } else { 0.0 })
                        .collect()
                });
                terms.push(Term {
                    col: pos,
                    coef: Coef::AsymPos(si),
                    sign: Sign::NonNegative,
                    fixed: if s.fit[0] { None } else { Some(s.values[0]) },
                });
                terms.push(Term {
                    col: neg,
                    coef: Coef::AsymNeg(si),
                    sign: Sign::NonNegative,
                    fixed: if s.fit[1] { None } else { Some(s.values[1]) },
                });
            }
            _ => push_effect_terms(ds, rows, cfg, si, s, &mut terms),
        }
    }
    for c in crate::fit::custom_columns::torque_columns(ds, &cfg.base, rows) {
        terms.push(Term {
            col: c.col,
            coef: Coef::Custom(c.slot, c.param.unwrap_or(usize::MAX)),
            sign: if c.non_negative {
                Sign::NonNegative
            } else {
                Sign::Free
            },
            fixed: if c.param.is_none() { Some(1.0) } else { None },
        });
    }
    let (equation, y) = if ds.has_current {
        (
            Equation::Torque,
            torque_current(ds, cfg, rows)
                .into_iter()
                .map(|i| p.k_t * i)
                .collect(),
        )
    } else {
        let r_eq = p.r_eq();
        let g = p.k_drv * p.k_t / r_eq;
        let shift = cfg.delay_s() + p.t_drv() + p.l_a / r_eq;
        let tr = cfg.input_transform();
        let useen = ds.column(rows, |r: &RecData| r.input_seen(&tr, shift));
        let w = ds.sample(rows, |r| &r.omega_f);
        let y: Vec<f64> = useen
            .iter()
            .zip(&w)
            .map(|(u, w)| g * u - p.k_t * p.k_e / r_eq * w)
            .collect();
        (Equation::Combined, y)
    };
    let (mut y, mut terms) = (y, terms);
    mask_gap_crossings(cfg, rows, &mut y, &mut terms);
    solve_terms(equation, rows, y, terms, half)
}

/// With a gear play in the model, the rigid-body torque balance does not hold while the motor
/// crosses the gap (the load coasts, the motor speed is not the measured one): the rows near a
/// reversal of the motor torque ([`Rows::gap_crossing`], load angle measured) get no weight.
/// Effects fitted beside a gear play (a breakaway friction, which lives at the same low speeds
/// as the reversals) are then sized on the motion the rigid balance describes.
fn mask_gap_crossings(cfg: &Config, rows: &Rows, y: &mut [f64], terms: &mut [Term]) {
    if !cfg
        .slots
        .iter()
        .any(|s| s.kind.sim_role() == SimRole::Contact)
    {
        return;
    }
    for (i, &u) in rows.gap_crossing.iter().enumerate() {
        if u {
            if let Some(v) = y.get_mut(i) {
                *v = 0.0;
            }
            for t in terms.iter_mut() {
                if let Some(c) = t.col.get_mut(i) {
                    *c = 0.0;
                }
            }
        }
    }
}

/// The regressors of the linear coefficients of slot `si` ([`crate::effects::EffectModel`]:
/// `linear_coefs`, `regressors`, `coefs_fitted`, `coef_from_values`), all built in one pass over
/// each record and filtered like every column.
fn push_effect_terms(
    ds: &Dataset,
    rows: &Rows,
    cfg: &Config,
    si: usize,
    s: &Slot,
    terms: &mut Vec<Term>,
) {
    let m = s.kind.model();
    let nc = m.linear_coefs();
    if nc == 0 || !s.nonlinear_set() {
        return;
    }
    let v = s.param_values();
    let fitted = m.coefs_fitted(&s.fit[..v.len()]);
    let n = cfg.base.params.n;
    let filter_hz = ds.opts.filter_hz;
    let tau_sf = cfg_tau_sf(cfg);
    let cols = ds.columns_with(rows, nc, |r: &RecData| {
        let len = r.theta_m_rad.len();
        let mut raw = alloc::vec![alloc::vec![0.0; len]; nc];
        let mut out = alloc::vec![0.0; nc];
        for k in 0..len {
            let u = r.u_v.get(k).copied().unwrap_or(0.0);
            let x = Sample {
                omega_m_rad_s: r.omega_raw[k],
                theta_m_rad: r.theta_m_rad[k],
                motor_phasor: r.motor_phasor[k],
                u_v: u,
                u_prev_v: k
                    .checked_sub(1)
                    .and_then(|i| r.u_v.get(i))
                    .copied()
                    .unwrap_or(u),
                n,
                filter_hz,
            };
            m.regressors(v, &x, &mut out);
            for (col, o) in raw.iter_mut().zip(&out) {
                col[k] = *o;
            }
        }
        raw
    });
    for (j, col) in cols.into_iter().enumerate() {
        terms.push(Term {
            col,
            coef: Coef::Effect(si, j),
            sign: match m.coef_sign(j) {
                CoefSign::NonNegative => Sign::NonNegative,
                CoefSign::Free => Sign::Free,
            },
            fixed: if fitted {
                None
            } else {
                Some(m.coef_from_values(v, j, tau_sf))
            },
        });
    }
}

fn cfg_tau_sf(cfg: &Config) -> f64 {
    cfg.slot(EffectKind::Coulomb)
        .map(|s| s.values[0])
        .filter(|v| v.is_finite())
        .unwrap_or(cfg.base.tau_sf())
}

/// The electrical balance's residual at every sample of record `r` [V, at the amplifier input]:
/// the input through `cfg`'s input maps, delay and lags, filtered (as [`solve_elec`] takes it) less
/// (R / k_drv) i_a and (k_e / k_drv) omega_m with the parameters `p` and the motor speed as
/// measured (from the load angle when that is what the encoder reads). `None` without the
/// current or the input in `r`.
pub fn electrical_residual(
    cfg: &Config,
    p: &crate::params::PlantParams,
    r: &RecData,
) -> Option<Vec<f64>> {
    let i = r.i_f.as_ref().filter(|_| r.has_u)?;
    let (delay, lag) = (cfg.delay_s(), p.t_drv() + p.l_a / p.r_eq());
    let y = r.filt(&r.input_point(cfg.input_transform(), delay, lag));
    let (r_k, ke_k) = (p.r_eq() / p.k_drv, p.k_e / p.k_drv);
    Some(
        y.iter()
            .zip(i)
            .zip(&r.omega_f)
            .map(|((y, i), w)| y - r_k * i - ke_k * w)
            .collect(),
    )
}

/// Solves the electrical equation of `cfg` (current logged).
pub fn solve_elec(ds: &Dataset, cfg: &Config) -> Option<EqSolution> {
    solve_elec_on(ds, cfg, Half::All)
}

/// [`solve_elec`] on `half` of the fit rows.
pub fn solve_elec_on(ds: &Dataset, cfg: &Config, half: Half) -> Option<EqSolution> {
    if !ds.has_current {
        return None;
    }
    let rows = &ds.elec_rows;
    let p = &cfg.base.params;
    let (delay, lag) = (cfg.delay_s(), p.t_drv() + p.l_a / p.r_eq());
    let tr = cfg.input_transform();
    let y = ds.column(rows, |r: &RecData| r.input_point(&tr, delay, lag));
    let fixed = |v: f64| if cfg.refit_base { None } else { Some(v) };
    let terms = alloc::vec![
        Term {
            col: ds.sample(rows, |r| r.i_f.as_deref().unwrap_or(&[])),
            coef: Coef::ROverK,
            sign: Sign::NonNegative,
            fixed: fixed(p.r_eq() / p.k_drv),
        },
        Term {
            col: ds.sample(rows, |r| &r.omega_f),
            coef: Coef::KeOverK,
            sign: Sign::NonNegative,
            fixed: fixed(p.k_e / p.k_drv),
        },
    ];
    let (mut y, mut terms) = (y, terms);
    if cfg
        .slots
        .iter()
        .any(|s| s.kind.sim_role() == SimRole::Contact)
    {
        // The motor speed is not the measured one while it crosses the gap: no weight there.
        for (i, &u) in rows.torque_reversal.iter().enumerate() {
            if u {
                y[i] = 0.0;
                for t in terms.iter_mut() {
                    t.col[i] = 0.0;
                }
            }
        }
    }
    solve_terms(Equation::Electrical, rows, y, terms, half)
}

fn solve_terms(
    equation: Equation,
    rows: &Rows,
    mut y: Vec<f64>,
    terms: Vec<Term>,
    half: Half,
) -> Option<EqSolution> {
    for t in &terms {
        if let Some(v) = t.fixed {
            for (yi, c) in y.iter_mut().zip(&t.col) {
                *yi -= v * c;
            }
        }
    }
    let free: Vec<&Term> = terms.iter().filter(|t| t.fixed.is_none()).collect();
    let mut fit_idx: Vec<usize> = (0..rows.len()).filter(|&i| rows.fit[i]).collect();
    let mid = fit_idx.len() / 2;
    match half {
        Half::All => {}
        Half::First => fit_idx.truncate(mid),
        Half::Second => {
            fit_idx.drain(..mid);
        }
        Half::Slow | Half::Fast => {
            // The speed is the viscous (torque) or back-EMF (electrical) column.
            let w = terms
                .iter()
                .find(|t| matches!(t.coef, Coef::BEq | Coef::KeOverK))?;
            let mut speeds: Vec<f64> = fit_idx.iter().map(|&i| w.col[i].abs()).collect();
            speeds.sort_by(f64::total_cmp);
            let median = speeds.get(mid).copied()?;
            let slow = half == Half::Slow;
            fit_idx.retain(|&i| (w.col[i].abs() < median) == slow);
        }
    }
    let cols: Vec<Vec<f64>> = free
        .iter()
        .map(|t| fit_idx.iter().map(|&i| t.col[i]).collect())
        .collect();
    let yfit: Vec<f64> = fit_idx.iter().map(|&i| y[i]).collect();
    let signs: Vec<Sign> = free.iter().map(|t| t.sign).collect();
    let sol = lsq::solve(&cols, &yfit, &signs)?;
    let mut resid = y;
    for (t, th) in free.iter().zip(&sol.theta) {
        for (r, c) in resid.iter_mut().zip(&t.col) {
            *r -= th * c;
        }
    }
    let (mut rss_fit, mut rss_hold, mut n_fit, mut n_hold) = (0.0, 0.0, 0, 0);
    for (r, &f) in resid.iter().zip(&rows.fit) {
        if f {
            rss_fit += r * r;
            n_fit += 1;
        } else {
            rss_hold += r * r;
            n_hold += 1;
        }
    }
    let mut coefs = Vec::new();
    let mut theta = Vec::new();
    let mut std_err = Vec::new();
    let mut std_err_robust = Vec::new();
    let mut fi = 0;
    for t in &terms {
        coefs.push(t.coef);
        match t.fixed {
            Some(v) => {
                theta.push(v);
                std_err.push(0.0);
                std_err_robust.push(0.0);
            }
            None => {
                theta.push(sol.theta[fi]);
                std_err.push(sol.std_err[fi]);
                std_err_robust.push(sol.std_err_robust[fi]);
                fi += 1;
            }
        }
    }
    Some(EqSolution {
        equation,
        coefs,
        theta,
        std_err,
        std_err_robust,
        resid,
        rss_fit,
        rss_hold,
        n_fit,
        n_hold,
        p: sol.p,
    })
}
