//! Leads beyond the catalogue: mechanisms the catalogue lacks that the candidates' own
//! simulation machinery can size ([`crate::effects::FitHooks::neighbour`], e.g. a gear play's
//! contact without its gap: a linear shaft or coupling).
//!
//! Asked only when the verdict is "unexplained" (no catalogue effect passes, a balance is above
//! its noise floor). A neighbour is reported among the signatures of its balance when it predicts
//! the held-out motion better than the simulation reference by at least the drop asked of an
//! effect judged on the simulation
//! ([`super::Thresholds::min_simulation_oe_drop_pct`]). It is a lead on the missing term, with
//! its fitted parameters and the experiment that would confirm it, never a named effect: the
//! status stays "unexplained".

use super::checks::Neighbour;
use super::structure::{BalanceReport, Signature};
use super::{par_map, DiagnoseOptions};
use crate::effects::EffectKind;
use crate::fit::Dataset;
use crate::math;
use crate::plant::Plant;
use alloc::vec::Vec;

/// The neighbours of the candidate `kinds`, each fitted from every model of `starts` (the best
/// on the fit blocks kept), that predict the held-out motion better than the reference
/// (held-out simulation error `reference_oe_rad` [rad]) by the drop asked, as signatures
/// (measured on the simulation), strongest first, each with the neighbour it came from.
pub(super) fn find(
    ds: &Dataset,
    kinds: &[EffectKind],
    starts: &[&Plant],
    reference_oe_rad: f64,
    opts: &DiagnoseOptions,
) -> Vec<(Neighbour, Signature)> {
    if !(reference_oe_rad.is_finite() && reference_oe_rad > 0.0) {
        return Vec::new();
    }
    let jobs: Vec<(EffectKind, &Plant)> = kinds
        .iter()
        .copied()
        .filter(|k| k.model().fit_hooks().is_some())
        .flat_map(|k| starts.iter().map(move |p| (k, *p)))
        .collect();
    let fitted = par_map(&jobs, opts.parallel, |(k, start)| {
        k.model()
            .fit_hooks()
            .and_then(|h| h.neighbour(ds, start))
            .map(|n| (*k, n))
    });
    // Per kind, the fit from the start that does best on the fit blocks.
    let mut found: Vec<(EffectKind, Neighbour)> = Vec::new();
    for (k, n) in fitted.into_iter().flatten() {
        match found.iter_mut().find(|(kk, _)| *kk == k) {
            Some(slot) if n.fit_oe_rad < slot.1.fit_oe_rad => slot.1 = n,
            Some(_) => {}
            None => found.push((k, n)),
        }
    }
    let found = found.into_iter().map(|(_, n)| n);
    let c0 = reference_oe_rad;
    let mut out: Vec<(Neighbour, Signature)> = found
        .filter(|n| n.heldout_oe_rad.is_finite())
        .filter_map(|n| {
            let c = n.heldout_oe_rad;
            let drop = 1.0 - c / c0;
            (drop >= super::thresholds::frac(opts.thresholds.min_simulation_oe_drop_pct)).then(|| {
                let sig = Signature {
                    kind: n.kind,
                    description: alloc::format!(
                        "{}; it predicts the held-out motion {:.0} % better than the model ({:.2e} -> {:.2e} rad RMS)",
                        n.description,
                        100.0 * drop,
                        c0,
                        c
                    ),
                    share: 1.0 - (c / c0) * (c / c0),
                    explained_rms: math::sqrt((c0 * c0 - c * c).max(0.0)),
                    on_simulation: true,
                    periodic: None,
                    measured_on: alloc::string::String::from(
                        "the held-out simulation error of the load angle (not the balance's residual)",
                    ),
                };
                (n, sig)
            })
        })
        .collect();
    out.sort_by(|a, b| b.1.share.total_cmp(&a.1.share));
    out
}

/// Adds each neighbour's signature to the report of its balance in `reports` (where present):
/// after a resonance or a friction-curve shape the balance itself shows (the direct evidence
/// stays first), otherwise first, and then its experiment becomes the balance's. A neighbour
/// whose mode (its `frequency` parameter) is farther than
/// [`super::Thresholds::lead_resonance_max_gap_pct`] from the resonance the balance rings at
/// says so in its signature there.
pub(super) fn attach(
    reports: &mut [BalanceReport],
    found: &[(Neighbour, Signature)],
    th: &super::Thresholds,
) {
    for (n, sig) in found.iter().rev() {
        for b in reports.iter_mut().filter(|b| b.balance == n.balance) {
            let at = b
                .signatures
                .iter()
                .take_while(|s| s.kind == "resonance" || s.kind == super::friction_curve::KIND)
                .count();
            let mut sig = sig.clone();
            sig.description
                .push_str(&off_resonance(n, b.resonance.as_ref(), th));
            b.signatures.insert(at, sig);
            if at == 0 {
                b.experiment = n.experiment.clone();
            }
        }
    }
}

/// "; its mode ... is not the resonance ..." when the mode of `n` (its `frequency` parameter
/// [Hz]) is farther than [`super::Thresholds::lead_resonance_max_gap_pct`] from the resonance
/// `res` of its balance; empty otherwise.
fn off_resonance(
    n: &Neighbour,
    res: Option<&super::resonance::Resonance>,
    th: &super::Thresholds,
) -> alloc::string::String {
    let mode = n
        .params
        .iter()
        .find(|p| p.0 == "frequency" && p.1 == "Hz")
        .map(|p| p.2);
    let (Some(f_hz), Some(r)) = (mode, res) else {
        return alloc::string::String::new();
    };
    let gap_pct = 100.0 * (f_hz / r.freq_hz - 1.0).abs();
    if gap_pct.is_nan() || gap_pct <= th.lead_resonance_max_gap_pct {
        return alloc::string::String::new();
    }
    alloc::format!(
        "; its mode ({f_hz:.1} Hz) is {gap_pct:.0} % away from the resonance this balance rings at ({:.1} Hz; more than lead_resonance_max_gap_pct = {:.0} %): the spectrum measures the frequency, while this fit on the simulation trades stiffness, damping and the inertia split, so take the resonance's frequency and this lead's kind of mechanism",
        r.freq_hz, th.lead_resonance_max_gap_pct
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::structure::BalanceKind;
    use crate::fit::model::Equation;
    use alloc::string::String;

    fn sig(kind: &'static str) -> Signature {
        Signature {
            kind,
            description: String::from(kind),
            share: 0.5,
            explained_rms: 1.0,
            on_simulation: kind == "compliance",
            periodic: None,
            measured_on: String::new(),
        }
    }

    fn report(balance: BalanceKind, first: Option<&'static str>) -> BalanceReport {
        BalanceReport {
            equation: Equation::Torque,
            balance,
            rms: 1.0,
            floor: 0.1,
            ratio_to_noise: 10.0,
            signatures: first.into_iter().map(sig).collect(),
            above_noise: true,
            experiment: String::from("before"),
            resonance: None,
            resonance_band_hz: None,
        }
    }

    fn lead() -> (Neighbour, Signature) {
        let n = Neighbour {
            kind: "compliance",
            balance: BalanceKind::Torque,
            description: String::from("shaft"),
            params: alloc::vec![("frequency", "Hz", 47.0)],
            heldout_oe_rad: 0.07,
            fit_oe_rad: 0.06,
            experiment: String::from("chirp"),
        };
        (n, sig("compliance"))
    }

    /// The lead goes first (and its experiment becomes the balance's) unless the balance shows
    /// a resonance itself; other balances are left alone.
    #[test]
    fn a_lead_follows_a_resonance_and_otherwise_comes_first() {
        let mut reports = [
            report(BalanceKind::Torque, Some("speed")),
            report(BalanceKind::Torque, Some("resonance")),
            report(BalanceKind::Electrical, Some("offset")),
        ];
        attach(
            &mut reports,
            &[lead()],
            &crate::diagnose::Thresholds::default(),
        );
        let kinds: Vec<Vec<&str>> = reports
            .iter()
            .map(|b| b.signatures.iter().map(|s| s.kind).collect())
            .collect();
        assert_eq!(kinds[0], ["compliance", "speed"]);
        assert_eq!(reports[0].experiment, "chirp");
        assert_eq!(kinds[1], ["resonance", "compliance"]);
        assert_eq!(reports[1].experiment, "before");
        assert_eq!(kinds[2], ["offset"]);
    }

    /// A lead whose mode is far from the resonance its balance rings at says so (the k = 0.8
    /// N m/rad shaft of stop 51: an overdamped 17.7 Hz lead beside a 24.3 Hz resonance); one
    /// near it, or beside no resonance, does not.
    #[test]
    fn a_lead_off_the_resonance_says_so() {
        let res = |freq_hz: f64| crate::diagnose::resonance::Resonance {
            freq_hz,
            damping_ratio: 0.05,
            damping_resolved: true,
            band_hz: 2.0,
            share: 0.6,
            band_ms: 1.0,
            prominence: 29.0,
            prominence_needed: 3.0,
            scanned_hz: (11.0, 45.0),
            held_out_runs: 10,
            held_out_rows: 1000,
            row_rate_hz: 250.0,
        };
        let th = crate::diagnose::Thresholds::default();
        for (resonance, lead_hz, says) in [
            (Some(res(63.5)), 47.0, true),
            (Some(res(52.0)), 47.0, false),
            (None, 47.0, false),
        ] {
            let mut reports = [report(BalanceKind::Torque, Some("resonance"))];
            reports[0].resonance = resonance;
            let mut l = lead();
            l.0.params[0].2 = lead_hz;
            attach(&mut reports, &[l], &th);
            let d = &reports[0].signatures[1].description;
            assert_eq!(d.contains("away from the resonance"), says, "{d}");
        }
    }
}
