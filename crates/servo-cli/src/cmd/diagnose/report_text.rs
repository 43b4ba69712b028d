//! `servo diagnose`: the text report (also the core of the HTML one).

use super::*;

/// The headline of the text and HTML outputs: the final status and, after `--auto`, what was
/// added on the way.
pub(super) fn headline(ladder: &[Rung], last: &Diagnosis) -> String {
    let added: Vec<String> = ladder
        .iter()
        .flat_map(|r| {
            r.added
                .into_iter()
                .chain(r.added_with)
                .chain(r.added_also.iter().copied())
        })
        .map(|k| k.name().to_string())
        .collect();
    let status = match last.status {
        servo_core::diagnose::Status::Complete => "complete: nothing material is left",
        servo_core::diagnose::Status::Missing if last.winner().is_some() => {
            "missing: a catalogue effect is still missing"
        }
        servo_core::diagnose::Status::Missing => {
            "missing: a user-defined or discovered effect passes every guard (no catalogue effect does)"
        }
        servo_core::diagnose::Status::Unexplained => {
            "unexplained: structured error above the noise floor that no catalogue effect explains"
        }
    };
    if added.is_empty() {
        format!("Status: {status}")
    } else {
        format!("Added {}; status after them: {status}", added.join(", "))
    }
}

/// The one line every simulating command prints: which plant (the model file, its effects, its
/// base refitted) and which controller: none, the logged input drives the model over short
/// horizons from the measured state (the same on closed-loop logs).
pub(super) fn plant_and_controller(
    model_path: &std::path::Path,
    model: &servo_core::plant::Plant,
    opts: &DiagnoseOptions,
) -> String {
    let mut effects: Vec<String> = model
        .effects
        .iter()
        .map(|e| e.kind.name().to_string())
        .collect();
    effects.extend(
        model
            .custom
            .iter()
            .map(|e| format!("{} (user-defined)", e.name())),
    );
    let effects = if effects.is_empty() {
        String::from("no effects beyond the base model")
    } else {
        format!("effects: {}", effects.join(", "))
    };
    format!(
        "simulated plant: the model of {} ({effects}; base parameters refitted on the logs, each candidate effect fitted with them); \
         controller: none in the simulation (the logged u drives the model over {} s horizons from the measured state, on closed-loop logs too)",
        model_path.display(),
        servo_core::math::sig(opts.fit.oe_horizon_s, 3)
    )
}

pub(super) fn where_it_fails(d: &Diagnosis) -> String {
    let mut s = String::new();
    for (eq, rms, share, occ) in &d.base.equations {
        let _ = writeln!(s, "  {}: residual {:.3e} {} RMS", eq.name(), rms, eq.unit());
        let mut idx: Vec<usize> = (0..5).filter(|&i| occ[i] > 0.0).collect();
        idx.sort_by(|&a, &b| (share[b] / occ[b]).total_cmp(&(share[a] / occ[a])));
        for &i in idx.iter().take(2) {
            if share[i] / occ[i] > 1.2 {
                let _ = writeln!(
                    s,
                    "    {:.0} % of the squared error sits {} ({:.0} % of the samples)",
                    100.0 * share[i],
                    Regime::ALL[i].phrase(),
                    100.0 * occ[i]
                );
            }
        }
    }
    s
}

pub(super) fn text_report(
    first: &Diagnosis,
    ladder: &[Rung],
    diags: &[Diagnosis],
    auto: bool,
    opts: &DiagnoseOptions,
) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "Model residual (base parameters refitted):");
    s.push_str(&where_it_fails(first));
    s.push_str(&balances_text(first));
    s.push_str(&friction_text(first));
    for (step, d) in diags.iter().enumerate() {
        if auto {
            let _ = writeln!(s, "\nStep {}:", step + 1);
        }
        let _ = writeln!(s, "\nCandidates, best first:");
        s.push_str(&candidates_table(&d.ranking, opts));
        if let Some(w) = d.ranking.first() {
            let _ = writeln!(s, "\nBest candidate: {}", w.evidence);
        }
        let _ = writeln!(s, "\nVerdict: {}", d.verdict);
    }
    let _ = writeln!(
        s,
        "\nBars (thresholds that can refuse an effect or a verdict):"
    );
    s.push_str(&bars_text(opts));
    if auto {
        let _ = writeln!(s, "\nError ladder:");
        s.push_str(&ladder_text(ladder));
    }
    if let Some(last) = diags.last() {
        let _ = writeln!(s, "\n{}", headline(ladder, last));
    }
    s
}

pub(super) fn ladder_text(ladder: &[Rung]) -> String {
    let mut s = String::new();
    for r in ladder {
        let name = r.added.map_or("starting model".to_string(), |k| {
            let mut s = format!("+ {k}");
            for w in r.added_with.iter().chain(&r.added_also) {
                s.push_str(&format!(" + {w}"));
            }
            s
        });
        let eqs: Vec<String> = r
            .equations
            .iter()
            .map(|(e, v)| format!("{} {:.3e} {}", e.name(), v, e.unit()))
            .collect();
        let oe = r
            .oe_cost_rad
            .map_or(String::new(), |v| format!(", prediction error {v:.3e} rad"));
        let _ = writeln!(s, "  {name:<16} {}{oe}", eqs.join(", "));
    }
    s
}

/// The linear axis' lines of the text report: the best candidate's effect and base in linear
/// units, the ladder's prediction errors in millimetres.
pub(super) fn linear_text(axis: &crate::axis::Axis, last: &Diagnosis, ladder: &[Rung]) -> String {
    let mut s = format!("\n{}\n", axis.describe());
    if let Some(c) = last.ranking.first() {
        let p = &c.plant.params;
        if let Some(e) = c.plant.effects.get(c.effect) {
            let _ = writeln!(
                s,
                "  best candidate {}: {}",
                c.effect.name(),
                axis.effect_text(e)
            );
        }
        s.push_str(&axis.base_text(p.j_eq(), p.b_eq(), p.tau_sf()));
    }
    let m = axis.transmission.metres_per_rad().unwrap_or(f64::NAN);
    for r in ladder {
        if let Some(c) = r.oe_cost_rad {
            let name = r
                .added
                .map_or("starting model".to_string(), |k| format!("+ {k}"));
            let _ = writeln!(s, "  {name:<16} prediction error {:.4} mm", c * m * 1e3);
        }
    }
    s
}

/// The measured friction curve as a table (load side, both directions), and its shape.
pub(super) fn friction_text(d: &Diagnosis) -> String {
    let mut s = String::new();
    let Some(c) = &d.friction_curve else {
        return s;
    };
    let _ = writeln!(
        s,
        "\nMeasured friction curve ({}, {} sliding rows away from standstill and reversals; load side):",
        c.equation.name(),
        c.sliding_rows
    );
    let _ = writeln!(
        s,
        "  {:>4} {:>19} {:>11} {:>13} {:>11} {:>11} {:>6}",
        "dir", "|speed| bin [rad/s]", "mean rad/s", "friction N m", "95 % +/-", "model N m", "rows"
    );
    for b in &c.bins {
        let _ = writeln!(
            s,
            "  {:>4} {:>9.3}-{:<9.3} {:>11.3} {:>13.4e} {:>11.1e} {:>11.4e} {:>6}",
            if b.direction > 0 { "fwd" } else { "bwd" },
            b.speed_lo_rad_s,
            b.speed_hi_rad_s,
            b.speed_rad_s,
            b.torque_nm,
            b.ci_nm,
            b.model_nm,
            b.rows
        );
    }
    match &c.shape {
        Some(sh) => {
            let _ = writeln!(s, "  Shape beyond the model: {}.", sh.description);
        }
        None => {
            let _ = writeln!(
                s,
                "  No shape beyond the model's Coulomb and viscous friction stands out."
            );
        }
    }
    s
}

/// The residual of each balance against its noise floor, one line each, with its strongest
/// shape (the "Model residual" block of the verbose report).
pub(super) fn balances_text(first: &Diagnosis) -> String {
    let mut s = String::new();
    for b in &first.balances {
        // A floor of 0 (no sensor noise model for this balance, e.g. no current logged) is
        // unknown, not zero: the residual is then said in its own unit, never "inf x".
        let level = if b.floor > 0.0 && b.floor.is_finite() && b.ratio_to_noise.is_finite() {
            format!(
                "noise floor {} {}, residual {} x the floor",
                servo_core::math::sig(b.floor, 3),
                b.equation.unit(),
                servo_core::math::sig(b.ratio_to_noise, 3)
            )
        } else {
            format!(
                "noise floor unknown (the logs give no sensor noise for this balance, e.g. no current), \
                 residual RMS {} {}: how much of it is structure cannot be said against noise",
                servo_core::math::sig(b.rms, 3),
                b.equation.unit()
            )
        };
        let _ = writeln!(
            s,
            "  {}: {level}{}",
            b.equation.name(),
            b.signatures.first().map_or(String::new(), |g| format!(
                "; strongest shape: {} ({:.0} % of the held-out {}; measured on {})",
                g.description,
                100.0 * g.share,
                g.share_of(),
                g.measured_on
            ))
        );
    }
    s
}

/// The candidates table: header and one row per candidate.
pub(super) fn candidates_table(ranking: &[Candidate], opts: &DiagnoseOptions) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "  {:<11} {:>11} {:>12} {:>10} {:>9}  refused by",
        "effect",
        "significant",
        servo_core::diagnose::phrase::RMS_DROP_COLUMN,
        "sim. drop",
        "BIC gain"
    );
    for c in ranking {
        let refused = if c.significant {
            String::new()
        } else {
            servo_core::diagnose::bars::refused_by(c, opts)
                .or_else(|| {
                    c.failed_check()
                        .map(|k| format!("{}: {}", k.name, k.detail))
                })
                .unwrap_or_default()
        };
        let _ = writeln!(
            s,
            "  {:<11} {:>11} {:>11}% {:>10} {:>9.1}  {refused}",
            c.effect.name(),
            if c.significant {
                "YES"
            } else if c.resolvable {
                "no"
            } else {
                "unresolved"
            },
            servo_core::diagnose::phrase::pct(c.error_reduction_pct),
            c.oe_reduction_pct.map_or("-".to_string(), |v| format!(
                "{}%",
                servo_core::diagnose::phrase::pct(v)
            )),
            c.bic_gain
        );
    }
    s
}

/// The bars (every threshold that can refuse an effect or a verdict), one row each.
pub(super) fn bars_text(opts: &DiagnoseOptions) -> String {
    let mut s = String::new();
    for b in servo_core::diagnose::bars::bars(opts) {
        let _ = writeln!(
            s,
            "  {:<27} {} {} {:<14} {}",
            b.name, b.rule, b.value, b.unit, b.why
        );
    }
    s
}
