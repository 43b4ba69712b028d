//! `servo identify`: the method fallback (friction staircase, inertia phases, combined least
//! squares) and the classification of the logs into friction and inertia experiments.

use super::*;

impl super::Identify {
    pub(super) fn friction_cfg(&self) -> FrictionConfig {
        FrictionConfig {
            samples: self.samples,
            ..FrictionConfig::default()
        }
    }

    pub(super) fn phase_cfg(&self) -> PhaseConfig {
        PhaseConfig {
            cutoff_hz: self.cutoff_hz,
            min_accel_rad_s2: self.min_accel,
            window_frac: self.phase_window,
            ..PhaseConfig::default()
        }
    }

    /// Runs the chosen (or every applicable) method.
    pub fn estimate(&self, exps: &[Experiment], p: &PlantParams) -> anyhow::Result<Report> {
        let fcfg = self.friction_cfg();
        let pcfg = self.phase_cfg();
        let ccfg = CombinedConfig {
            cutoff_hz: self.cutoff_hz,
            ..CombinedConfig::default()
        };
        let mut r = Report::default();
        let inertia =
            |exps: &[Experiment], f: Option<&FrictionFit>| -> Result<InertiaFit, IdentError> {
                match self.inertia_method {
                    InertiaMethod::Phases => identify_inertia(exps, f, &pcfg),
                    InertiaMethod::Ls => identify_inertia_ls(exps, f, &pcfg),
                }
            };
        match self.method {
            Some(Method::Friction) => r.friction = Some(identify_friction(exps, p.n, &fcfg)?),
            Some(Method::Combined) => r.combined = Some(identify_combined(exps, p.n, &ccfg)?),
            Some(Method::Electrical) => r.electrical = Some(identify_electrical(exps, p, &fcfg)?),
            Some(Method::Inertia) => {
                let (fr, ir) = split_logs(exps, &fcfg, &pcfg)?;
                if ir.is_empty() {
                    inertia(exps, None)?; // produces the explanation
                }
                let f = if fr.is_empty() {
                    None
                } else {
                    identify_friction(&fr, p.n, &fcfg).ok()
                };
                r.friction = f.clone();
                r.inertia = Some(inertia(&ir, f.as_ref())?);
            }
            None => {
                let (fr, ir) = split_logs(exps, &fcfg, &pcfg)?;
                if !fr.is_empty() {
                    match identify_friction(&fr, p.n, &fcfg) {
                        Ok(f) => r.friction = Some(f),
                        Err(e) => r.skipped.push(format!("friction: {e}")),
                    }
                    if fr.iter().any(|e| e.u_v.is_some()) {
                        match identify_electrical(&fr, p, &fcfg) {
                            Ok(e) => r.electrical = Some(e),
                            Err(e) => r.skipped.push(format!("electrical: {e}")),
                        }
                    }
                } else {
                    r.skipped.push(String::from(
                        "friction: no log has constant-speed segments at two or more speeds (handout 4.1 staircase)",
                    ));
                }
                if !ir.is_empty() {
                    match inertia(&ir, r.friction.as_ref()) {
                        Ok(i) => r.inertia = Some(i),
                        Err(e) => r.skipped.push(format!("inertia: {e}")),
                    }
                } else {
                    r.skipped.push(String::from(
                        "inertia: no log has constant acceleration/deceleration phases (handout 4.2)",
                    ));
                }
                if r.friction.is_none() || r.inertia.is_none() {
                    match identify_combined(exps, p.n, &ccfg) {
                        Ok(c) => r.combined = Some(c),
                        Err(e) => r.skipped.push(format!("combined: {e}")),
                    }
                }
                if r.b_eq().is_none() && r.j_eq().is_none() {
                    bail!(
                        "nothing could be identified from these logs:\n  {}",
                        r.skipped.join("\n  ")
                    );
                }
            }
        }
        Ok(r)
    }
}

/// Splits the experiments into those with constant-speed segments at >= 2 speeds (friction) and
/// those with >= 2 acceleration phases (inertia). A log may be in both.
pub(super) fn split_logs(
    exps: &[Experiment],
    fcfg: &FrictionConfig,
    pcfg: &PhaseConfig,
) -> anyhow::Result<(Vec<Experiment>, Vec<Experiment>)> {
    let mut fr = Vec::new();
    let mut ir = Vec::new();
    for e in exps {
        let pts = friction_points(std::slice::from_ref(e), fcfg)?;
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
