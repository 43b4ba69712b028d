//! The method fallback of identification (what `servo identify` runs without `--method`): the
//! logs are classified into friction experiments (constant-speed segments at two or more speeds,
//! handout 4.1) and inertia experiments (acceleration/deceleration phases, 4.2); friction runs on
//! the first, the electrical check on those that logged u, inertia on the second with that
//! friction, and the combined least squares (4.3) on every log for whatever the dedicated tests
//! could not give. What could not run is said, not hidden.

use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;

use super::combined::{identify_combined, CombinedConfig, CombinedFit};
use super::electrical::{identify_electrical, ElectricalFit};
use super::friction::{friction_points, identify_friction, FrictionConfig, FrictionFit};
use super::inertia::{identify_inertia, identify_inertia_ls, InertiaFit};
use super::phases::{find_phases, PhaseConfig};
use super::{Estimate, Experiment, IdentError};
use crate::params::PlantParams;
use crate::record::Record;

/// One identification method (`--method`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Friction from constant-speed segments (4.1).
    Friction,
    /// Inertia from acceleration/deceleration phases (4.2), with the friction of the logs that
    /// allow it.
    Inertia,
    /// One least squares over whole records (4.3).
    Combined,
    /// k_drv and R_eq from the steady-state voltage balance.
    Electrical,
}

/// How the inertia is taken from the phases.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum InertiaMethod {
    /// Eqs. 67-70 averaged over phase pairs.
    #[default]
    Phases,
    /// Least squares on the samples of the phases.
    Ls,
}

/// Settings of [`identify`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct IdentifyOptions {
    /// One method only; `None`: every applicable one, with the fallback described in the module.
    pub method: Option<Method>,
    pub inertia_method: InertiaMethod,
    pub friction: FrictionConfig,
    pub phases: PhaseConfig,
    pub combined: CombinedConfig,
}

/// The `skipped` line of a run without the friction staircase (no log has one).
pub const NO_STAIRCASE: &str =
    "friction: no log has constant-speed segments at two or more speeds (handout 4.1 staircase)";
/// The `skipped` line of a run without the inertia ramps (no log has them).
pub const NO_RAMPS: &str =
    "inertia: no log has constant acceleration/deceleration phases (handout 4.2)";

/// For a `skipped` line that says an experiment was not in the logs (not that it failed): the
/// experiment, in words. `None` for a method that ran and failed.
pub fn absent_experiment(skipped: &str) -> Option<&'static str> {
    match skipped {
        NO_STAIRCASE => Some(
            "the friction staircase (handout 4.1; no log has constant-speed segments at two or more speeds)",
        ),
        NO_RAMPS => Some(
            "the inertia ramps (handout 4.2; no log has constant acceleration/deceleration phases)",
        ),
        _ => None,
    }
}

/// What the methods gave, and why the others did not run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Identification {
    pub friction: Option<FrictionFit>,
    pub inertia: Option<InertiaFit>,
    pub combined: Option<CombinedFit>,
    pub electrical: Option<ElectricalFit>,
    /// One line per method that did not run or failed (`friction: ...`).
    pub skipped: Vec<String>,
}

impl Identification {
    /// B_eq [N m s/rad] (motor side) and the method it came from: the friction test, else the
    /// combined least squares.
    pub fn b_eq(&self) -> Option<(Estimate, &'static str)> {
        self.friction
            .as_ref()
            .map(|f| (f.b_eq, "friction"))
            .or_else(|| self.combined.as_ref().map(|c| (c.b_eq, "combined")))
    }
    /// tau_sf [N m] (load side) and the method it came from.
    pub fn tau_sf(&self) -> Option<(Estimate, &'static str)> {
        self.friction
            .as_ref()
            .map(|f| (f.tau_sf, "friction"))
            .or_else(|| self.combined.as_ref().map(|c| (c.tau_sf, "combined")))
    }
    /// J_eq [kg m^2] (motor side) and the method it came from: the inertia test, else the
    /// combined least squares.
    pub fn j_eq(&self) -> Option<(Estimate, &'static str)> {
        self.inertia
            .as_ref()
            .map(|f| (f.j_eq, "inertia"))
            .or_else(|| self.combined.as_ref().map(|c| (c.j_eq, "combined")))
    }
}

/// True when no record holds the armature current but every one holds u: the current-based
/// methods cannot run, and the u-driven balance
/// ([`crate::fit::identify_without_current`]) is the way.
pub fn needs_u_driven_balance(records: &[Record]) -> bool {
    records.iter().all(|r| r.i_a_a.is_none() && r.u_v.is_some())
}

/// Runs the chosen method, or every applicable one (friction, electrical, inertia, then the
/// combined least squares for what is still missing), on the experiments `exps` with the
/// constants of `p`. Refused with [`IdentError::NotIdentifiable`] when nothing could be
/// identified (the message lists why each method did not run).
///
/// ```
/// # use servo_core::{record::Record, sim::{PlantSim, SensorConfig, Sensors}, Plant, PlantParams};
/// use servo_core::ident::{auto::{identify, IdentifyOptions}, Experiment};
/// // A staircase of voltages: constant-speed plateaus and acceleration phases.
/// let plant = Plant::from_params(PlantParams::TABLE2)?;
/// let (mut sim, mut sensors) = (PlantSim::new(&plant, 1e-3)?, Sensors::new(SensorConfig::default()));
/// let mut rec = Record::default();
/// let (mut th, mut ia, mut uv) = (Vec::new(), Vec::new(), Vec::new());
/// for k in 0..6000 {
///     let u = [2.0, 4.0, 6.0, -2.0, -4.0, -6.0][k / 1000];
///     let m = sensors.measure(sim.state());
///     rec.time_s.push(k as f64 * 1e-3);
///     th.push(m.theta_l_rad); ia.push(m.i_a_a); uv.push(u);
///     sim.step(u);
/// }
/// (rec.theta_l_rad, rec.i_a_a, rec.u_v) = (Some(th), Some(ia), Some(uv));
/// let exp = Experiment::from_record(&rec, &PlantParams::TABLE2)?;
/// let found = identify(&[exp], &PlantParams::TABLE2, &IdentifyOptions::default())?;
/// let (b_eq, method) = found.b_eq().expect("B_eq identified");
/// assert!(b_eq.value > 0.0, "B_eq = {} from {method}", b_eq.value);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn identify(
    exps: &[Experiment],
    p: &PlantParams,
    opts: &IdentifyOptions,
) -> Result<Identification, IdentError> {
    // The current is taken as sampled before each zero-order-hold command of a voltage drive
    // (the torque aligned with the speed's derivative, J_eq corrected) unless told otherwise.
    let sampling = Some(super::CurrentSampling::from_params(p));
    let ccfg = &CombinedConfig {
        current_sampling: opts.combined.current_sampling.or(sampling),
        ..opts.combined
    };
    let pcfg = &PhaseConfig {
        current_sampling: opts.phases.current_sampling.or(sampling),
        ..opts.phases
    };
    let fcfg = &opts.friction;
    let mut r = Identification::default();
    let inertia =
        |exps: &[Experiment], f: Option<&FrictionFit>| -> Result<InertiaFit, IdentError> {
            match opts.inertia_method {
                InertiaMethod::Phases => identify_inertia(exps, f, pcfg),
                InertiaMethod::Ls => identify_inertia_ls(exps, f, pcfg),
            }
        };
    match opts.method {
        Some(Method::Friction) => r.friction = Some(identify_friction(exps, p.n, fcfg)?),
        Some(Method::Combined) => r.combined = Some(identify_combined(exps, p.n, ccfg)?),
        Some(Method::Electrical) => r.electrical = Some(identify_electrical(exps, p, fcfg)?),
        Some(Method::Inertia) => {
            let (fr, ir) = split_logs(exps, fcfg, pcfg)?;
            if ir.is_empty() {
                inertia(exps, None)?; // produces the explanation
            }
            let f = if fr.is_empty() {
                None
            } else {
                identify_friction(&fr, p.n, fcfg).ok()
            };
            r.friction = f.clone();
            r.inertia = Some(inertia(&ir, f.as_ref())?);
        }
        None => {
            let (fr, ir) = split_logs(exps, fcfg, pcfg)?;
            if !fr.is_empty() {
                match identify_friction(&fr, p.n, fcfg) {
                    Ok(f) => r.friction = Some(f),
                    Err(e) => r.skipped.push(format!("friction: {e}")),
                }
                if fr.iter().any(|e| e.u_v.is_some()) {
                    match identify_electrical(&fr, p, fcfg) {
                        Ok(e) => r.electrical = Some(e),
                        Err(e) => r.skipped.push(format!("electrical: {e}")),
                    }
                }
            } else {
                r.skipped.push(String::from(NO_STAIRCASE));
            }
            if !ir.is_empty() {
                match inertia(&ir, r.friction.as_ref()) {
                    Ok(i) => r.inertia = Some(i),
                    Err(e) => r.skipped.push(format!("inertia: {e}")),
                }
            } else {
                r.skipped.push(String::from(NO_RAMPS));
            }
            if r.friction.is_none() || r.inertia.is_none() {
                match identify_combined(exps, p.n, ccfg) {
                    Ok(c) => r.combined = Some(c),
                    Err(e) => r.skipped.push(format!("combined: {e}")),
                }
            }
            if r.b_eq().is_none() && r.j_eq().is_none() {
                return Err(IdentError::NotIdentifiable(format!(
                    "nothing could be identified from these logs:\n  {}",
                    r.skipped.join("\n  ")
                )));
            }
        }
    }
    Ok(r)
}

/// Splits the experiments into those with constant-speed segments at >= 2 speeds (friction) and
/// those with >= 2 acceleration phases (inertia). A log may be in both.
pub fn split_logs(
    exps: &[Experiment],
    fcfg: &FrictionConfig,
    pcfg: &PhaseConfig,
) -> Result<(Vec<Experiment>, Vec<Experiment>), IdentError> {
    let mut fr = Vec::new();
    let mut ir = Vec::new();
    for e in exps {
        let pts = friction_points(core::slice::from_ref(e), fcfg)?;
        let mags: Vec<f64> = pts.iter().map(|p| p.omega_m_rad_s.abs()).collect();
        let (lo, hi) = mags
            .iter()
            .fold((f64::INFINITY, 0.0_f64), |(a, b), &m| (a.min(m), b.max(m)));
        if pts.len() >= 2 && hi - lo > 0.1 * hi {
            fr.push(e.clone());
        }
        if find_phases(&e.time_s, &e.omega_m_rad_s, pcfg)?.len() >= 2 {
            ir.push(e.clone());
        }
    }
    Ok((fr, ir))
}
