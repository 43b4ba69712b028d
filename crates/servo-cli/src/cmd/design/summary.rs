//! `servo design`: the default text. The answer first (the gains, what `servo run` will give with
//! them, whether the time-domain specs are met), then the margins and what to look at; the
//! spec translation, the linear loops' table, the poles and every step case under `--verbose`.
//!
//! One figure per question: the step response quoted is the one `servo run --gains` gives on the
//! plant the design names (friction, the drive's limit, the discrete PID as run builds it), not a
//! linear loop's.

use super::*;
use servo_hw::run::step_cases::StepStart;

impl super::Design {
    /// The default text report. `unit`: the controller output's unit (V, or A on a current drive).
    pub(super) fn summary_report(&self, out: &Outcome, src: &PlantSource, unit: &str) -> String {
        let mut s = String::new();
        let r = &out.report;
        let g = &r.gains;
        let ls = r.request.spec;
        let how = if self.meet_specs {
            ", found by --meet-specs"
        } else if self.exact {
            ", exact on the discrete loop (--exact)"
        } else {
            ""
        };
        let plant = if src.bare_reduced {
            "the reduced model given by --km/--tm".to_string()
        } else {
            self.plant_words()
        };
        let _ = writeln!(
            s,
            "servo design: {} by Bode's method (eqs. 44-53) for w_gc = {} rad/s, phase margin {} deg{how}, on {plant}",
            r.request.kind.name().to_uppercase(),
            sig(ls.omega_gc),
            sig(deg(ls.phase_margin)),
        );
        let _ = writeln!(
            s,
            "  K_P = {} {unit}/rad   K_I = {} {unit}/(rad s)   K_D = {} {unit} s/rad   T_L = {} s   T_s = {} s",
            sig(g.kp),
            sig(g.ki),
            sig(g.kd),
            sig(g.tl_s),
            sig(r.request.ts_s)
        );
        match &out.run_check {
            Some(rc) => run_headline(&mut s, rc, out.structure.u_limit_v, unit),
            None => {
                // --km/--tm: no plant `servo run` could simulate; the linear discrete loop's step
                if let Some(st) = r.discrete.step {
                    let _ = writeln!(
                        s,
                        "step response of the linear discrete loop (no plant to simulate with --km/--tm): overshoot {:.1} %, settling 5 % {}",
                        st.overshoot_pct,
                        st.settling_time_5pct_s.map_or("not settled".into(), |t| format!("{} s", sig(t)))
                    );
                }
            }
        }
        if let Some(c) = &out.check {
            self.specs_verdict(&mut s, out, c);
        }
        margins_lines(&mut s, r);
        let pm_short = deg(ls.phase_margin) - r.discrete.margins.phase_margin_deg;
        if !self.exact && !self.meet_specs && pm_short > 0.5 {
            let _ = writeln!(
                s,
                "note: the derivative filter and the ZOH delay cost {pm_short:.2} deg of the phase margin asked; --exact compensates."
            );
        }
        if r.request.alpha < 4.0 && r.request.kind == ControllerKind::Pid {
            let _ = writeln!(
                s,
                "note: alpha < 4 gives complex PID zeros (the handout recommends alpha >= 4)."
            );
        }
        if let Some(c) = &out.compensated {
            super::compensated::compensated_section(&mut s, c);
        }
        s
    }

    /// Whether the time-domain specs are met, in one or two lines, and what would meet them.
    fn specs_verdict(&self, s: &mut String, out: &Outcome, c: &RangeCheck) {
        let sp = &c.specs;
        let mut asked = Vec::new();
        if let Some(m) = sp.overshoot_max {
            asked.push(format!("overshoot <= {} %", sig(100.0 * m)));
        }
        if let Some(t) = speed_spec_s(sp) {
            asked.push(format!(
                "{} <= {} s",
                speed_label(sp).trim_end_matches(" [s]"),
                sig(t)
            ));
        }
        let asked = format!(
            "{}, steps {}-{} rad",
            asked.join(", "),
            sig(sp.step_min_rad),
            sig(sp.step_max_rad)
        );
        if out.time_specs_met() == Some(true) {
            let _ = writeln!(
                s,
                "time-domain specs ({asked}): MET in every case, on the design's loop model and through `servo run`"
            );
            return;
        }
        let (os, speed) = match &out.run_check {
            Some(rc) => (worst_overshoot(rc), worst_settling(rc)),
            None => (c.worst_overshoot_pct, c.worst_speed_s),
        };
        let missed = out.run_check.as_ref().map_or(String::new(), |rc| {
            format!(" in {} of {} cases", rc.failing().len(), rc.cases.len())
        });
        let _ = writeln!(
            s,
            "time-domain specs ({asked}): NOT met{missed}: the worst case overshoots {os:.1} % and {}",
            speed.map_or("does not settle".into(), |t| format!("settles in {} s", sig(t)))
        );
        let advice = if self.meet_specs {
            format!(
                "the closest design found reaches overshoot {os:.1} %{}: ask for that, or change the loop \
                 (a shorter --ts, a larger --u-limit, a lower --wc)",
                speed.map_or(String::new(), |t| format!(" with settling {} s", sig(t)))
            )
        } else {
            "--meet-specs searches w_gc, the phase margin, alpha, T_L and the anti-windup on the loop that runs"
                .to_string()
        };
        let _ = writeln!(s, "  to meet them: {advice}");
    }
}

/// The answer: the step response `servo run --gains` gives, a 1 rad (largest) step at t = 0 first,
/// then the range over every case.
fn run_headline(s: &mut String, rc: &RunCheck, u_limit: f64, unit: &str) {
    let Some(last) = rc.cases.last() else {
        return;
    };
    let top = last.step_rad;
    let main = rc
        .cases
        .iter()
        .find(|c| c.start == StepStart::AtStart && (c.step_rad - top).abs() < 1e-12);
    let _ = writeln!(
        s,
        "as `servo run --gains` runs it (simulator on {}, limit +-{} {unit}):",
        rc.plant,
        sig(u_limit)
    );
    if let Some(m) = main {
        let _ = writeln!(
            s,
            "  a {} rad step (`--ref step:{}`) overshoots {:.1} % and settles (5 %) in {}",
            sig(top),
            sig(top),
            m.overshoot_pct,
            m.settling_time_s
                .map_or("more than the simulated time".into(), |t| format!(
                    "{} s",
                    sig(t)
                ))
        );
    }
    if rc.cases.iter().any(|c| c.settling_time_s.is_none()) {
        let _ = writeln!(
            s,
            "  some of the {} step cases checked do not settle: see --verbose",
            rc.cases.len()
        );
    }
}

fn worst_overshoot(rc: &RunCheck) -> f64 {
    rc.cases.iter().map(|c| c.overshoot_pct).fold(0.0, f64::max)
}

/// The worst 5 % settling time, `None` when some case does not settle.
fn worst_settling(rc: &RunCheck) -> Option<f64> {
    rc.cases
        .iter()
        .map(|c| c.settling_time_s)
        .try_fold(0.0_f64, |acc, t| t.map(|t| acc.max(t)))
}

/// The discrete loop's margins, and what a negative gain margin means.
fn margins_lines(s: &mut String, r: &DesignReport) {
    let dm = &r.discrete.margins;
    let _ = writeln!(
        s,
        "margins of the linear discrete loop: w_gc {} rad/s, phase margin {} deg, gain margin {} dB; closed loop {}",
        fmt_f(dm.omega_gc, 2),
        fmt_f(dm.phase_margin_deg, 2),
        fmt_gm(dm.gain_margin_db),
        stability_name(r.discrete.stability)
    );
    if dm.gain_margin_db.is_finite()
        && dm.gain_margin_db < 0.0
        && r.discrete.stability == Stability::Stable
    {
        let _ = writeln!(
            s,
            "  a negative gain margin on a stable loop: the loop is conditionally stable. Lowering its gain by \
             {:.1} dB makes it unstable, and a drive that saturates lowers the loop's effective gain on large \
             errors: large steps may oscillate or diverge. Check them with `servo run`, or lower w_gc.",
            -dm.gain_margin_db
        );
    }
    let loops = [Some(&r.reduced), r.full.as_ref(), Some(&r.discrete)];
    for a in loops.into_iter().flatten() {
        if a.stability != Stability::Stable {
            let _ = writeln!(
                s,
                "WARNING: the {} loop is {}.",
                a.name,
                stability_name(a.stability)
            );
        }
    }
}

/// A number to six significant figures at most, without trailing zeros.
pub(crate) fn sig(x: f64) -> String {
    if !x.is_finite() {
        return if x.is_infinite() { "inf" } else { "none" }.into();
    }
    if x == 0.0 {
        return "0".into();
    }
    let mag = x.abs().log10().floor() as i32;
    if !(-4..6).contains(&mag) {
        let t = format!("{x:.5e}");
        return match t.split_once('e') {
            Some((m, e)) if m.contains('.') => {
                format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.'))
            }
            _ => t,
        };
    }
    let decimals = (5 - mag).max(0) as usize;
    let t = format!("{x:.decimals$}");
    if t.contains('.') {
        t.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        t
    }
}

#[cfg(test)]
mod tests {
    use super::sig;

    #[test]
    fn six_significant_figures_at_most() {
        assert_eq!(sig(7.866411234), "7.86641");
        assert_eq!(sig(88.34936), "88.3494");
        assert_eq!(sig(0.001), "0.001");
        assert_eq!(sig(30.0), "30");
        assert_eq!(sig(0.006666667), "0.00666667");
        assert_eq!(sig(-12.5), "-12.5");
        assert_eq!(sig(0.0), "0");
        assert_eq!(sig(f64::INFINITY), "inf");
        assert!(sig(1.23456789e-7).starts_with("1.2345"));
        assert!(sig(1.23456789e-7).ends_with("e-7"));
    }
}
