//! `servo design --model M --ff TERMS` (issue #29, design on the identified model): the gains are
//! designed on the model's linear part (J_eq, B_eq and the drive), then verified on the model's
//! whole nonlinear plant (its effects simulated) without and with the compensation `--ff`
//! chooses: the loop's margins with the angle-dependent torques linearised over one load
//! revolution (servo_core::stiffness), the step cases `servo run` would give, and the tracking
//! error on the standard tracking reference, one compensated effect at a time.

use super::report_json::num;
use super::*;
use servo_core::design::verify::{loop_with_stiffness, SpringLoop};
use servo_core::effects::{AngleFrom, Compensation, EffectKind};
use servo_core::stiffness::{stiffness_range, StiffnessRange};
use servo_hw::run::compensation_check::{tracking_ladder, TrackingRun, TrackingRung};
use servo_hw::run::step_cases::{run_step_cases_compensated, CaseOutcome, CaseRig};
use servo_io::compensation::CompensationChoice;

/// Step sizes of the step check, evenly from --step-min to --step-max.
const STEPS: usize = 5;
/// How long each step of the check is held [s].
const HOLD_S: f64 = 1.0;

/// The flags of the check.
#[derive(Debug, Clone, clap::Args)]
pub struct CompensationArgs {
    /// Verify the design on the model file's whole nonlinear plant (its effects simulated)
    /// without and with this compensation, as `servo run --model M --ff TERMS` runs it: `all`,
    /// effect names of the model, linear terms (`inertia`, `friction`, ...). Needs --model FILE.
    #[arg(long, value_name = "TERMS")]
    pub ff: Option<String>,
    /// Ramp-in time of the effects' compensation [s] (as `servo run --ff-ramp`).
    #[arg(long = "ff-ramp", value_name = "SECONDS", default_value_t = 0.0)]
    pub ff_ramp_s: f64,
    /// Tracking reference of the check (an experiment TOML); default: the standard tracking
    /// reference (experiments/tracking.toml: moves of 1.5 rad both ways and a 0.2 Hz sine).
    #[arg(long = "ff-experiment", value_name = "TOML")]
    pub ff_experiment: Option<PathBuf>,
}

/// Margins of the loop linearised at the two ends of the angle-dependent torques' stiffness.
pub(super) struct MarginRange {
    pub stiffness: StiffnessRange,
    /// At the smallest and at the largest stiffness.
    pub at_ends: [SpringLoop; 2],
}

impl MarginRange {
    fn worst_pm_deg(&self) -> f64 {
        self.at_ends
            .iter()
            .map(|m| m.phase_margin_deg)
            .fold(f64::INFINITY, f64::min)
    }
    fn stable(&self) -> bool {
        self.at_ends
            .iter()
            .all(|m| m.stability.is_none_or(|s| s == Stability::Stable))
    }
}

/// The design verified on the model without and with its compensation.
pub(super) struct CompensatedCheck {
    pub model: PathBuf,
    pub choice: CompensationChoice,
    /// The effects of the model simulated.
    pub effects: Vec<String>,
    /// Margins of the linear part alone (no angle-dependent torque).
    pub linear: SpringLoop,
    pub without: MarginRange,
    pub with: MarginRange,
    pub steps_without: Vec<CaseOutcome>,
    pub steps_with: Vec<CaseOutcome>,
    pub tracking_name: String,
    pub tracking_s: f64,
    pub ladder: Vec<TrackingRung>,
}

impl Design {
    /// The check, when `--ff` is given (needs the model file).
    pub(super) fn compensated_check(
        &self,
        out: &Outcome,
        gains: &GainsFile,
    ) -> anyhow::Result<Option<CompensatedCheck>> {
        let Some(terms) = self.comp.ff.as_deref() else {
            return Ok(None);
        };
        let Some(path) = &self.params else {
            bail!("--ff needs the identified model: --model FILE (a model file from `servo identify -o` or `servo compare --save`)");
        };
        let mf = ModelFile::load(path)?;
        let plant = mf.plant()?;
        let choice = CompensationChoice::parse(terms, &mf, &plant, self.comp.ff_ramp_s)?;
        let comp = choice.build(&plant)?;
        let r = &out.report;
        let (pid, u_limit_v) = servo_hw::run::pid_from_gains(gains, "the designed gains")?;
        let (_, sensors) = self.run_plant().load()?;

        // Margins: the linear part, then the angle-dependent torques linearised.
        let model = self.design_model(r);
        let p = &plant.params;
        let drive_nm_per_v = p.k_drv * p.k_t / p.r_eq();
        let wgc = r.request.spec.omega_gc;
        let at = |k: f64| loop_with_stiffness(&r.gains, &model, wgc, k, drive_nm_per_v);
        let range = |s: StiffnessRange| MarginRange {
            stiffness: s,
            at_ends: [at(s.min_nm_per_rad), at(s.max_nm_per_rad)],
        };
        let cancelled = |k: EffectKind| {
            choice.select.selects(k)
                && k.model().compensation()
                    == Compensation::Torque {
                        angle: AngleFrom::Measured,
                    }
        };
        let without = range(stiffness_range(&plant, &|_| true));
        let with = range(stiffness_range(&plant, &|k| !cancelled(k)));

        // Steps as `servo run` runs them, without and with.
        let steps: Vec<f64> = (0..STEPS)
            .map(|i| {
                self.step_min + (self.step_max - self.step_min) * i as f64 / (STEPS - 1) as f64
            })
            .collect();
        let cases = |ff: Option<&servo_core::control::LoopCompensation>| {
            let rig = CaseRig {
                plant: &plant,
                sensors,
                drive: mf.drive,
            };
            run_step_cases_compensated(&rig, &pid, u_limit_v, &steps, HOLD_S, ff)
                .map_err(|e| anyhow!("checking the design on {}: {e}", path.display()))
        };
        let steps_without = cases(None)?;
        let steps_with = cases(Some(&comp))?;

        // The tracking ladder.
        let exp = match &self.comp.ff_experiment {
            Some(p) => servo_io::reference_file::load_experiment(p)?,
            None => servo_io::reference_file::Experiment::standard_tracking()?,
        };
        let duration_s = exp.duration_s();
        let run = TrackingRun {
            truth: &plant,
            sensors,
            model: &plant,
            pid,
            u_limit_v,
            program: servo_core::control::Program::Segments(exp.segments.clone()),
            duration_s,
            ramp_s: self.comp.ff_ramp_s,
            drive: mf.drive,
        };
        let effects: Vec<EffectKind> = plant
            .effects
            .iter()
            .map(|e| e.kind)
            .filter(|k| choice.compensated.iter().any(|(n, _)| *n == k.name()))
            .collect();
        let ladder = tracking_ladder(&run, choice.linear, &effects, &choice.custom)
            .map_err(|e| anyhow!("the tracking check on {}: {e}", path.display()))?;
        Ok(Some(CompensatedCheck {
            model: path.clone(),
            effects: plant
                .effects
                .iter()
                .map(|e| e.kind.name().to_string())
                .collect(),
            choice,
            linear: at(0.0),
            without,
            with,
            steps_without,
            steps_with,
            tracking_name: exp.name.clone(),
            tracking_s: duration_s,
            ladder,
        }))
    }
}

/// The worst overshoot [%] and 5 % settling time [s] (`None`: a case did not settle) of `cases`.
fn worst(cases: &[CaseOutcome]) -> (f64, Option<f64>) {
    let os = cases.iter().map(|c| c.overshoot_pct).fold(0.0, f64::max);
    let ts = cases
        .iter()
        .try_fold(0.0f64, |w, c| c.settling_time_s.map(|t| w.max(t)));
    (os, ts)
}

fn settle_words(t: Option<f64>) -> String {
    t.map_or("not settled".into(), |t| format!("{t:.3} s"))
}

fn margins_words(m: &SpringLoop) -> String {
    let st = match m.stability {
        Some(s) => stability_name(s).to_lowercase(),
        None => "stability not computed (ideal derivative)".into(),
    };
    if m.phase_margin_deg.is_finite() {
        format!(
            "PM {:.1} deg at w_gc {:.2} rad/s, {st}",
            m.phase_margin_deg, m.omega_gc
        )
    } else {
        format!("no crossover within a decade of the design's, {st}")
    }
}

fn range_words(r: &MarginRange) -> String {
    let s = &r.stiffness;
    if s == &StiffnessRange::NONE {
        return "no angle-dependent torque in the loop: the linear part's margins".into();
    }
    format!(
        "{} (stiffness {:.3e} N m/rad at the rotor, load angle {:.2} rad) .. {} ({:.3e} N m/rad, {:.2} rad)",
        margins_words(&r.at_ends[0]),
        s.min_nm_per_rad,
        s.min_at_load_rad,
        margins_words(&r.at_ends[1]),
        s.max_nm_per_rad,
        s.max_at_load_rad
    )
}

/// The range's verdict: the worst phase margin, or where the loop is unstable.
fn verdict_words(r: &MarginRange, linear: &SpringLoop) -> String {
    if let Some((i, _)) = r
        .at_ends
        .iter()
        .enumerate()
        .find(|(_, m)| m.stability.is_some_and(|s| s != Stability::Stable))
    {
        let (k, at) = if i == 0 {
            (r.stiffness.min_nm_per_rad, r.stiffness.min_at_load_rad)
        } else {
            (r.stiffness.max_nm_per_rad, r.stiffness.max_at_load_rad)
        };
        return format!(
            "the linearised loop is UNSTABLE near load angle {at:.2} rad (stiffness {k:.3e} N m/rad \
             at the rotor: the loop cannot hold the shaft there)"
        );
    }
    format!(
        "worst phase margin {:.1} deg, stable at every angle",
        r.worst_pm_deg().min(linear.phase_margin_deg)
    )
}

/// The text section.
pub(super) fn compensated_section(s: &mut String, c: &CompensatedCheck) {
    let _ = writeln!(
        s,
        "\nverified on the nonlinear model of {} (effects: {}), without and with --ff {}:",
        c.model.display(),
        c.effects.join(", "),
        c.choice.label()
    );
    for line in c.choice.lines() {
        let _ = writeln!(s, "  {line}");
    }
    let _ = writeln!(
        s,
        "  margins (continuous loop; angle-dependent torques linearised over one load revolution):"
    );
    let _ = writeln!(s, "    linear part:          {}", margins_words(&c.linear));
    let _ = writeln!(s, "    without compensation: {}", range_words(&c.without));
    let _ = writeln!(s, "    with compensation:    {}", range_words(&c.with));
    let _ = writeln!(
        s,
        "    without compensation: {}; with: {} (a torque cancelled at the measured angle leaves \
         the loop; a feedforward from the reference does not change it)",
        verdict_words(&c.without, &c.linear),
        verdict_words(&c.with, &c.linear)
    );
    let (os0, ts0) = worst(&c.steps_without);
    let (os1, ts1) = worst(&c.steps_with);
    let _ = writeln!(
        s,
        "  steps {} to {} rad as `servo run` runs them (at t = 0, from rest later, after a move; held {HOLD_S} s):",
        c.steps_without.first().map_or(0.0, |x| x.step_rad),
        c.steps_without.last().map_or(0.0, |x| x.step_rad),
    );
    let _ = writeln!(
        s,
        "    without compensation: worst overshoot {os0:.2} %, worst settling 5 % {}",
        settle_words(ts0)
    );
    let _ = writeln!(
        s,
        "    with compensation:    worst overshoot {os1:.2} %, worst settling 5 % {}",
        settle_words(ts1)
    );
    let _ = writeln!(
        s,
        "  tracking error on `{}` ({:.0} s), RMS [rad], one compensation added at a time:",
        c.tracking_name, c.tracking_s
    );
    let first = c.ladder.first().map_or(f64::NAN, |r| r.err_rms_rad);
    for r in &c.ladder {
        let _ = writeln!(
            s,
            "    {:<40} {:.3e} rad ({:+.0} %), max {:.3e} rad",
            r.label(),
            r.err_rms_rad,
            100.0 * (r.err_rms_rad / first - 1.0),
            r.err_max_rad
        );
    }
}

fn margins_json(m: &SpringLoop) -> Value {
    json!({
        "pm_deg": num(m.phase_margin_deg),
        "wgc_rad_s": num(m.omega_gc),
        "stable": m.stability.map(|s| s == Stability::Stable),
    })
}

fn range_json(r: &MarginRange) -> Value {
    json!({
        "stiffness_min_nm_per_rad": r.stiffness.min_nm_per_rad,
        "stiffness_min_at_load_rad": r.stiffness.min_at_load_rad,
        "stiffness_max_nm_per_rad": r.stiffness.max_nm_per_rad,
        "stiffness_max_at_load_rad": r.stiffness.max_at_load_rad,
        "at_min": margins_json(&r.at_ends[0]),
        "at_max": margins_json(&r.at_ends[1]),
        "worst_pm_deg": num(r.worst_pm_deg()),
        "stable": r.stable(),
    })
}

fn steps_json(cases: &[CaseOutcome]) -> Value {
    let (os, ts) = worst(cases);
    json!({
        "worst_overshoot_pct": os,
        "worst_settling_time_5pct_s": ts,
        "cases": cases.iter().map(|c| json!({
            "step_rad": c.step_rad,
            "start": format!("{:?}", c.start).to_lowercase(),
            "overshoot_pct": c.overshoot_pct,
            "settling_time_5pct_s": c.settling_time_s,
        })).collect::<Vec<_>>(),
    })
}

/// The `compensation_check` object of `--json`.
pub(super) fn compensated_json(c: &CompensatedCheck) -> Value {
    json!({
        "model": c.model.display().to_string(),
        "effects": c.effects,
        "ff": c.choice.label(),
        "compensation": c.choice.lines(),
        "margins": {
            "linear": margins_json(&c.linear),
            "without": range_json(&c.without),
            "with": range_json(&c.with),
        },
        "steps_without": steps_json(&c.steps_without),
        "steps_with": steps_json(&c.steps_with),
        "tracking": {
            "reference": c.tracking_name,
            "duration_s": c.tracking_s,
            "ladder": c.ladder.iter().map(|r| json!({
                "rung": r.label(),
                "ff": servo_io::controller::ff_name(&r.linear),
                "effects": r.effects.iter().map(|k| k.name()).collect::<Vec<_>>(),
                "err_rms_rad": r.err_rms_rad,
                "err_max_rad": r.err_max_rad,
                "saturation_time_s": r.saturation_time_s,
            })).collect::<Vec<_>>(),
        },
    })
}
