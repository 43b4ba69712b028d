//! Fitting a model (base parameters + catalogue effects) to records.
//!
//! Each effect is fitted in the equation where it lives (see [`Equation`]): the torque balance
//! for mechanical effects and the electrical balance for input-side effects when the current is
//! logged, otherwise the u-driven combined equation. Position is filtered once with a zero-phase
//! filter before being differentiated twice, and every regressor goes through the same filter.
//! Linear parameters are estimated by least squares (QR) with their physical signs, nonlinear ones
//! (a speed scale, a harmonic, a dead band, a limit, a delay) by a grid search plus golden-section
//! refinement, always refitting the base parameters (J_eq, B_eq, tau_sf, and R_eq, k_drv where
//! the electrical balance is used) together with the effect. Everything effect-specific (the
//! regressors, the grids, the search hints, what is refined on the simulation) comes from the
//! effect's [`crate::effects::EffectModel`]; an effect without regressors (a gear play) is sized on
//! the output error of short simulations ([`oe`]) by its
//! [`crate::effects::FitHooks::refine_on_simulation`].
//!
//! Entry point: [`fit_model`]. For repeated fits on the same data (diagnosis), prepare a
//! [`Dataset`] once and call [`Dataset::fit`]. User-defined effects are fitted in [`custom`];
//! [`discover`] proposes a new one from a residual no effect explains.

pub mod custom;
mod custom_columns;
pub mod dataset;
pub mod discover;
pub mod lsq;
pub mod model;
pub mod oe;
pub mod search;
pub mod udriven;

pub use dataset::Dataset;
pub use model::Equation;

use crate::effects::{
    Effect, EffectError, EffectKind, GridContext, NoEffectAt, SearchScale, SimRole, MAX_PARAMS,
};
use crate::math;
use crate::plant::Plant;
use crate::record::Record;
use alloc::string::String;
use alloc::vec::Vec;
use model::{Coef, Config, EqSolution, Slot};

/// Options of the fit.
#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    /// Cut-off of the zero-phase low-pass filter applied to every signal [Hz].
    pub filter_hz: f64,
    /// Upper bound of the motor speed below which a sample counts as stuck [rad/s]. A dataset
    /// uses its rig's own threshold ([`dataset::rig_stuck_speed_rad_s`]: the encoder's
    /// resolution through the filter and 1 % of the running speed), at most this; a prepared
    /// [`Dataset`]'s `opts` hold the threshold it used.
    pub min_speed_rad_s: f64,
    /// Margin excluded around stuck phases in the torque balance [s].
    pub margin_s: f64,
    /// Refit J_eq, B_eq, tau_sf (and R_eq, k_drv) together with the effects.
    pub refit_base: bool,
    /// Largest input delay searched [s].
    pub max_delay_s: f64,
    /// Largest harmonic of a periodic torque searched [cycles per revolution of its shaft].
    pub max_harmonic: u32,
    /// Length of the blocks of the fit / held-out split [s].
    pub holdout_block_s: f64,
    /// Every `holdout_every`-th block is held out (0: none; fit on everything).
    pub holdout_every: usize,
    /// Horizon of each output-error prediction segment [s].
    pub oe_horizon_s: f64,
    /// Most output-error segments simulated (bounds the cost on long logs).
    pub oe_max_segments: usize,
    /// Pre-sliding regime: the torque balance leaves out the rows whose travel since the last
    /// reversal of the motion is below this many encoder counts [counts]. There a dynamic
    /// friction (bristles, a Dahl or LuGre friction) acts as a spring that winds up to the
    /// breakaway level, not as the steady-state (sliding) curve the catalogue's friction shapes
    /// describe ([`dataset::presliding`]). 0: keep them.
    pub presliding_counts: f64,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            filter_hz: 25.0,
            min_speed_rad_s: 1.0,
            margin_s: 0.01,
            refit_base: true,
            max_delay_s: 0.02,
            max_harmonic: 40,
            holdout_block_s: 1.0,
            holdout_every: 0,
            oe_horizon_s: 0.25,
            oe_max_segments: 60,
            presliding_counts: 0.0,
        }
    }
}

/// Why a fit failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    #[error("not enough data: {0}")]
    NoData(String),
    #[error("unusable record: {0}")]
    BadRecord(String),
    #[error("the least-squares problem is singular: {0}")]
    Singular(String),
    #[error("model: {0}")]
    BadModel(String),
    /// The caller's cancel hook was set ([`crate::diagnose::cancel::Cancel`]).
    #[error("cancelled")]
    Cancelled,
}

/// An effect to add to the model, with the parameters to fit marked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffectToFit {
    /// The effect; values of parameters to fit are ignored (may be NaN).
    pub effect: Effect,
    /// Which parameters (in [`EffectKind::params`] order) are fitted.
    pub fit: [bool; MAX_PARAMS],
}

/// Parameters that the fit never estimates unless asked explicitly keep their default
/// ([`crate::effects::EffectModel::fittable`]).
fn fittable(kind: EffectKind, key: &str) -> bool {
    kind.model().fittable(key)
}

impl EffectToFit {
    /// Every fittable parameter of `kind` is fitted (the others keep their defaults).
    pub fn all(kind: EffectKind) -> EffectToFit {
        let mut fit = [false; MAX_PARAMS];
        for (f, p) in fit.iter_mut().zip(kind.params()) {
            *f = fittable(kind, p.key);
        }
        EffectToFit {
            effect: Effect::unset(kind),
            fit,
        }
    }

    /// Only the levels of `fitted`: its nonlinear parameters (a harmonic, a speed scale) keep
    /// `fitted`'s values, and the linear ones this marks are fitted again. `None` when no
    /// parameter is left to fit.
    pub fn levels_of(self, fitted: Effect) -> Option<EffectToFit> {
        let mut t = EffectToFit {
            effect: fitted,
            fit: self.fit,
        };
        for (f, spec) in t.fit.iter_mut().zip(fitted.kind.params()) {
            *f &= !spec.nonlinear;
        }
        t.fit.iter().any(|f| *f).then_some(t)
    }

    /// Parses the `--add` syntax `name[:key=value,...]`: given keys are kept as given, every
    /// other fittable key is fitted.
    pub fn parse(spec: &str) -> Result<EffectToFit, EffectError> {
        let effect = Effect::parse(spec)?;
        let given: Vec<&str> = match spec.split_once(':') {
            Some((_, rest)) => rest
                .split(',')
                .filter_map(|kv| kv.split_once('=').map(|(k, _)| k.trim()))
                .collect(),
            None => Vec::new(),
        };
        let mut t = EffectToFit::all(effect.kind);
        t.effect = effect;
        for (i, p) in effect.kind.params().iter().enumerate() {
            if given.contains(&p.key) {
                t.fit[i] = false;
            }
        }
        Ok(t)
    }
}

impl From<Effect> for EffectToFit {
    /// Parameters that are NaN (unset) are fitted, the others kept.
    fn from(effect: Effect) -> EffectToFit {
        let mut fit = [false; MAX_PARAMS];
        for (f, v) in fit.iter_mut().zip(effect.values()) {
            *f = v.is_nan();
        }
        EffectToFit { effect, fit }
    }
}

/// One estimated (or kept) parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamEstimate {
    /// The effect it belongs to; `None` for base parameters (`j_eq`, `r_eq`, `k_drv`).
    pub effect: Option<EffectKind>,
    /// Catalogue key (or base parameter name).
    pub key: &'static str,
    pub unit: &'static str,
    pub value: f64,
    /// Standard error from the least-squares covariance (linear parameters only).
    pub std_err: Option<f64>,
    /// Was it estimated (true) or kept as given (false)?
    pub fitted: bool,
}

/// Residual of one equation before (base model as given) and after the fit.
#[derive(Debug, Clone, PartialEq)]
pub struct EquationFit {
    pub equation: Equation,
    /// Unit of the residual (N m or V).
    pub unit: &'static str,
    pub rms_before: f64,
    pub rms_after: f64,
    /// Rows used (decimated samples).
    pub n: usize,
}

/// The fitted model.
#[derive(Debug, Clone, PartialEq)]
pub struct FitResult {
    /// The fitted plant (base parameters refitted, effects added with their values).
    pub plant: Plant,
    /// Base parameters and effect parameters with standard errors.
    pub params: Vec<ParamEstimate>,
    /// Equation residuals before and after.
    pub equations: Vec<EquationFit>,
    /// Parameters of the user-defined effects ([`crate::custom`]).
    pub custom: Vec<crate::fit::custom::CustomEstimate>,
}

/// Fraction of the current-sampling correction of J_eq taken as its standard error: the mean
/// current of a period depends on the electrical time constant, a current sensor's own lag and
/// a drive that is not quite first order, which a log does not tell. On servo's simulator and
/// on an independent one (the calibration benchmark's), J_eq from the torque balance was off by
/// up to a third of the correction (0.05-0.3 % of J_eq, on PRBS, sine and closed-loop logs).
pub const SAMPLING_CORRECTION_DOUBT: f64 = 0.2;

/// Fewest fit rows in each half for the halves' disagreement to be folded into the intervals
/// (2 s of rows at the fits' 100 Hz row rate).
pub const MIN_HALF_ROWS: usize = 200;

/// The standard error behind the printed 95 % interval (+/- 1.96 of it) of coefficient `c` of
/// `eq`: the block-robust one ([`lsq::LsSolution::std_err_robust`]) or the halves'
/// disagreement `spread` (one value per coefficient of `eq`), whichever is larger.
fn interval_se(eq: &EqSolution, spread: &[f64], c: Coef) -> Option<f64> {
    let i = eq.coefs.iter().position(|&q| q == c)?;
    let rob = eq.std_err_robust.get(i).copied().unwrap_or(0.0);
    if rob <= 0.0 {
        // a coefficient held, not fitted
        return None;
    }
    Some(rob.max(spread.get(i).copied().unwrap_or(0.0)))
}

/// Fits `base` extended with `effects` to `records`.
///
/// Effects already in `base` keep their nonlinear parameters and have their linear ones refitted
/// (with the base parameters, unless `opts.refit_base` is false); `effects` are added (or replace
/// the base's effect of the same kind) with the parameters marked in [`EffectToFit::fit`]
/// estimated.
///
/// The base model is identified with no effects to add (J_eq, B_eq, tau_sf and the electrical
/// constants by least squares on the mechanical and electrical balances, handout 4.3):
///
/// ```
/// # use servo_core::{record::Record, sim::{PlantSim, SensorConfig, Sensors}, Plant, PlantParams};
/// # fn simulate(plant: &Plant, seconds: f64) -> Record {
/// #     let (mut sim, mut sensors) = (PlantSim::new(plant, 1e-3).unwrap(), Sensors::new(SensorConfig::default()));
/// #     let mut rec = Record::default();
/// #     let (mut th, mut ia, mut uv) = (Vec::new(), Vec::new(), Vec::new());
/// #     for k in 0..(seconds * 1e3) as usize {
/// #         let u = [6.0, -3.0, 2.0, -7.0, 4.0][(k / 300) % 5];
/// #         let m = sensors.measure(sim.state());
/// #         rec.time_s.push(k as f64 * 1e-3);
/// #         th.push(m.theta_l_rad); ia.push(m.i_a_a); uv.push(u);
/// #         sim.step(u);
/// #     }
/// #     (rec.theta_l_rad, rec.i_a_a, rec.u_v) = (Some(th), Some(ia), Some(uv));
/// #     rec
/// # }
/// use servo_core::fit::{fit_model, FitOptions};
/// let truth = Plant::from_params(PlantParams { b_eq: Some(2e-6), ..PlantParams::TABLE2 })?;
/// let log = simulate(&truth, 3.0);
/// let fit = fit_model(&[log], &Plant::from_params(PlantParams::TABLE2)?, &[], &FitOptions::default())?;
/// assert!((fit.plant.b_eq() / 2e-6 - 1.0).abs() < 0.2, "B_eq = {}", fit.plant.b_eq());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn fit_model(
    records: &[Record],
    base: &Plant,
    effects: &[EffectToFit],
    opts: &FitOptions,
) -> Result<FitResult, FitError> {
    let ds = Dataset::new(records, &base.params, opts)?;
    ds.fit(base, effects)
}

/// Relative tolerance assumed for each of k_drv, R_a, k_e and k_t when the mechanical parameters
/// are identified from u and the angle alone (datasheet-grade constants).
pub const DRIVE_CONSTANT_TOLERANCE: f64 = 0.05;

/// One mechanical parameter identified from the u-driven balance.
#[derive(Debug, Clone, PartialEq)]
pub struct UDrivenEstimate {
    /// The effect the parameter belongs to; `None` for the base (`j_eq`, `b_eq`, `tau_sf`).
    pub effect: Option<EffectKind>,
    pub key: &'static str,
    pub unit: &'static str,
    pub value: f64,
    /// Statistical standard error (least squares; NaN when the fit gives none, e.g. a phase).
    pub std_err: f64,
    /// Standard error including the tolerance of the drive constants
    /// ([`DRIVE_CONSTANT_TOLERANCE`] on each of k_drv, R_a, k_e, k_t, root-sum-square).
    pub std_err_total: f64,
}

/// J_eq, B_eq and tau_sf from logs of u and angle alone (no current), through the u-driven
/// balance k_drv k_t u / R_eq = J_eq dw/dt + (B_eq + k_t k_e / R_eq) w + tau_sf/N sign(w), with
/// k_drv, R_eq, k_e and k_t taken from `params`. Without the current these constants cannot be
/// checked: each is perturbed by [`DRIVE_CONSTANT_TOLERANCE`] and the shift of every estimate is
/// added to its interval (B_eq, a small difference of large terms, widens most).
pub fn identify_without_current(
    records: &[Record],
    params: &crate::params::PlantParams,
    opts: &FitOptions,
) -> Result<Vec<UDrivenEstimate>, FitError> {
    let start = |p: crate::params::PlantParams| {
        Plant::from_params(crate::params::PlantParams {
            tau_sf: Some(p.tau_sf.unwrap_or(0.005)),
            ..p
        })
        .map_err(|e| FitError::BadModel(alloc::format!("{e}")))
    };
    let strip: Vec<Record> = records
        .iter()
        .map(|r| Record {
            i_a_a: None,
            ..r.clone()
        })
        .collect();
    let fit_with = |p: crate::params::PlantParams| -> Result<Vec<ParamEstimate>, FitError> {
        let ds = Dataset::new(&strip, &p, opts)?;
        Ok(ds.fit(&start(p)?, &[])?.params)
    };
    let nominal = fit_with(*params)?;
    let keys = ["j_eq", "b_eq", "tau_sf"];
    let mut shifts = [0.0f64; 3];
    let tol = DRIVE_CONSTANT_TOLERANCE;
    let perturbed = [
        crate::params::PlantParams {
            k_drv: params.k_drv * (1.0 + tol),
            ..*params
        },
        crate::params::PlantParams {
            r_a: params.r_a * (1.0 + tol),
            ..*params
        },
        crate::params::PlantParams {
            k_e: params.k_e * (1.0 + tol),
            ..*params
        },
        crate::params::PlantParams {
            k_t: params.k_t * (1.0 + tol),
            ..*params
        },
    ];
    for p in perturbed {
        let est = fit_with(p)?;
        for (j, key) in keys.iter().enumerate() {
            let a = nominal.iter().find(|e| e.key == *key).map(|e| e.value);
            let b = est.iter().find(|e| e.key == *key).map(|e| e.value);
            if let (Some(a), Some(b)) = (a, b) {
                shifts[j] += (b - a) * (b - a);
            }
        }
    }
    let mut out = Vec::new();
    for (j, key) in keys.iter().enumerate() {
        let Some(e) = nominal.iter().find(|e| e.key == *key) else {
            continue;
        };
        let se = e.std_err.unwrap_or(0.0);
        out.push(UDrivenEstimate {
            effect: None,
            key,
            unit: e.unit,
            value: e.value,
            std_err: se,
            std_err_total: math::sqrt(se * se + shifts[j]),
        });
    }
    Ok(out)
}

/// Internal outcome of fitting one configuration.
#[derive(Debug, Clone)]
pub struct Solved {
    pub cfg: Config,
    pub mech: EqSolution,
    pub elec: Option<EqSolution>,
    pub plant: Plant,
}

impl Solved {
    /// The solution of `eq`.
    pub fn equation(&self, eq: Equation) -> Option<&EqSolution> {
        if self.mech.equation == eq {
            Some(&self.mech)
        } else {
            self.elec.as_ref().filter(|e| e.equation == eq)
        }
    }
}

impl Dataset {
    /// Fits `base` extended with `effects` (see [`fit_model`]).
    pub fn fit(&self, base: &Plant, effects: &[EffectToFit]) -> Result<FitResult, FitError> {
        let before = self.solve_config(&self.config(
            &crate::fit::custom::without_unknown(base),
            &[],
            false,
        ))?;
        let solved = self.fit_config(base, effects)?;
        let mut equations = Vec::new();
        for (b, a) in [
            (Some(&before.mech), Some(&solved.mech)),
            (before.elec.as_ref(), solved.elec.as_ref()),
        ] {
            if let (Some(b), Some(a)) = (b, a) {
                equations.push(EquationFit {
                    equation: a.equation,
                    unit: a.equation.unit(),
                    rms_before: b.rms(),
                    rms_after: a.rms(),
                    n: a.n_fit + a.n_hold,
                });
            }
        }
        let custom = custom_estimates(base, &solved);
        Ok(FitResult {
            plant: solved.plant,
            params: self.estimates(&solved),
            equations,
            custom,
        })
    }

    /// Builds the configuration: base effects beyond viscous/Coulomb become slots with their
    /// linear parameters refitted (when `refit_base`), `effects` are added.
    pub fn config(&self, base: &Plant, effects: &[EffectToFit], refit_base: bool) -> Config {
        let mut slots: Vec<Slot> = Vec::new();
        for e in base.effects.iter() {
            if matches!(e.kind, EffectKind::Viscous | EffectKind::Coulomb) {
                continue;
            }
            let mut fit = [false; MAX_PARAMS];
            for (i, p) in e.kind.params().iter().enumerate() {
                fit[i] = refit_base && !p.nonlinear;
            }
            let mut values = [f64::NAN; MAX_PARAMS];
            values[..e.values().len()].copy_from_slice(e.values());
            slots.push(Slot {
                kind: e.kind,
                values,
                fit,
            });
        }
        for t in effects {
            if matches!(t.effect.kind, EffectKind::Viscous)
                || (t.effect.kind == EffectKind::Coulomb
                    && base.effects.contains(EffectKind::Coulomb))
            {
                continue;
            }
            slots.retain(|s| s.kind != t.effect.kind);
            let mut values = [f64::NAN; MAX_PARAMS];
            values[..t.effect.values().len()].copy_from_slice(t.effect.values());
            slots.push(Slot {
                kind: t.effect.kind,
                values,
                fit: t.fit,
            });
        }
        Config {
            base: *base,
            slots,
            refit_base,
        }
    }

    /// Solves a configuration whose nonlinear parameters are all set.
    pub fn solve_config(&self, cfg: &Config) -> Result<Solved, FitError> {
        let mech = model::solve_mech(self, cfg).ok_or_else(|| {
            FitError::Singular(String::from(
                "the torque-balance regressors are collinear or too few",
            ))
        })?;
        let elec = if self.has_current && !self.elec_rows.is_empty() {
            Some(model::solve_elec(self, cfg).ok_or_else(|| {
                FitError::Singular(String::from(
                    "the electrical-balance regressors are collinear",
                ))
            })?)
        } else {
            None
        };
        let plant = to_plant(cfg, &mech, elec.as_ref())?;
        Ok(Solved {
            cfg: cfg.clone(),
            mech,
            elec,
            plant,
        })
    }

    /// Fits `base` alone like [`Dataset::fit_config`]; when the fitted inertia comes out not
    /// positive (the classic symptom of a large torque the base lacks, e.g. an arm's gravity),
    /// the solution is kept (its residuals and coefficients, for judging candidates against)
    /// with a plant that holds `base`'s inertia instead, and the fitted J_eq [kg m^2] is returned
    /// beside it. Any other failure is returned as the error.
    pub fn fit_base_tolerant(&self, base: &Plant) -> Result<(Solved, Option<f64>), FitError> {
        let err = match self.fit_config(base, &[]) {
            Ok(s) => return Ok((s, None)),
            Err(e) => e,
        };
        let cfg = self.config(base, &[], true);
        let Some(mech) = model::solve_mech(self, &cfg) else {
            return Err(err);
        };
        let j = match mech.coef(Coef::JEq) {
            Some((j, _)) if j <= 0.0 => j,
            _ => return Err(err),
        };
        let elec = if self.has_current && !self.elec_rows.is_empty() {
            model::solve_elec(self, &cfg)
        } else {
            None
        };
        let mut held = mech.clone();
        if let Some(i) = held.coefs.iter().position(|&q| q == Coef::JEq) {
            held.theta[i] = base.params.j_eq();
        }
        let plant = to_plant(&cfg, &held, elec.as_ref())?;
        Ok((
            Solved {
                cfg,
                mech,
                elec,
                plant,
            },
            Some(j),
        ))
    }

    /// Residual sum of squares (fit rows) of the equation where `kind` lives, per row.
    fn cost(&self, cfg: &Config, kind: EffectKind) -> f64 {
        let eq = Config::equation_of(kind, self.has_current);
        let sol = if eq == Equation::Electrical {
            model::solve_elec(self, cfg)
        } else {
            model::solve_mech(self, cfg)
        };
        sol.map_or(f64::INFINITY, |s| s.rss_fit / s.n_fit.max(1) as f64)
    }

    /// Fits a configuration: nonlinear parameters by search (coordinate-wise when several), the
    /// linear ones by least squares.
    ///
    /// With a user sensor effect the configuration is fitted on the angle mapped back through
    /// the sensor's inverse ([`crate::fit::custom::sensor_corrected`]).
    pub fn fit_config(&self, base: &Plant, effects: &[EffectToFit]) -> Result<Solved, FitError> {
        let mut with_custom = *base;
        crate::fit::custom::search_nonlinear(self, &mut with_custom)?;
        if with_custom.custom.has(crate::custom::ActsOn::Sensor) {
            let corrected = crate::fit::custom::sensor_corrected(self, &with_custom)?;
            return corrected.fit_config_searched(&with_custom, effects);
        }
        self.fit_config_searched(&with_custom, effects)
    }

    /// When `cfg` searches the parameters of a gear play (a contact effect entering the model)
    /// and `resize` is set, marks the input effects already in the model (those sized in the
    /// electrical balance, when the current is logged) to be searched again. Returns whether a
    /// play is searched, and whether there are such effects (marked or not).
    fn play_enters(&self, cfg: &mut model::Config, resize: bool) -> (bool, bool) {
        let entering = cfg
            .slots
            .iter()
            .any(|s| s.kind.sim_role() == SimRole::Contact && s.fit.iter().any(|f| *f));
        if !entering || !self.has_current {
            return (entering, false);
        }
        let mut found = false;
        for slot in cfg.slots.iter_mut() {
            let kind = slot.kind;
            if kind.is_mechanical() || slot.fit.iter().any(|f| *f) {
                continue;
            }
            for (j, p) in kind.params().iter().enumerate() {
                if p.nonlinear && kind.model().fittable(p.key) {
                    found = true;
                    slot.fit[j] |= resize;
                }
            }
        }
        (true, found)
    }

    /// [`Dataset::fit_config`] once the user effects' nonlinear parameters are set.
    ///
    /// A gear play entering a model that already holds input effects is fitted from two starts,
    /// and the one that predicts the fit blocks better (simulation cost) is kept: those effects
    /// as they are, and those effects searched again in the electrical balance with the play
    /// in it ([`Self::play_enters`]). That balance infers the motor speed (its back-EMF) from
    /// the load angle; with a play the motor leads the load through the contact and crosses
    /// the gap at every reversal of its torque, so an input effect sized before the play
    /// absorbs the difference (on five seeds of open- and closed-loop logs with a 0.03 rad play
    /// and a 3.0 ms delay, the delay came out 3.9-4.4 ms; re-sized, 3.1-3.4 ms). On
    /// closed-loop logs alone the bias was small and the re-sized start predicted worse.
    fn fit_config_searched(
        &self,
        base: &Plant,
        effects: &[EffectToFit],
    ) -> Result<Solved, FitError> {
        // Whether the second start applies depends only on the configuration: known before
        // either runs, so the two run side by side (on an idle core, else in turn; the same
        // fits either way).
        let mut cfg = self.config(base, effects, self.opts.refit_base);
        let (_, resizable) = self.play_enters(&mut cfg, false);
        if !resizable {
            return self.fit_config_started(base, effects, false);
        }
        let (kept, other) = crate::par::join(
            || self.fit_config_started(base, effects, false),
            || self.fit_config_started(base, effects, true),
        );
        let kept = kept?;
        let Ok(other) = other else {
            return Ok(kept);
        };
        let cost = |s: &Solved| oe::prediction_cost(self, &s.plant, oe::Part::Fit);
        Ok(match (cost(&kept), cost(&other)) {
            (Some(a), Some(b)) if b < a => other,
            _ => kept,
        })
    }

    /// [`Dataset::fit_config_searched`] from one start: with `resize`, the input effects in the
    /// model are searched again when a play enters.
    fn fit_config_started(
        &self,
        base: &Plant,
        effects: &[EffectToFit],
        resize: bool,
    ) -> Result<Solved, FitError> {
        let mut cfg = self.config(base, effects, self.opts.refit_base);
        let (play_searched, _) = self.play_enters(&mut cfg, resize);
        let searched: Vec<(usize, &'static str)> = cfg
            .slots
            .iter()
            .enumerate()
            .flat_map(|(i, s)| {
                s.kind
                    .params()
                    .iter()
                    .enumerate()
                    .filter(move |(j, p)| p.nonlinear && s.fit[*j])
                    .map(move |(_, p)| (i, p.key))
            })
            .collect();
        // Start every searched parameter at a sensible value.
        for &(i, key) in &searched {
            let v = self.initial(&cfg.slots[i], key);
            cfg.slots[i].set(key, v);
        }
        let passes = if searched.len() > 1 { 2 } else { 1 };
        // Effects judged on the simulation size their parameters there, after the regression.
        let on_simulation = |i: usize| {
            cfg.slots[i]
                .kind
                .model()
                .fit_hooks()
                .is_some_and(|h| h.judged_on_simulation())
        };
        let sim_searched: Vec<usize> = searched
            .iter()
            .map(|&(i, _)| i)
            .filter(|&i| on_simulation(i))
            .collect();
        for _ in 0..passes {
            for &(i, key) in &searched {
                if sim_searched.contains(&i) {
                    continue;
                }
                let kind = cfg.slots[i].kind;
                let grid = self.grid(&cfg.slots[i], key);
                let search = kind.model().search(key);
                let integer = search.scale == SearchScale::Integer;
                let log_scale = search.scale == SearchScale::Log;
                let on = self.search_set();
                let at = |trial: &mut model::Config, x: f64| {
                    let x = if log_scale { math::exp(x) } else { x };
                    trial.slots[i].set(key, x);
                    on.cost(trial, kind)
                };
                let mut trial = cfg.clone();
                let mut f = |x: f64| at(&mut trial, x);
                let g: Vec<f64> = if log_scale {
                    grid.iter().map(|v| math::ln(*v)).collect()
                } else {
                    grid.clone()
                };
                // The grid's least-squares solves are independent: on an idle core too.
                let on_grid = |xs: &[f64]| -> Vec<f64> {
                    let (a, b) = xs.split_at(xs.len() / 2);
                    let part = |xs: &[f64]| -> Vec<f64> {
                        let mut trial = cfg.clone();
                        xs.iter().map(|&x| at(&mut trial, x)).collect()
                    };
                    let (mut va, vb) = crate::par::join(|| part(a), || part(b));
                    va.extend(vb);
                    va
                };
                let iters = if integer { 0 } else { 20 };
                let (x, fx) = search::grid_then_golden_batched(&g, on_grid, &mut f, iters)
                    .ok_or_else(|| {
                        FitError::Singular(alloc::format!(
                            "{kind}: no finite cost over the search grid"
                        ))
                    })?;
                let mut x = if log_scale { math::exp(x) } else { x };
                // Ties go to the "no effect" end (a saturation limit above every logged input, a
                // zero dead band or delay): data that do not reach an effect cannot size it.
                let none = match search.no_effect_at {
                    NoEffectAt::Last => grid.last().copied(),
                    NoEffectAt::First => grid.first().copied(),
                    NoEffectAt::Nowhere => None,
                };
                if let Some(none) = none {
                    if f(none) <= fx * (1.0 + 1e-4) {
                        x = none;
                    }
                }
                cfg.slots[i].set(key, x);
            }
        }
        // A delay found in the electrical balance is sized to the sample only (the current
        // settles within a period); the motion resolves the fraction: refine on the simulation
        // (with a gear play searched too, the play's refinement does, with the gap).
        if let Some(&(i, _)) = searched
            .iter()
            .find(|(i, _)| cfg.slots[*i].kind == EffectKind::Delay)
            .filter(|_| !play_searched)
        {
            let d0 = cfg.slots[i].get("delay");
            let dt = self
                .recs
                .iter()
                .map(|r| r.dt_s)
                .fold(f64::INFINITY, f64::min);
            if self.has_current && d0 > 0.0 && dt.is_finite() {
                let base = self.solve_config(&cfg)?;
                let segs = oe::segments(self, oe::Part::Fit);
                let h = self.opts.oe_horizon_s;
                let mut f = |d: f64, bound: f64| {
                    let mut c = base.cfg.clone();
                    c.slots[i].set("delay", d);
                    match to_plant(&c, &base.mech, base.elec.as_ref()) {
                        Ok(p) => oe::prediction_cost_bounded(self, &p, &segs, h, bound)
                            .unwrap_or(f64::INFINITY),
                        Err(_) => f64::INFINITY,
                    }
                };
                let grid = search::linspace((d0 - dt).max(0.0), d0 + dt, 9);
                if let Some((d, _)) = search::grid_then_golden_bounded(&grid, &mut f, 10) {
                    cfg.slots[i].set("delay", d);
                }
            }
        }
        let mut solved = self.solve_config(&cfg)?;
        // With an effect judged on the simulation in the model (a gear play), its parameters
        // (when asked) and J_eq (when the base is refitted) are sized on the simulation: the
        // torque balance cannot see them, and they bias J_eq.
        for i in 0..cfg.slots.len() {
            let Some(hooks) = cfg.slots[i].kind.model().fit_hooks() else {
                continue;
            };
            if !hooks.judged_on_simulation() {
                continue;
            }
            let fit_main = sim_searched.contains(&i);
            if fit_main || cfg.refit_base {
                hooks.refine_on_simulation(self, &mut solved, i, fit_main, cfg.refit_base)?;
            }
        }
        self.polish_on_simulation(&mut solved, effects)?;
        Ok(solved)
    }

    /// Refines, on the simulation cost of the fit blocks, the parameters of the fitted effects
    /// that the motion is most sensitive to, starting from their least-squares values (see
    /// [`crate::effects::EffectModel::polish`]); the others keep their least-squares value.
    ///
    /// The torque balance estimates them from small differences (a sin/cos pair under the noise,
    /// a breakaway excess seen over a few samples), and a position loop is very sensitive to
    /// them: a magnetic detent of twice the Coulomb level (motor side) decides where the loop
    /// stops, and a phase 0.15 rad off (h = 12) drops a closed-loop replay from 99.7 % to 99.0 %
    /// fit; the breakaway excess tau_s - tau_sf sets the amplitude of the hunting around a set
    /// point. Each parameter gets a grid over its span and a golden-section search, in turn,
    /// and a change is kept only when it lowers the cost.
    fn polish_on_simulation(
        &self,
        solved: &mut Solved,
        effects: &[EffectToFit],
    ) -> Result<(), FitError> {
        for e in effects {
            let kind = e.effect.kind;
            for &(key, span) in kind.model().polish() {
                let Some(ki) = kind.params().iter().position(|p| p.key == key) else {
                    continue;
                };
                let Some(x0) = solved.plant.effects.value(kind, key) else {
                    continue;
                };
                if !e.fit[ki] {
                    continue;
                }
                let plant0 = solved.plant;
                let with = |x: f64| -> Option<Plant> {
                    let mut p = plant0;
                    p.effects.get_mut(kind)?.set(key, x).ok()?;
                    Some(p)
                };
                let segs = oe::segments(self, oe::Part::Fit);
                let h = self.opts.oe_horizon_s;
                let cost = |x: f64, bound: f64| -> f64 {
                    with(x)
                        .and_then(|p| oe::prediction_cost_bounded(self, &p, &segs, h, bound))
                        .unwrap_or(f64::INFINITY)
                };
                let grid = match span {
                    crate::effects::Span::Add(d) => search::linspace(x0 - d, x0 + d, 9),
                    crate::effects::Span::Scale(f) => search::linspace(x0 / f, x0 * f, 9),
                };
                let c0 = cost(x0, f64::INFINITY);
                if let Some((x, c)) = search::grid_then_golden_bounded(&grid, cost, 10) {
                    if c < c0 {
                        if let Some(p) = with(x) {
                            solved.plant = p;
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// `plant` with J_eq (+-15 %) and the Coulomb level (+-10 %) refined on the simulation cost
    /// of the fit blocks (short segments), each by a grid and a golden-section search, in turn.
    ///
    /// The reference a candidate judged on the simulation (a gear play) is judged against: its
    /// own J_eq and tau_sf are refined on the simulation together with its parameters
    /// ([`Dataset::fit_config`]), so the model without it must get the same refinement, or the
    /// candidate wins on the refinement alone.
    pub fn refine_rigid_on_simulation(&self, plant: &Plant) -> Plant {
        let segs = oe::segments(self, oe::Part::Fit);
        let h = self.opts.oe_horizon_s;
        let cost = |p: &Plant, bound: f64| {
            oe::prediction_cost_bounded(self, p, &segs, h, bound).unwrap_or(f64::INFINITY)
        };
        let mut best = *plant;
        let j0 = plant.params.j_eq();
        let with_j = |p: &Plant, j: f64| {
            let mut q = *p;
            q.params.j_eq = Some(j);
            q
        };
        if let Some((s, _)) = search::grid_then_golden_bounded(
            &search::linspace(0.85, 1.15, 5),
            |s, bound| cost(&with_j(&best, j0 * s), bound),
            8,
        ) {
            best = with_j(&best, j0 * s);
        }
        if best.effects.contains(EffectKind::Coulomb) {
            let t0 = best.tau_sf();
            let with_tau = |p: &Plant, t: f64| -> Option<Plant> {
                let mut q = *p;
                q.params.tau_sf = Some(t);
                set_effect(&mut q, EffectKind::Coulomb, &[t]).ok()?;
                Some(q)
            };
            if let Some((s, _)) = search::grid_then_golden_bounded(
                &search::linspace(0.9, 1.1, 5),
                |s, bound| with_tau(&best, t0 * s).map_or(f64::INFINITY, |p| cost(&p, bound)),
                8,
            ) {
                if let Some(p) = with_tau(&best, t0 * s) {
                    best = p;
                }
            }
        }
        if cost(&best, f64::INFINITY) <= cost(plant, f64::INFINITY) {
            best
        } else {
            *plant
        }
    }

    /// Largest load-side speed in the torque-balance rows [rad/s].
    pub fn omega_l_max(&self) -> f64 {
        let w = self.sample(&self.mech_rows, |r| &r.omega_f);
        w.iter().fold(0.0f64, |m, v| m.max(v.abs())) / self.gear_ratio
    }

    /// What the search grids may depend on.
    pub fn grid_context(&self) -> GridContext {
        GridContext {
            omega_l_max_rad_s: self.omega_l_max(),
            u_max_v: self.u_max_v.max(1e-6),
            dt_s: self
                .recs
                .iter()
                .map(|r| r.dt_s)
                .fold(f64::INFINITY, f64::min),
            max_delay_s: self.opts.max_delay_s,
            max_harmonic: self.opts.max_harmonic,
        }
    }

    /// The search grid of `key` of slot `s` ([`crate::effects::EffectModel::search_grid`]; its
    /// current value when the effect gives none).
    pub fn grid(&self, s: &Slot, key: &str) -> Vec<f64> {
        s.kind
            .model()
            .search_grid(key, &self.grid_context())
            .filter(|g| !g.is_empty())
            .unwrap_or_else(|| alloc::vec![s.get(key)])
    }

    fn initial(&self, s: &Slot, key: &str) -> f64 {
        let g = self.grid(s, key);
        g[g.len() / 2]
    }

    /// Half the disagreement of the coefficients of `eq` fitted on two halves of its fit rows
    /// apart (the configuration's nonlinear parameters held), per coefficient, the larger of
    /// two splits: the first and second half in time, and the slower and faster half by motor
    /// speed; zeros when the rows are too few or no split can be solved. A model or sampling
    /// error that changes along the logs or with the speed (friction near reversals, the
    /// current's sampling under the large accelerations of a reversal) shows there even when
    /// the block sandwich, which trusts the model, does not: for halves of equal information,
    /// (theta_1 - theta_2)^2 / 4 estimates the variance of the whole fit.
    fn halves_spread(&self, solved: &Solved, eq: &EqSolution) -> Vec<f64> {
        let zeros = alloc::vec![0.0; eq.coefs.len()];
        if eq.n_fit / 2 < MIN_HALF_ROWS {
            return zeros;
        }
        let solve = |h: model::Half| match eq.equation {
            Equation::Electrical => model::solve_elec_on(self, &solved.cfg, h),
            _ => model::solve_mech_on(self, &solved.cfg, h),
        };
        let mut spread = zeros;
        for (h1, h2) in [
            (model::Half::First, model::Half::Second),
            (model::Half::Slow, model::Half::Fast),
        ] {
            if let (Some(a), Some(b)) = (solve(h1), solve(h2)) {
                if a.coefs == eq.coefs && b.coefs == eq.coefs {
                    for ((s, x), y) in spread.iter_mut().zip(&a.theta).zip(&b.theta) {
                        *s = s.max(0.5 * (x - y).abs());
                    }
                }
            }
        }
        spread
    }

    /// Estimates of every parameter of a solved configuration, with the standard errors behind
    /// the printed 95 % intervals (block-robust, widened by the halves' disagreement).
    pub fn estimates(&self, solved: &Solved) -> Vec<ParamEstimate> {
        self.estimates_with(solved, true)
    }

    /// [`Dataset::estimates`] with the plain least-squares standard errors: what a comparison
    /// of two parts of the data weighs their difference against (the printed intervals fold
    /// in that very disagreement, so a halves check on them would pass itself).
    pub fn estimates_plain(&self, solved: &Solved) -> Vec<ParamEstimate> {
        self.estimates_with(solved, false)
    }

    fn estimates_with(&self, solved: &Solved, widened: bool) -> Vec<ParamEstimate> {
        let mut out = Vec::new();
        let p = &solved.plant.params;
        let refit = solved.cfg.refit_base;
        let spread = |eq: &EqSolution| {
            if widened {
                self.halves_spread(solved, eq)
            } else {
                Vec::new()
            }
        };
        let mech_spread = spread(&solved.mech);
        let elec_spread = solved.elec.as_ref().map(spread).unwrap_or_default();
        let mech_se = |c: Coef| {
            if widened {
                interval_se(&solved.mech, &mech_spread, c)
            } else {
                solved.mech.coef(c).map(|(_, s)| s)
            }
        };
        let se = |eq: &EqSolution, c: Coef| {
            let s = if eq.equation == solved.mech.equation {
                mech_se(c)
            } else if widened {
                interval_se(eq, &elec_spread, c)
            } else {
                eq.coef(c).map(|(_, s)| s)
            };
            s.filter(|s| *s > 0.0)
        };
        // The torque balance takes the mean current of each period from point samples at its
        // end ([`dataset::torque_current_f`]); that correction moves J_eq by
        // k_t w (k_e / R_eq) T_s, and its doubt is folded into J_eq's standard error.
        let j_se = se(&solved.mech, Coef::JEq).map(|s| {
            if solved.mech.equation != Equation::Torque || !widened {
                return s;
            }
            let dt = self
                .recs
                .iter()
                .map(|r| r.dt_s)
                .fold(f64::INFINITY, f64::min);
            let tau = p.t_drv() + p.l_a / p.r_eq();
            let dj = p.k_t * dataset::centring_weight(dt, tau) * p.k_e / p.r_eq() * dt;
            let doubt = if dj.is_finite() {
                SAMPLING_CORRECTION_DOUBT * dj
            } else {
                0.0
            };
            math::sqrt(s * s + doubt * doubt)
        });
        out.push(ParamEstimate {
            effect: None,
            key: "j_eq",
            unit: "kg m^2",
            value: p.j_eq(),
            std_err: j_se,
            fitted: refit,
        });
        out.push(ParamEstimate {
            effect: Some(EffectKind::Viscous),
            key: "b_eq",
            unit: "N m s/rad",
            value: solved.plant.b_eq(),
            std_err: se(&solved.mech, Coef::BEq),
            fitted: refit,
        });
        if solved.plant.effects.contains(EffectKind::Coulomb) {
            out.push(ParamEstimate {
                effect: Some(EffectKind::Coulomb),
                key: "tau_sf",
                unit: "N m",
                value: solved.plant.tau_sf(),
                std_err: se(&solved.mech, Coef::TauSf),
                fitted: refit || solved.cfg.slot(EffectKind::Coulomb).is_some(),
            });
        }
        if let Some(el) = &solved.elec {
            let (ci, _) = el.coef(Coef::ROverK).unwrap_or((f64::NAN, 0.0));
            let (cw, _) = el.coef(Coef::KeOverK).unwrap_or((f64::NAN, 0.0));
            let si = se(el, Coef::ROverK).unwrap_or(0.0);
            let sw = se(el, Coef::KeOverK).unwrap_or(0.0);
            let k_drv = p.k_drv;
            let se_k = k_drv * sw / cw;
            let se_r = p.r_eq() * math::sqrt((si / ci) * (si / ci) + (sw / cw) * (sw / cw));
            out.push(ParamEstimate {
                effect: None,
                key: "k_drv",
                unit: "V/V",
                value: k_drv,
                std_err: Some(se_k).filter(|v| *v > 0.0),
                fitted: refit,
            });
            out.push(ParamEstimate {
                effect: None,
                key: "r_eq",
                unit: "ohm",
                value: p.r_eq(),
                std_err: Some(se_r).filter(|v| *v > 0.0),
                fitted: refit,
            });
        }
        for (si, s) in solved.cfg.slots.iter().enumerate() {
            if s.kind == EffectKind::Coulomb {
                continue;
            }
            for (j, spec) in s.kind.params().iter().enumerate() {
                let value = solved
                    .plant
                    .effects
                    .value(s.kind, spec.key)
                    .unwrap_or(f64::NAN);
                let std_err = match (s.kind, spec.key) {
                    (EffectKind::Asymmetry, "tau_sf_pos") => mech_se(Coef::AsymPos(si)),
                    (EffectKind::Asymmetry, "tau_sf_neg") => mech_se(Coef::AsymNeg(si)),
                    _ => {
                        let m = s.kind.model();
                        let (coefs, se): (Vec<f64>, Vec<f64>) = (0..m.linear_coefs())
                            .map(|j| {
                                let c = Coef::Effect(si, j);
                                (
                                    solved.mech.coef(c).map_or(0.0, |v| v.0),
                                    mech_se(c).unwrap_or(0.0),
                                )
                            })
                            .unzip();
                        m.std_err(spec.key, &se, &coefs)
                    }
                }
                .filter(|v| *v > 0.0);
                out.push(ParamEstimate {
                    effect: Some(s.kind),
                    key: spec.key,
                    unit: spec.unit,
                    value,
                    std_err,
                    fitted: s.fit[j],
                });
            }
        }
        out
    }
}

/// Turns a solved configuration into a plant.
pub fn to_plant(
    cfg: &Config,
    mech: &EqSolution,
    elec: Option<&EqSolution>,
) -> Result<Plant, FitError> {
    let mut plant = cfg.base;
    let mut params = plant.params;
    let c = |q: Coef| mech.coef(q).map(|v| v.0);
    if let Some(j) = c(Coef::JEq) {
        if j <= 0.0 {
            return Err(FitError::BadModel(String::from(
                "the fitted inertia J_eq is not positive; the logs need accelerations",
            )));
        }
        params.j_eq = Some(j);
    }
    let b = c(Coef::BEq).unwrap_or(plant.b_eq()).max(0.0);
    params.b_eq = Some(b);
    set_effect(&mut plant, EffectKind::Viscous, &[b])?;
    let asym = cfg
        .slots
        .iter()
        .position(|s| s.kind == EffectKind::Asymmetry);
    let mut tau_sf = c(Coef::TauSf);
    if let Some(ai) = asym {
        let pos = c(Coef::AsymPos(ai)).unwrap_or(0.0).max(0.0);
        let neg = c(Coef::AsymNeg(ai)).unwrap_or(0.0).max(0.0);
        set_effect(&mut plant, EffectKind::Asymmetry, &[pos, neg])?;
        tau_sf = Some(0.5 * (pos + neg));
    }
    if let Some(t) = tau_sf {
        params.tau_sf = Some(t.max(0.0));
        set_effect(&mut plant, EffectKind::Coulomb, &[t.max(0.0)])?;
    }
    if let Some(el) = elec {
        let ci = el.coef(Coef::ROverK).map(|v| v.0).unwrap_or(f64::NAN);
        let cw = el.coef(Coef::KeOverK).map(|v| v.0).unwrap_or(f64::NAN);
        if ci > 0.0 && cw > 0.0 {
            let k_drv = params.k_e / cw;
            let r_eq = ci * k_drv;
            if r_eq > params.r_s {
                params.k_drv = k_drv;
                params.r_a = r_eq - params.r_s;
            }
        }
    }
    for (si, s) in cfg.slots.iter().enumerate() {
        let mut v: Vec<f64> = s.values[..s.kind.params().len()].to_vec();
        match s.kind {
            EffectKind::Coulomb | EffectKind::Asymmetry => continue,
            _ => {
                let m = s.kind.model();
                let nc = m.linear_coefs();
                if nc > 0 {
                    let coefs: Vec<f64> = (0..nc)
                        .map(|j| c(Coef::Effect(si, j)).unwrap_or(0.0))
                        .collect();
                    m.values_from_coefs(&coefs, &mut v, params.tau_sf.unwrap_or(0.0));
                }
            }
        }
        for x in v.iter_mut() {
            if x.is_nan() {
                *x = 0.0;
            }
        }
        set_effect(&mut plant, s.kind, &v)?;
    }
    for (si, e) in plant.custom.iter_mut().enumerate() {
        for j in 0..e.def.params().len() {
            if e.values[j].is_nan() {
                let spec = &e.def.params()[j];
                let v = c(Coef::Custom(si, j)).unwrap_or(0.0);
                e.values[j] = v.clamp(spec.min, spec.max);
            }
        }
    }
    plant.params = params;
    params
        .validate()
        .map_err(|e| FitError::BadModel(alloc::format!("fitted parameters: {e}")))?;
    Ok(plant)
}

/// The parameters of the user effects of a solved configuration: those unknown in `base` are
/// marked fitted, with the least-squares standard error of the linear ones.
fn custom_estimates(base: &Plant, solved: &Solved) -> Vec<crate::fit::custom::CustomEstimate> {
    let mut out = Vec::new();
    for (si, e) in solved.plant.custom.iter().enumerate() {
        let given = base.custom.get(e.name());
        for (j, spec) in e.def.params().iter().enumerate() {
            let fitted = given.is_none_or(|g| g.values[j].is_nan());
            out.push(crate::fit::custom::CustomEstimate {
                effect: e.name(),
                key: spec.key,
                unit: spec.unit,
                value: e.values[j],
                std_err: solved
                    .mech
                    .coef(Coef::Custom(si, j))
                    .map(|c| c.1)
                    .filter(|v| *v > 0.0),
                fitted,
            });
        }
    }
    out
}

/// Activates `kind` with `values` in `plant` (a fitted value outside its range is a model error).
pub fn set_effect(plant: &mut Plant, kind: EffectKind, values: &[f64]) -> Result<(), FitError> {
    let e = Effect::new(kind, values)
        .map_err(|e| FitError::BadModel(alloc::format!("fitted {kind}: {e}")))?;
    plant.effects.insert(e);
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::params::PlantParams;
    use crate::sim::excitation::{simulate_open_loop, RandomSteps};
    use crate::sim::SensorConfig;

    /// An open-loop identification-like log: random voltage steps of both signs.
    pub(crate) fn open_loop_log(
        plant: &Plant,
        seconds: f64,
        seed: u64,
        with_current: bool,
    ) -> Record {
        let dt = 1e-3;
        let steps = RandomSteps {
            hold_samples: 300,
            min_v: 0.5,
            span_v: 5.0,
            ..RandomSteps::new(seed ^ 0xABCD)
        };
        let u = steps.voltages((seconds / dt) as usize, dt);
        let sensors = SensorConfig {
            seed,
            ..SensorConfig::default()
        };
        let mut rec = simulate_open_loop(plant, sensors, dt, &u, "sim").unwrap();
        if !with_current {
            rec.i_a_a = None;
        }
        rec
    }

    pub(crate) fn truth() -> Plant {
        let params = PlantParams {
            j_eq: Some(7.0e-7),
            b_eq: Some(1.0e-6),
            tau_sf: Some(0.01),
            ..PlantParams::TABLE2
        };
        Plant::from_params(params).unwrap()
    }

    /// [`truth`] without its Coulomb friction (tau_sf unset): the model the tests' diagnoses
    /// find lacking.
    pub(crate) fn without_coulomb() -> Plant {
        Plant::from_params(PlantParams {
            j_eq: Some(7.0e-7),
            b_eq: Some(1.0e-6),
            ..PlantParams::TABLE2
        })
        .expect("the Table 2 plant without Coulomb friction")
    }

    #[test]
    fn refits_the_base_parameters_with_and_without_current() {
        let truth = truth();
        let log = open_loop_log(&truth, 10.0, 3, true);
        // Start from the nominal datasheet values with a rough friction guess.
        let start = Plant::from_params(PlantParams {
            tau_sf: Some(0.002),
            ..PlantParams::TABLE2
        })
        .unwrap();
        let r = fit_model(
            std::slice::from_ref(&log),
            &start,
            &[],
            &FitOptions::default(),
        )
        .unwrap();
        let p = &r.plant;
        assert!(
            (p.params.j_eq() / 7.0e-7 - 1.0).abs() < 0.05,
            "J_eq {}",
            p.params.j_eq()
        );
        assert!(
            (p.tau_sf() / 0.01 - 1.0).abs() < 0.1,
            "tau_sf {}",
            p.tau_sf()
        );
        assert!((p.b_eq() / 1.0e-6 - 1.0).abs() < 0.25, "B_eq {}", p.b_eq());
        assert!(
            (p.params.k_drv / 0.6 - 1.0).abs() < 0.03,
            "k_drv {}",
            p.params.k_drv
        );
        assert!(
            (p.params.r_eq() / 3.1 - 1.0).abs() < 0.05,
            "R_eq {}",
            p.params.r_eq()
        );
        assert!(r.equations.iter().all(|e| e.rms_after <= e.rms_before));
        let mut no_i = log;
        no_i.i_a_a = None;
        let r = fit_model(&[no_i], &start, &[], &FitOptions::default()).unwrap();
        assert_eq!(r.equations[0].equation, Equation::Combined);
        let p = &r.plant;
        assert!(
            (p.params.j_eq() / 7.0e-7 - 1.0).abs() < 0.05,
            "J_eq {}",
            p.params.j_eq()
        );
        assert!(
            (p.tau_sf() / 0.01 - 1.0).abs() < 0.1,
            "tau_sf {}",
            p.tau_sf()
        );
    }
}
