//! `servo design`: the text sections of `--meet-specs` and of the time-domain specs check.

use super::*;

/// The --meet-specs summary: what was searched, what was found, the margins, the verdict.
pub(super) fn meet_section(
    s: &mut String,
    m: &MeetResult,
    ms: f64,
    tr: &Translation,
    d: &Design,
    run: Option<&RunCheck>,
) {
    let p = &m.params;
    let c = &m.check;
    let _ = writeln!(
        s,
        "
--meet-specs: searched w_gc, phase margin, alpha, T_L, the derivative input and K_w on the loop that runs \
         ({} designs simulated in {ms:.0} ms)",
        m.evaluations
    );
    let _ = writeln!(
        s,
        "  handout's design: w_gc = {:.3} rad/s, PM = {:.2} deg, alpha = {}, 1/T_L = {} w_gc, derivative on the {}",
        tr.spec.omega_gc,
        deg(tr.spec.phase_margin),
        d.alpha,
        d.tl.map_or(format!("{}", d.tl_factor), |t| format!("{:.3}", 1.0 / (t * tr.spec.omega_gc))),
        derivative_name(d.derivative_on.into())
    );
    let _ = writeln!(
        s,
        "  found:            w_gc = {:.3} rad/s, PM = {:.2} deg, alpha = {:.3}, 1/T_L = {:.3} w_gc, derivative on the {}, K_w = {:.4} 1/s",
        p.omega_gc,
        deg(p.phase_margin),
        p.alpha,
        p.tl_factor,
        derivative_name(p.derivative_on),
        p.kw_per_s
    );
    let dm = &m.report.discrete.margins;
    let _ = writeln!(
        s,
        "  margins it ends with (discrete loop): phase margin {} deg at w_gc = {} rad/s, gain margin {} dB, \
         sensitivity peak Ms = {:.3} ({:.2} dB)",
        fmt_f(dm.phase_margin_deg, 2),
        fmt_f(dm.omega_gc, 3),
        fmt_gm(dm.gain_margin_db),
        m.sensitivity_peak,
        20.0 * m.sensitivity_peak.log10()
    );
    let (lo, hi) = (c.specs.step_min_rad, c.specs.step_max_rad);
    let worst_speed = c
        .worst_speed_s
        .map_or("not settled".into(), |t| format!("{t:.4} s"));
    let missed_in_run = run.map_or(0, |r| r.failing().len());
    if m.feasible && missed_in_run > 0 {
        let _ = writeln!(
            s,
            "  result: the specs are NOT met: the search met them on its model of the loop (worst overshoot {:.2} %), \
             but `servo run` with these gains on {} misses them in {missed_in_run} case(s), listed below",
            c.worst_overshoot_pct,
            run.map_or(String::new(), |r| r.plant.clone())
        );
    } else if m.feasible {
        let _ = writeln!(
            s,
            "  result: the specs are MET for every step from {lo} to {hi} rad, at t = 0, later and after a previous move: \
             worst overshoot {:.2} %, worst {} {} (on the design's loop model; `servo run`'s loop below)",
            c.worst_overshoot_pct,
            speed_label(&c.specs).trim_end_matches(" [s]"),
            worst_speed
        );
    } else {
        let _ = writeln!(
            s,
            "  result: the specs are INFEASIBLE on this loop (plant, T_s, +-{} V) within the search box; \
             the closest achievable pair is overshoot {:.2} %, {} {} (worst over {lo}..{hi} rad) with the design above",
            m.structure.u_limit_v,
            c.worst_overshoot_pct,
            speed_label(&c.specs).trim_end_matches(" [s]"),
            worst_speed
        );
    }
}

/// The time-domain check: achieved figures per step size next to the spec, and a warning in words
/// when missed.
pub(super) fn check_section(s: &mut String, c: &RangeCheck, r: &DesignReport, meet: bool) {
    let sp = &c.specs;
    let _ = writeln!(
        s,
        "
time-domain specs on the loop that runs ({} model, ZOH at T_s = {} s, {}), steps {}..{} rad:",
        r.discrete.plant,
        r.request.ts_s,
        structure_words(&c.structure),
        sp.step_min_rad,
        sp.step_max_rad
    );
    let _ = writeln!(
        s,
        "  {:<12}{:>16}{:>20}{:>16}",
        "step [rad]",
        "overshoot [%]",
        speed_label(sp),
        "peak |u| [V]"
    );
    let _ = writeln!(
        s,
        "  {:<12}{:>16}{:>20}",
        "spec",
        sp.overshoot_max
            .map_or("-".into(), |m| format!("<= {:.2}", 100.0 * m)),
        speed_spec_s(sp).map_or("-".into(), |t| format!("<= {t:.4}"))
    );
    let n = c.outcomes.len();
    let rows: Vec<usize> = if n <= 5 {
        (0..n).collect()
    } else {
        (0..5).map(|k| k * (n - 1) / 4).collect()
    };
    let rise = matches!(sp.speed, Some(SpeedTarget::Rise { .. }));
    for k in rows {
        let o = &c.outcomes[k];
        let speed = if rise {
            o.rise_time_s
        } else {
            o.settling_time_s
        };
        let _ = writeln!(
            s,
            "  {:<12.4}{:>16.2}{:>20}{:>16}",
            o.step_rad,
            o.overshoot_pct,
            speed.map_or("not settled".into(), |t| format!("{t:.4}")),
            format!(
                "{:.2}{}",
                o.peak_u_v,
                if o.saturated_fraction > 0.0 {
                    " (limit)"
                } else {
                    ""
                }
            )
        );
    }
    let _ = writeln!(
        s,
        "  {:<12}{:>16.2}{:>20}   (over {} step sizes)",
        "worst",
        c.worst_overshoot_pct,
        c.worst_speed_s
            .map_or("not settled".into(), |t| format!("{t:.4}")),
        n
    );
    if let (Some(first), Some(lin)) = (c.outcomes.first(), r.discrete.step) {
        if first.saturated_fraction > 0.0 {
            let _ = writeln!(
                s,
                "  note: even the {} rad step reaches the voltage limit; smaller steps stay linear and behave as the \
                 'discrete' column above ({:.2} % overshoot, settling 5 % {} s)",
                first.step_rad,
                lin.overshoot_pct,
                opt(lin.settling_time_5pct_s)
            );
        }
    }
    if c.met() {
        let _ = writeln!(
            s,
            "  the time-domain specs are met for every step size checked."
        );
        return;
    }
    let _ = writeln!(
        s,
        "WARNING: the design MISSES the time-domain specs on the loop that will run:"
    );
    if let (Some(ex), Some(m)) = (c.overshoot_excess_pct(), sp.overshoot_max) {
        let _ = writeln!(
            s,
            "  overshoot {:.2} % exceeds the spec {:.2} % by {ex:.2} percentage points ({:.1} x the spec)",
            c.worst_overshoot_pct,
            100.0 * m,
            c.worst_overshoot_pct / (100.0 * m)
        );
    }
    if let (Some(ex), Some(t)) = (c.speed_excess_s(), speed_spec_s(sp)) {
        let what = speed_label(sp).trim_end_matches(" [s]").to_string();
        match c.worst_speed_s {
            Some(w) => {
                let _ = writeln!(
                    s,
                    "  {what} {w:.4} s exceeds the spec {t} s by {ex:.4} s ({:+.0} %)",
                    100.0 * ex / t
                );
            }
            None => {
                let _ = writeln!(
                    s,
                    "  {what}: some step does not settle within the simulated {:.2} s (spec {t} s)",
                    c.outcomes.first().map_or(0.0, |o| o.horizon_s)
                );
            }
        }
    }
    if !meet {
        let _ = writeln!(
            s,
            "  (the handout's translation, eqs. 36-41, assumes a second-order loop without PID zeros, derivative \
             filter, ZOH or voltage limit; --meet-specs searches for a design that meets the specs)"
        );
    }
}
