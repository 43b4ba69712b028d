//! `servo design`: from the flags to the design request (spec translation, eqs. 31-41; the
//! time-domain specs) and from the outcome to the gains file.

use super::*;

#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DesignModel {
    /// Eq. 29: k_m / ((T_m s + 1) N s) (the handout's choice)
    Reduced,
    /// Eq. 27: driver low-pass, armature R-L, mechanics, integrator
    Full,
    /// An identified model file: its linear part, reduced model (as --params FILE).
    File(PathBuf),
}

/// `--model`: `reduced`, `full` or a model file.
pub(super) fn parse_design_model(s: &str) -> Result<DesignModel, String> {
    match s {
        "reduced" => Ok(DesignModel::Reduced),
        "full" => Ok(DesignModel::Full),
        _ if std::path::Path::new(s).is_file() => Ok(DesignModel::File(PathBuf::from(s))),
        _ => Err(format!(
            "expected `reduced`, `full` or a model file (TOML from `servo identify -o` or \
             `servo compare --save`); `{s}` is neither (no such file)"
        )),
    }
}

impl super::Design {
    pub(super) fn translation(&self) -> anyhow::Result<(Translation, Vec<String>)> {
        let damping = match (self.pm, self.overshoot) {
            (Some(pm), None) => DampingSpec::PhaseMargin(rad(pm)),
            (None, Some(mp)) => DampingSpec::Overshoot(mp),
            (None, None) => bail!("no damping spec: give --pm <deg> (e.g. --pm 60) or --overshoot <fraction> (e.g. --overshoot 0.1)"),
            (Some(_), Some(_)) => bail!("--pm and --overshoot both set the phase margin; give one"),
        };
        let speed = match (self.wc, self.settling_time, self.settling_time_1pct, self.rise_time) {
            (Some(w), None, None, None) => SpeedSpec::OmegaGc(w),
            (None, Some(t), None, None) => SpeedSpec::Settling5(t),
            (None, None, Some(t), None) => SpeedSpec::Settling1(t),
            (None, None, None, Some(t)) => SpeedSpec::RiseTime(t),
            (None, None, None, None) => bail!(
                "no speed spec: give --wc <rad/s> (e.g. --wc 30), --settling-time <s>, --settling-time-1pct <s> or --rise-time <s>"
            ),
            _ => bail!("give only one of --wc, --settling-time, --settling-time-1pct, --rise-time"),
        };
        let t = translate(damping, speed).map_err(|e| anyhow!("{e}"))?;
        let mut lines = Vec::new();
        match damping {
            DampingSpec::Overshoot(mp) => lines.push(format!(
                "M_p = {:.4} ({:.2} %) -> delta = {:.5} (eq. 36) -> phi_m = {:.4} rad = {:.3} deg (eq. 41)",
                mp,
                100.0 * mp,
                t.delta,
                t.spec.phase_margin,
                deg(t.spec.phase_margin)
            )),
            DampingSpec::PhaseMargin(_) => lines.push(format!(
                "phi_m = {:.3} deg -> delta = {:.5} (inverse of eq. 41), expected M_p ~ {:.2} % (eq. 33)",
                deg(t.spec.phase_margin),
                t.delta,
                100.0 * t.overshoot
            )),
        }
        match speed {
            SpeedSpec::OmegaGc(w) => lines.push(format!("w_gc = {w:.4} rad/s (given)")),
            SpeedSpec::Settling5(ts) => lines.push(format!(
                "t_s,5% = {ts} s -> w_gc = 3/(delta t_s,5%) = {:.4} rad/s (eq. 40)",
                t.spec.omega_gc
            )),
            SpeedSpec::Settling1(ts) => lines.push(format!(
                "t_s,1% = {ts} s -> w_gc = 4.6/(delta t_s,1%) = {:.4} rad/s (eq. 40)",
                t.spec.omega_gc
            )),
            SpeedSpec::RiseTime(tr) => lines.push(format!(
                "t_r = {tr} s -> w_gc = 1.8/t_r = {:.4} rad/s (eq. 39)",
                t.spec.omega_gc
            )),
        }
        Ok((t, lines))
    }

    /// The time-domain specs given on the command line, if any.
    pub(super) fn time_specs(&self) -> Option<TimeSpecs> {
        let speed = match (self.settling_time, self.settling_time_1pct, self.rise_time) {
            (Some(t), _, _) => Some(SpeedTarget::Settling {
                band: 0.05,
                time_s: t,
            }),
            (_, Some(t), _) => Some(SpeedTarget::Settling {
                band: 0.01,
                time_s: t,
            }),
            (_, _, Some(t)) => Some(SpeedTarget::Rise { time_s: t }),
            _ => None,
        };
        if self.overshoot.is_none() && speed.is_none() {
            return None;
        }
        Some(TimeSpecs {
            overshoot_max: self.overshoot,
            speed,
            step_min_rad: self.step_min,
            step_max_rad: self.step_max,
        })
    }

    pub(super) fn design_model(&self, r: &DesignReport) -> PlantModel {
        match (&self.model, r.request.full) {
            (DesignModel::Full, Some(f)) => f,
            _ => r.request.reduced,
        }
    }

    pub(super) fn gains_file(&self, out: &Outcome, tr: &Translation) -> GainsFile {
        let r = &out.report;
        let g = &r.gains;
        let mut d = toml::Table::new();
        d.insert("method".into(), "Bode (handout eqs. 44-53)".into());
        d.insert("controller".into(), r.request.kind.name().into());
        d.insert("model".into(), self.design_model(r).name().into());
        d.insert("wgc_rad_s".into(), r.request.spec.omega_gc.into());
        d.insert("pm_deg".into(), deg(r.request.spec.phase_margin).into());
        d.insert("alpha".into(), r.request.alpha.into());
        d.insert(
            "discretization".into(),
            r.request.discretization.name().into(),
        );
        d.insert("exact".into(), self.exact.into());
        // What the design assumed, for `servo run` to compare with what it runs.
        d.insert("plant".into(), self.plant_key().into());
        // ... and its parameters, which `servo run` compares (not the name)
        if let Some(t) = self
            .run_plant()
            .base_params()
            .and_then(|p| toml::Value::try_from(p).ok())
        {
            d.insert("plant_params".into(), t);
        }
        // A drive other than a voltage amplifier: the output's unit follows it (amps on a
        // current drive), in the file's comments and in `servo run`'s words.
        if let Ok(drive) = self.run_plant().drive() {
            if drive.kind != servo_core::drive::DriveKind::Voltage {
                d.insert("drive".into(), drive.kind.name().into());
            }
        }
        d.insert("meet_specs".into(), self.meet_specs.into());
        if self.meet_specs {
            d.insert("translated_wgc_rad_s".into(), tr.spec.omega_gc.into());
            d.insert("translated_pm_deg".into(), deg(tr.spec.phase_margin).into());
        }
        let m = &r.discrete.margins;
        if m.phase_margin_deg.is_finite() {
            d.insert("achieved_discrete_pm_deg".into(), m.phase_margin_deg.into());
            d.insert("achieved_discrete_wgc_rad_s".into(), m.omega_gc.into());
        }
        if let Some(c) = &out.check {
            if let Some(o) = c.specs.overshoot_max {
                d.insert("spec_overshoot_pct".into(), (100.0 * o).into());
            }
            d.insert("step_min_rad".into(), c.specs.step_min_rad.into());
            d.insert("step_max_rad".into(), c.specs.step_max_rad.into());
            d.insert(
                "achieved_worst_overshoot_pct".into(),
                c.worst_overshoot_pct.into(),
            );
            if let Some(t) = c.worst_speed_s {
                d.insert(format!("achieved_worst_{}", speed_key(&c.specs)), t.into());
            }
            d.insert(
                "time_specs_met".into(),
                out.time_specs_met().unwrap_or(false).into(),
            );
        }
        GainsFile {
            pid: PidSection {
                kw: out.structure.kw_per_s,
                u_limit_v: Some(out.structure.u_limit_v),
                derivative_on: Some(out.structure.derivative_on),
                ..PidSection::of(g, r.request.ts_s)
            },
            design: Some(d),
        }
    }
}

/// `settling_time_5pct_s`, `settling_time_1pct_s` or `rise_time_s`.
pub(super) fn speed_key(sp: &TimeSpecs) -> String {
    match sp.speed {
        Some(SpeedTarget::Rise { .. }) => "rise_time_s".into(),
        _ => format!("settling_time_{}pct_s", (100.0 * sp.band()).round()),
    }
}
