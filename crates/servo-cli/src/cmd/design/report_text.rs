//! `servo design`: the text report (design, verification table, time-domain specs check).

use super::*;

impl super::Design {
    pub(super) fn text_report(
        &self,
        out: &Outcome,
        tr: &Translation,
        translation: &[String],
        src: &PlantSource,
        unit: &str,
    ) -> String {
        let mut s = String::new();
        let r = &out.report;
        let g = &r.gains;
        let model = self.design_model(r);
        // the loop spec of the gains: the translation, or what --meet-specs found
        let ls = r.request.spec;
        let w = ls.omega_gc;
        let _ = writeln!(
            s,
            "servo design: {} by Bode's method (handout eqs. 44-53) on the {} model",
            r.request.kind.name().to_uppercase(),
            model.name()
        );
        match r.request.reduced {
            PlantModel::Reduced { k_m, t_m, n } => {
                let _ = writeln!(
                    s,
                    "plant: {}; reduced model P(s) = k_m/((T_m s + 1) N s), k_m = {k_m:.6} rad/(V s), T_m = {t_m:.6} s, N = {n}",
                    if src.bare_reduced { "given by --km/--tm".to_string() } else { src.label.clone() }
                );
            }
            PlantModel::Full { .. } => {}
        }
        let _ = writeln!(s, "\nspec translation:");
        for l in translation {
            let _ = writeln!(s, "  {l}");
        }
        // the translation's crossover (--meet-specs moves the design's: its section says where)
        let p_gc = model.response(tr.spec.omega_gc);
        let (dk, dphi) = required_compensation(&tr.spec, p_gc);
        let _ = writeln!(
            s,
            "  P(j w_gc) = {:.6} {:+.6}j (|P| = {:.6}, angle {:.3} deg) -> Delta K = {:.6}, Delta phi = {:.3} deg (eq. 44)",
            p_gc.re,
            p_gc.im,
            c_abs(p_gc),
            deg(c_arg(p_gc)),
            dk,
            deg(dphi)
        );
        if let Some((m, ms)) = &out.meet {
            meet_section(&mut s, m, *ms, tr, self, out.run_check.as_ref());
        }
        let _ = writeln!(
            s,
            "\ngains{}:",
            if self.exact {
                " (--exact: w_gc and phase margin on the discrete loop equal the loop spec; the step \
                 response is checked below)"
            } else if self.meet_specs {
                " (--meet-specs)"
            } else {
                ""
            }
        );
        let _ = writeln!(
            s,
            "  K_P = {:<12.6} {unit}/rad        T_I = {} s",
            g.kp,
            fmt_s(g.ti_s())
        );
        let _ = writeln!(
            s,
            "  K_I = {:<12.6} {unit}/(rad s)    T_D = {} s",
            g.ki,
            fmt_s(g.td_s())
        );
        let tl_note = match (self.tl, r.request.kind, &out.meet) {
            (_, ControllerKind::Pi, _) => "(no derivative)".to_string(),
            (_, _, Some((m, _))) => format!(
                "(1/T_L = {:.3} w_gc, chosen by --meet-specs)",
                m.params.tl_factor
            ),
            (Some(_), _, _) => "(given)".to_string(),
            (None, _, _) => format!("(1/T_L = {} w_gc, eq. 53)", self.tl_factor),
        };
        let _ = writeln!(
            s,
            "  K_D = {:<12.6} {unit} s/rad      T_L = {} s {tl_note}",
            g.kd,
            fmt_s(g.tl_s)
        );
        if self.exact {
            let h = &r.handout_gains;
            let _ = writeln!(
                s,
                "  (handout formulas would give K_P = {:.6}, K_I = {:.6}, K_D = {:.6})",
                h.kp, h.ki, h.kd
            );
        }
        let disc_plant = if r.request.full.is_some() {
            "full"
        } else {
            "reduced"
        };
        let _ = writeln!(
            s,
            "\nverification (real derivative; discrete = {} model, ZOH at T_s = {} s, {} PID):",
            disc_plant,
            r.request.ts_s,
            r.request.discretization.name()
        );
        let loops: Vec<&Achieved> = [Some(&r.reduced), r.full.as_ref(), Some(&r.discrete)]
            .into_iter()
            .flatten()
            .collect();
        let _ = write!(s, "  {:<22}{:>12}", "", "spec");
        for a in &loops {
            let _ = write!(s, "{:>12}", a.name);
        }
        let _ = writeln!(s);
        let d = if self.meet_specs {
            damping_from_phase_margin(ls.phase_margin).unwrap_or(tr.delta)
        } else {
            tr.delta
        };
        let rows: [Row; 8] = [
            (
                "w_gc [rad/s]",
                format!("{w:.4}"),
                Box::new(|a: &Achieved| fmt_f(a.margins.omega_gc, 4)),
            ),
            (
                "phase margin [deg]",
                format!("{:.3}", deg(ls.phase_margin)),
                Box::new(|a: &Achieved| fmt_f(a.margins.phase_margin_deg, 3)),
            ),
            (
                "gain margin [dB]",
                "-".into(),
                Box::new(|a: &Achieved| fmt_gm(a.margins.gain_margin_db)),
            ),
            (
                "overshoot [%]",
                format!(
                    "~{:.2}",
                    100.0 * servo_core::design::spec::overshoot_from_damping(d)
                ),
                Box::new(|a: &Achieved| {
                    a.step
                        .map_or("-".into(), |m| format!("{:.2}", m.overshoot_pct))
                }),
            ),
            (
                "rise 10-90 % [s]",
                format!("~{:.4}", 1.8 / w),
                Box::new(|a: &Achieved| a.step.map_or("-".into(), |m| opt(m.rise_time_s))),
            ),
            (
                "settling 5 % [s]",
                format!("~{:.4}", 3.0 / (d * w)),
                Box::new(|a: &Achieved| a.step.map_or("-".into(), |m| opt(m.settling_time_5pct_s))),
            ),
            (
                "settling 1 % [s]",
                format!("~{:.4}", 4.6 / (d * w)),
                Box::new(|a: &Achieved| a.step.map_or("-".into(), |m| opt(m.settling_time_1pct_s))),
            ),
            (
                "closed loop",
                "".into(),
                Box::new(|a: &Achieved| stability_name(a.stability).into()),
            ),
        ];
        for (name, spec, f) in rows.iter() {
            let _ = write!(s, "  {name:<22}{spec:>12}");
            for a in &loops {
                let _ = write!(s, "{:>12}", f(a));
            }
            let _ = writeln!(s);
        }
        let _ = writeln!(
            s,
            "  (spec column: time figures are the 2nd-order estimates of eqs. 32-33, 39-40)"
        );
        let _ = writeln!(s, "\nclosed-loop poles:");
        for a in &loops {
            let unit = if a.name == "discrete" {
                "z"
            } else {
                "s [rad/s]"
            };
            let poles: Vec<String> = a
                .poles
                .iter()
                .map(|p| format!("{:.4}{:+.4}j", p.re, p.im))
                .collect();
            let _ = writeln!(s, "  {:<9} {unit}: {}", a.name, poles.join(", "));
        }
        let pm_short = deg(ls.phase_margin) - r.discrete.margins.phase_margin_deg;
        if !self.exact && !self.meet_specs && pm_short > 0.5 {
            let _ = writeln!(
                s,
                "\nnote: the derivative filter and the ZOH delay cost {pm_short:.2} deg of phase margin on the discrete loop; \
                 use --exact to compensate."
            );
        }
        if r.request.alpha < 4.0 && r.request.kind == ControllerKind::Pid {
            let _ = writeln!(
                s,
                "note: alpha < 4 gives complex PID zeros (the handout recommends alpha >= 4)."
            );
        }
        for a in &loops {
            if a.stability != Stability::Stable {
                let _ = writeln!(
                    s,
                    "WARNING: the {} loop is {}.",
                    a.name,
                    stability_name(a.stability)
                );
            }
        }
        if let Some(c) = &out.check {
            check_section(&mut s, c, r, out.meet.is_some());
        }
        if let Some(rc) = &out.run_check {
            run_section(&mut s, rc);
        }
        if let Some(c) = &out.compensated {
            super::compensated::compensated_section(&mut s, c);
        }
        s
    }
}

/// One row of the verification table: name, spec column, value per loop.
pub(super) type Row = (&'static str, String, Box<dyn Fn(&Achieved) -> String>);

pub(super) fn fmt_f(x: f64, prec: usize) -> String {
    if x.is_finite() {
        format!("{x:.prec$}")
    } else {
        "none".into()
    }
}

pub(super) fn fmt_gm(x: f64) -> String {
    if x.is_infinite() {
        "inf".into()
    } else {
        format!("{x:.2}")
    }
}

pub(super) fn fmt_s(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.6}")
    } else {
        "inf".into()
    }
}

pub(super) fn opt(x: Option<f64>) -> String {
    x.map_or("n/a".into(), |v| format!("{v:.4}"))
}

pub(super) fn stability_name(s: Stability) -> &'static str {
    match s {
        Stability::Stable => "stable",
        Stability::Marginal => "MARGINAL",
        Stability::Unstable => "UNSTABLE",
    }
}
