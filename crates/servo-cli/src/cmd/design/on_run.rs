//! `servo design`: the time-domain specs checked through what `servo run` will run: the gains
//! file as written, the PID `servo run` builds from it, the simulator on the plant the design
//! names (friction and sensors included), steps at t = 0, later from rest and after a previous
//! move (servo_hw::run::step_cases).

use super::*;
use servo_hw::run::step_cases::{run_step_cases, CaseOutcome, CaseRig};

/// Step sizes of the check: the range's ends and evenly in between (0.2, 0.3, ..., 1 rad for the
/// default range).
const RUN_CHECK_STEPS: usize = 9;

/// What `servo run` gives with the designed gains.
pub(super) struct RunCheck {
    /// The plant, in words.
    pub plant: String,
    pub cases: Vec<CaseOutcome>,
    /// The specs checked: overshoot [%] and 5 % settling time [s] (`None`: not checkable through
    /// the run summary, which measures the 5 % band).
    pub overshoot_max_pct: f64,
    pub settling_max_s: Option<f64>,
    /// Why the speed spec was not checked here, if it was not.
    pub unchecked: Option<String>,
}

impl RunCheck {
    pub fn failing(&self) -> Vec<&CaseOutcome> {
        self.cases
            .iter()
            .filter(|c| !c.meets(self.overshoot_max_pct, self.settling_max_s))
            .collect()
    }
    pub fn met(&self) -> bool {
        self.failing().is_empty()
    }
}

impl Design {
    /// The simulated plant `servo run` uses for the same `--params`/`--plant-preset`.
    pub(super) fn run_plant(&self) -> crate::plant_args::PlantArgs {
        crate::plant_args::PlantArgs {
            plant: self.params.clone(),
            plant_preset: self.plant_preset,
            ..Default::default()
        }
    }

    /// Runs the designed gains file through `servo run`'s loop on the design's plant.
    pub(super) fn run_check(
        &self,
        gains: &GainsFile,
        specs: &TimeSpecs,
    ) -> anyhow::Result<RunCheck> {
        let (pid, u_limit_v) = servo_hw::run::pid_from_gains(gains, "the designed gains")?;
        let (plant, sensors) = self.run_plant().load()?;
        let rig = CaseRig {
            plant: &plant,
            sensors,
            drive: self.run_plant().drive()?,
        };
        let (settling_max_s, unchecked, hold_s) = match specs.speed {
            Some(SpeedTarget::Settling { band, time_s }) if (band - 0.05).abs() < 1e-12 => {
                (Some(time_s), None, (8.0 * time_s).max(0.8))
            }
            None => (None, None, 1.0),
            _ => (
                None,
                Some(
                    "the speed spec (1 % settling or rise time) is not measured by `servo run`'s summary (5 % band)"
                        .to_string(),
                ),
                1.0,
            ),
        };
        let steps = specs.grid(RUN_CHECK_STEPS);
        let cases = run_step_cases(&rig, &pid, u_limit_v, &steps, hold_s)
            .map_err(|e| anyhow!("checking the design through servo run's loop: {e}"))?;
        Ok(RunCheck {
            plant: self.plant_words(),
            cases,
            overshoot_max_pct: 100.0 * specs.overshoot_max.unwrap_or(f64::INFINITY),
            settling_max_s,
            unchecked,
        })
    }

    /// The plant the design names, in words.
    pub(super) fn plant_words(&self) -> String {
        match (&self.params, self.plant_preset) {
            (Some(p), _) => format!("the plant of {}", p.display()),
            (None, p) => p
                .unwrap_or(crate::plant_args::DEFAULT_PLANT)
                .describe()
                .to_string(),
        }
    }
}

/// The text section of the run check.
pub(super) fn run_section(s: &mut String, rc: &RunCheck) {
    let _ = writeln!(
        s,
        "\nchecked as `servo run --gains` runs it (simulator on {}, the PID as run builds it from the gains file): \
         {} steps from {} to {} rad, each at t = 0, later from rest and after a previous move",
        rc.plant,
        rc.cases.len() / 3,
        rc.cases.first().map_or(0.0, |c| c.step_rad),
        rc.cases.last().map_or(0.0, |c| c.step_rad),
    );
    let worst_os = rc.cases.iter().map(|c| c.overshoot_pct).fold(0.0, f64::max);
    let worst_ts = rc
        .cases
        .iter()
        .map(|c| c.settling_time_s.unwrap_or(f64::INFINITY))
        .fold(0.0, f64::max);
    let _ = writeln!(
        s,
        "  worst overshoot {worst_os:.2} %{}, worst settling 5 % {} (spec {})",
        if rc.overshoot_max_pct.is_finite() {
            format!(" (spec {:.2} %)", rc.overshoot_max_pct)
        } else {
            " (no spec)".to_string()
        },
        if worst_ts.is_finite() {
            format!("{worst_ts:.4} s")
        } else {
            "not settled".into()
        },
        rc.settling_max_s
            .map_or("not checked".into(), |t| format!("{t} s"))
    );
    if let Some(why) = &rc.unchecked {
        let _ = writeln!(s, "  note: {why}");
    }
    for c in rc.failing() {
        let _ = writeln!(
            s,
            "  MISSED: {}: overshoot {:.2} %, settling 5 % {}",
            c.start.words(c.step_rad),
            c.overshoot_pct,
            c.settling_time_s
                .map_or("not settled".into(), |t| format!("{t:.4} s"))
        );
    }
}

/// The `run_check` object of `--json`.
pub(super) fn run_json(rc: &RunCheck) -> Value {
    json!({
        "plant": rc.plant,
        "met": rc.met(),
        "overshoot_max_pct": rc.overshoot_max_pct,
        "settling_time_5pct_max_s": rc.settling_max_s,
        "cases": rc.cases.iter().map(|c| json!({
            "step_rad": c.step_rad,
            "start": format!("{:?}", c.start).to_lowercase(),
            "overshoot_pct": c.overshoot_pct,
            "settling_time_5pct_s": c.settling_time_s,
            "met": c.meets(rc.overshoot_max_pct, rc.settling_max_s),
        })).collect::<Vec<_>>(),
    })
}

impl Design {
    /// The plant as the gains file's `[design] plant` records it (`lab`, `table2` or the
    /// `--params` file as given), compared by `servo run` with what it simulates.
    pub(super) fn plant_key(&self) -> String {
        match (&self.params, self.plant_preset) {
            (Some(p), _) => p.display().to_string(),
            (None, p) => crate::plant_args::PlantArgs {
                plant_preset: p,
                ..Default::default()
            }
            .key(),
        }
    }
}

/// Spec margins of the successive searches of [`Design::meet_through_run`]: the search aims at
/// the specs times this factor, until `servo run`'s loop meets the specs themselves (the search's
/// linear loop model has no Coulomb friction, quantisation or noise).
const MARGINS: [f64; 4] = [1.0, 0.8, 0.65, 0.5];

impl Design {
    /// `--meet-specs` closed through `servo run`: searches (servo_core::design::meet), checks the
    /// result through the run loop on the design's plant, and when some case misses, searches
    /// again with tighter targets; returns the first design that `servo run` meets, else the
    /// one with the fewest missed cases (which the report then names).
    pub(super) fn meet_through_run(
        &self,
        req: &DesignRequest,
        specs: TimeSpecs,
        derivative_on: DerivativeOn,
        tr: &Translation,
    ) -> anyhow::Result<Outcome> {
        let t0 = std::time::Instant::now();
        let mut best: Option<Outcome> = None;
        for factor in MARGINS {
            let aimed = TimeSpecs {
                overshoot_max: specs.overshoot_max.map(|m| m * factor),
                speed: specs.speed.map(|s| match s {
                    SpeedTarget::Settling { band, time_s } => SpeedTarget::Settling {
                        band,
                        time_s: time_s * factor,
                    },
                    SpeedTarget::Rise { time_s } => SpeedTarget::Rise {
                        time_s: time_s * factor,
                    },
                }),
                ..specs
            };
            let mut m = match meet_specs(&MeetRequest {
                base: *req,
                specs: aimed,
                u_limit_v: self.u_limit,
                derivative_on,
            }) {
                Ok(m) => m,
                Err(_) if best.is_some() => break,
                Err(e) => return Err(anyhow!("{e}")).context("--meet-specs failed"),
            };
            if factor < 1.0 && !m.feasible {
                break; // tighter than the loop can do: keep the last one
            }
            // The claim is about the user's specs: re-check the found design against them.
            m.check = check_report(&m.report, &m.structure, &specs)
                .map_err(|e| anyhow!("{e}"))
                .context("checking the time-domain specs")?;
            m.feasible = m.check.met();
            let mut out = Outcome {
                report: m.report.clone(),
                structure: m.structure,
                check: Some(m.check.clone()),
                meet: Some((m, 0.0)),
                run_check: None,
                compensated: None,
            };
            // (--km/--tm name no plant that `servo run` could simulate)
            if self.km.is_some() {
                return Ok(out);
            }
            let rc = self.run_check(&self.gains_file(&out, tr), &specs)?;
            let missed = rc.failing().len();
            out.run_check = Some(rc);
            let better = best.as_ref().is_none_or(|b| {
                missed
                    < b.run_check
                        .as_ref()
                        .map_or(usize::MAX, |r| r.failing().len())
            });
            if better {
                best = Some(out);
            }
            if missed == 0
                && best
                    .as_ref()
                    .is_some_and(|b| b.check.as_ref().is_some_and(RangeCheck::met))
            {
                break;
            }
        }
        let mut out = best.ok_or_else(|| anyhow!("--meet-specs found no design"))?;
        if let Some((_, ms)) = out.meet.as_mut() {
            *ms = t0.elapsed().as_secs_f64() * 1e3;
        }
        Ok(out)
    }
}
