//! The one table of a diagnosis's thresholds: every figure that can refuse a candidate, demote it
//! or decide the verdict, named, with its unit and why it is there. The pipeline's stages read
//! them from here and nowhere else; [`Thresholds::table`] lists them for the text report and the
//! `--json` output (`bars`), so a user who sees "BIC gain 9.9" sees the bar of 10 beside it.
//!
//! Drops and shares are in percent, as the results they are compared with
//! ([`super::Candidate::error_reduction_pct`], [`super::Candidate::oe_reduction_pct`]); ratios to
//! a noise floor are plain multiples.

use crate::compare::gate::Bar;
use crate::math;
use alloc::vec::Vec;

/// Every threshold of a diagnosis (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Thresholds {
    /// Minimum BIC gain of the effect's own equation [-] (search-corrected, over the effective
    /// number of independent rows).
    pub min_bic_gain: f64,
    /// Minimum drop of the effect's own equation's squared residual on held-out blocks [%].
    pub min_eq_drop_pct: f64,
    /// Minimum drop of the held-out output-error (simulation) cost [%].
    pub min_oe_drop_pct: f64,
    /// Minimum held-out simulation drop of an effect judged on the simulation alone (a gear play,
    /// [`crate::effects::FitHooks::judged_on_simulation`]) [%].
    pub min_simulation_oe_drop_pct: f64,
    /// Charge of the information criterion per nonlinear parameter found by a search, in units of
    /// ln(n) (a searched parameter costs this many fitted ones) [-].
    pub bic_search_charge: f64,
    /// When a candidate's fit-row squared residual is below this share of the base's, its own
    /// residual (not the base's, which is the effect's smooth shape) measures the noise's lag-1
    /// correlation for the effective sample size [%].
    pub dominant_residual_pct: f64,
    /// An effect must explain at least this multiple of its balance's noise floor (RMS) [x].
    pub min_noise_ratio: f64,
    /// An effect must explain at least this share of the structured (above-noise) squared error
    /// of its balance [%].
    pub min_structured_share_pct: f64,
    /// A candidate is a mimic when the shape that carried its balance's residual is still there
    /// after it, at least this share of that shape's RMS [%].
    pub structure_left_pct: f64,
    /// A candidate is a mimic of a resonance when this share of the resonance band's power is
    /// left in its residual [%].
    pub max_resonance_kept_pct: f64,
    /// A resonance refuses candidates only at this prominence over the spectrum's median [x].
    pub resonance_refuse_prominence: f64,
    /// A resonance is named only in a balance whose residual (RMS) is at least this multiple of
    /// its noise floor [x], the multiple that makes a balance incomplete
    /// ([`Thresholds::unexplained_ratio`]): in a complete balance, a spectral peak is nothing
    /// material (an encoder's quantisation ripple aliased at a speed the log dwells at, at 0.8
    /// times the floor; a friction's pre-sliding ringing at 1.3 times), no mode a user must act
    /// on.
    pub resonance_min_ratio: f64,
    /// A lead's mode (a compliance fitted on the simulation) farther than this from the
    /// resonance its balance rings at says so [% of the resonance's frequency]: the spectrum
    /// measures the frequency, while a fit on the simulation trades stiffness, damping and the
    /// inertia split (an overdamped 17.7 Hz spring beside a ringing 24.3 Hz shaft).
    pub lead_resonance_max_gap_pct: f64,
    /// Parameters fitted on the two halves of the data agree within this relative difference [%]
    /// (or within `consistency_std_errors` combined standard errors).
    pub consistency_tol_pct: f64,
    /// The standard-error alternative of `consistency_tol_pct` [standard errors].
    pub consistency_std_errors: f64,
    /// No torque is named while the electrical balance (which holds none) is this many times its
    /// noise floor: the current or the speed measurement is then inconsistent [x].
    pub electrical_block_ratio: f64,
    /// A drive-side effect that explains this share of the electrical residual (RMS) accounts for
    /// it, and lifts the electrical veto [%].
    pub drive_explains_pct: f64,
    /// Ranking: the weight of the equation residual reduction beside the held-out simulation
    /// reduction in a candidate's score [-].
    pub rank_equation_weight: f64,
    /// Ranking: two significant candidates within this many score points explain the data alike;
    /// the one with fewer searched parameters is named [percentage points].
    pub rank_tie_points: f64,
    /// A balance whose residual RMS exceeds this multiple of its noise floor is incomplete [x].
    pub unexplained_ratio: f64,
    /// A balance this many times `unexplained_ratio` above its floor is structured even when no
    /// shape is named [x].
    pub structured_without_shape: f64,
    /// A residual shape is named when it explains this share of the held-out residual [%].
    pub min_signature_share_pct: f64,
    /// Bins per direction of the measured friction curve (log-spaced in |speed|) [-].
    pub friction_curve_bins: f64,
    /// Fewest sliding rows in a bin of the measured friction curve [rows].
    pub friction_curve_min_rows: f64,
    /// A friction candidate is refused when the part of the measured friction curve that the
    /// base model misses (beyond the bins' 95 % intervals, RMS over the bins) is still there
    /// with it, at least this share [%].
    pub friction_curve_left_pct: f64,
    /// A shape of the measured friction curve is named at this |t| of its coefficient
    /// (effective number of rows) [-].
    pub friction_shape_min_t: f64,
    /// The joint search (catalogue effects hiding each other) is not run when the measured
    /// friction curve shows a shape no catalogue friction has (not a hump) that carries at least
    /// this share of the held-out residual of the sliding rows, and no other balance is above
    /// its floor [%].
    pub joint_skip_friction_share_pct: f64,
    /// Nor when every balance above its floor is carried, at least this share of its held-out
    /// residual, by a shape periodic in angle that no catalogue effect makes
    /// ([`Thresholds::periodic_order_gap`]) [%].
    pub joint_skip_periodic_share_pct: f64,
    /// A shape periodic in angle this far from every order a catalogue torque locked to an
    /// angle can take (whole cycles per motor revolution for a motor torque, per load
    /// revolution for a load torque), or with an amplitude that changes with speed, is one no
    /// catalogue effect makes [cycles per revolution].
    pub periodic_order_gap: f64,
    /// A friction growing with the transmitted torque is named only below this share of
    /// |k_t i_a| (a gear that loses more of the torque it transmits is self-locking; a fit above
    /// it says the balance itself is inconsistent, e.g. the current) [%].
    pub max_torque_friction_share_pct: f64,
    /// A change of the plant during a log must explain at least this multiple of its balance's
    /// noise floor (RMS over the log's rows) [x].
    pub change_min_noise_ratio: f64,
    /// ... and this share of the log's structured (above-floor) squared error [%].
    pub change_min_share_pct: f64,
    /// ... and move the base parameter that carries it by at least this much [%].
    pub change_min_relative_pct: f64,
    /// ... and be a step: the best further split inside either side gains less than this share
    /// of the step's gain (a linear drift leaves about 25 %) [%].
    pub change_max_further_pct: f64,
    /// Each side of a change spans at least this share of its log [%].
    pub change_margin_pct: f64,
    /// The pre-sliding regime (rows within a few encoder counts of travel since a reversal) is
    /// its own regime when its torque-balance residual is this many times the sliding rows'
    /// (RMS); the candidates are then judged again on the sliding rows [x].
    pub presliding_min_ratio: f64,
    /// A searched parameter whose best fit lies within this share of its search range from a
    /// bound that is not the effect's "no effect" end is at its search bound: not determined by
    /// these logs, so the effect is not named [% of the range; of its logarithm on a log grid].
    pub search_bound_margin_pct: f64,
}

impl Default for Thresholds {
    fn default() -> Self {
        Thresholds {
            min_bic_gain: 10.0,
            min_eq_drop_pct: 2.0,
            min_oe_drop_pct: 1.0,
            min_simulation_oe_drop_pct: 8.0,
            bic_search_charge: 3.0,
            dominant_residual_pct: 50.0,
            min_noise_ratio: 1.0,
            min_structured_share_pct: 25.0,
            structure_left_pct: 50.0,
            max_resonance_kept_pct: 50.0,
            resonance_refuse_prominence: super::resonance::REFUSE_PROMINENCE,
            resonance_min_ratio: 2.0,
            lead_resonance_max_gap_pct: 20.0,
            consistency_tol_pct: 35.0,
            consistency_std_errors: 3.0,
            electrical_block_ratio: 6.0,
            drive_explains_pct: 50.0,
            rank_equation_weight: 0.1,
            rank_tie_points: 0.1,
            unexplained_ratio: 2.0,
            structured_without_shape: 2.0,
            min_signature_share_pct: 15.0,
            friction_curve_bins: 8.0,
            friction_curve_min_rows: 40.0,
            friction_curve_left_pct: 50.0,
            friction_shape_min_t: 5.0,
            joint_skip_friction_share_pct: 50.0,
            joint_skip_periodic_share_pct: 50.0,
            periodic_order_gap: 0.25,
            max_torque_friction_share_pct: 50.0,
            change_min_noise_ratio: 1.0,
            change_min_share_pct: 50.0,
            change_min_relative_pct: 5.0,
            change_max_further_pct: 15.0,
            change_margin_pct: 10.0,
            presliding_min_ratio: 2.0,
            search_bound_margin_pct: 5.0,
        }
    }
}

/// `pct` [%] as a fraction.
pub(crate) fn frac(pct: f64) -> f64 {
    pct / 100.0
}

impl Thresholds {
    /// The held-out RMS drop [%] that [`Thresholds::min_eq_drop_pct`] (a drop of the squared
    /// residual) asks for: the scale of a candidate's `error_reduction_pct`.
    pub fn min_eq_rms_drop_pct(&self) -> f64 {
        100.0 * (1.0 - math::sqrt(1.0 - frac(self.min_eq_drop_pct)))
    }

    /// Every threshold, in the order the pipeline applies them (the statistical guards, the
    /// practical checks, the mimic checks, the ranking, the verdict), each with its unit, the rule
    /// a figure must meet and why.
    pub fn table(&self) -> Vec<Bar> {
        let t = self;
        alloc::vec![
            Bar { name: "min_bic_gain", value: t.min_bic_gain, unit: "-", rule: ">",
                why: "information criterion: the fit gain must outweigh the cost of the effect's parameters (search-corrected, effective sample size)" },
            Bar { name: "min_eq_drop_pct", value: t.min_eq_drop_pct, unit: "%", rule: ">=",
                why: "the effect must lower its balance's squared residual on held-out blocks; a joint search's member must not raise it by as much" },
            Bar { name: "min_simulation_oe_drop_pct", value: t.min_simulation_oe_drop_pct, unit: "%", rule: ">=",
                why: "an effect judged on the simulation alone (a gear play) needs a clear held-out simulation drop" },
            Bar { name: "min_oe_drop_pct", value: t.min_oe_drop_pct, unit: "%", rule: ">=",
                why: "the effect must lower the held-out simulation (output) error" },
            Bar { name: "bic_search_charge", value: t.bic_search_charge, unit: "x ln(n) per searched parameter", rule: "charged",
                why: "a parameter found by a search over a grid overfits more than a linear one" },
            Bar { name: "dominant_residual_pct", value: t.dominant_residual_pct, unit: "%", rule: "<",
                why: "when a candidate explains most of the residual, its own residual measures the noise's correlation (the base's is the effect's smooth shape)" },
            Bar { name: "min_noise_ratio", value: t.min_noise_ratio, unit: "x noise floor", rule: ">=",
                why: "what the effect explains must stand above the sensor noise of its balance (RMS)" },
            Bar { name: "min_structured_share_pct", value: t.min_structured_share_pct, unit: "%", rule: ">=",
                why: "the effect must explain a material share of the structured (above-noise) error" },
            Bar { name: "structure_left_pct", value: t.structure_left_pct, unit: "% of the shape's RMS", rule: "<",
                why: "a mimic leaves the shape it was meant to explain: still above the noise floor and at this share of its size" },
            Bar { name: "max_resonance_kept_pct", value: t.max_resonance_kept_pct, unit: "% of the band's power", rule: "<",
                why: "a candidate that leaves a resonance ringing is a mimic (no effect of the rigid model rings)" },
            Bar { name: "resonance_refuse_prominence", value: t.resonance_refuse_prominence, unit: "x spectrum median", rule: ">=",
                why: "only a clear resonance refuses candidates" },
            Bar { name: "resonance_min_ratio", value: t.resonance_min_ratio, unit: "x noise floor", rule: ">=",
                why: "a resonance is named only in an incomplete balance (unexplained_ratio): in a complete one a spectral peak is nothing material (an encoder's quantisation ripple aliased at a speed the log dwells at, a friction's pre-sliding ringing)" },
            Bar { name: "lead_resonance_max_gap_pct", value: t.lead_resonance_max_gap_pct, unit: "% of the resonance's frequency", rule: "<=",
                why: "a lead's mode farther from the resonance its balance rings at says so: the spectrum measures the frequency, a fit on the simulation trades stiffness, damping and split" },
            Bar { name: "consistency_tol_pct", value: t.consistency_tol_pct, unit: "%", rule: "<=",
                why: "parameters fitted on the two halves of the data must agree (or within consistency_std_errors standard errors)" },
            Bar { name: "consistency_std_errors", value: t.consistency_std_errors, unit: "standard errors", rule: "<=",
                why: "the halves may differ by their combined standard error this many times over" },
            Bar { name: "electrical_block_ratio", value: t.electrical_block_ratio, unit: "x noise floor", rule: "<",
                why: "no torque is named while the electrical balance is this far above its floor (inconsistent current or speed)" },
            Bar { name: "drive_explains_pct", value: t.drive_explains_pct, unit: "%", rule: ">=",
                why: "a drive-side effect explaining this much of the electrical residual accounts for it (the measurements are not suspect)" },
            Bar { name: "rank_equation_weight", value: t.rank_equation_weight, unit: "-", rule: "weight",
                why: "the ranking's score is the held-out simulation drop plus this weight times the equation drop (near ties go to the effect that also explains its balance)" },
            Bar { name: "rank_tie_points", value: t.rank_tie_points, unit: "points", rule: "<",
                why: "two candidates this close in score explain the data alike: the one with fewer searched parameters is named" },
            Bar { name: "unexplained_ratio", value: t.unexplained_ratio, unit: "x noise floor", rule: "<=",
                why: "a balance whose residual is above this is incomplete" },
            Bar { name: "structured_without_shape", value: t.structured_without_shape, unit: "x unexplained_ratio", rule: ">=",
                why: "a residual this far above its floor is structured even when no shape is named" },
            Bar { name: "min_signature_share_pct", value: t.min_signature_share_pct, unit: "%", rule: ">=",
                why: "a residual shape is named when it explains this share of the held-out residual" },
            Bar { name: "friction_curve_bins", value: t.friction_curve_bins, unit: "bins per direction", rule: "log-spaced",
                why: "the measured friction curve: enough bins to see a hump or a rise, few enough for tight intervals" },
            Bar { name: "friction_curve_min_rows", value: t.friction_curve_min_rows, unit: "rows", rule: ">=",
                why: "a bin of the friction curve with fewer sliding rows has no usable interval" },
            Bar { name: "friction_curve_left_pct", value: t.friction_curve_left_pct, unit: "% of the curve's excess (RMS)", rule: "<",
                why: "a friction candidate must take away most of what the measured friction curve shows beyond the base model (a drag its rise, a breakaway its hump)" },
            Bar { name: "friction_shape_min_t", value: t.friction_shape_min_t, unit: "|t|", rule: ">=",
                why: "a shape of the measured friction curve is named only when its coefficient stands out of the noise (effective rows)" },
            Bar { name: "joint_skip_friction_share_pct", value: t.joint_skip_friction_share_pct, unit: "% of the sliding rows' residual", rule: ">=",
                why: "a friction shape outside the catalogue that carries this much of the residual is what is missing: no set of catalogue effects is searched for it (the joint search costs most of a diagnosis)" },
            Bar { name: "joint_skip_periodic_share_pct", value: t.joint_skip_periodic_share_pct, unit: "% of each balance's residual", rule: ">=",
                why: "a torque or sensor error periodic in angle at an order no catalogue effect has that carries this much of every incomplete balance is what is missing: no set of catalogue effects is searched for it" },
            Bar { name: "periodic_order_gap", value: t.periodic_order_gap, unit: "cycles per revolution", rule: ">=",
                why: "a periodic shape this far from every order a catalogue torque locked to an angle takes (or with an amplitude that changes with speed) is none of theirs: the angle scan resolves a tenth of a cycle per load revolution" },
            Bar { name: "max_torque_friction_share_pct", value: t.max_torque_friction_share_pct, unit: "% of |k_t i_a|", rule: "<",
                why: "a friction growing with the transmitted torque beyond this share would make the gears self-locking: the balance, not the friction, is then inconsistent" },
            Bar { name: "change_min_noise_ratio", value: t.change_min_noise_ratio, unit: "x noise floor", rule: ">=",
                why: "a change of the base parameters during a log must explain this much of its balance (RMS over the log) to be reported" },
            Bar { name: "change_min_share_pct", value: t.change_min_share_pct, unit: "%", rule: ">=",
                why: "a change must explain this share of the log's structured (above-floor) error: a missing effect is not a change" },
            Bar { name: "change_min_relative_pct", value: t.change_min_relative_pct, unit: "%", rule: ">=",
                why: "the base parameter that carries a change must move this much (smaller changes are immaterial)" },
            Bar { name: "change_max_further_pct", value: t.change_max_further_pct, unit: "% of the step's gain", rule: "<",
                why: "a change is a step: a further split inside either side must gain less than this (a drift leaves about 25 %)" },
            Bar { name: "change_margin_pct", value: t.change_margin_pct, unit: "% of the log", rule: ">=",
                why: "each side of a change must be this long for its parameters to be refitted" },
            Bar { name: "presliding_min_ratio", value: t.presliding_min_ratio, unit: "x the sliding rows' RMS", rule: ">=",
                why: "rows near reversals (few counts of travel) carrying this much more residual are a pre-sliding regime of their own (a dynamic friction's bristles): friction shapes are then judged on the sliding rows" },
            Bar { name: "search_bound_margin_pct", value: t.search_bound_margin_pct, unit: "% of the searched range", rule: ">",
                why: "a searched parameter whose best fit sits this close to a bound of its search (not the effect's 'no effect' end) is not determined by these logs: the optimum may lie beyond it, or another mechanism bends the effect" },
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_field_is_in_the_table_once() {
        let t = Thresholds::default();
        let table = t.table();
        // One row per field: a field added without a row (or a row twice) fails here.
        assert_eq!(table.len(), 37);
        for (i, a) in table.iter().enumerate() {
            assert!(
                table[i + 1..].iter().all(|b| b.name != a.name),
                "{}",
                a.name
            );
            assert!(!a.unit.is_empty() && !a.why.is_empty(), "{}", a.name);
        }
    }

    #[test]
    fn percents_convert_to_the_fractions_they_replaced() {
        let t = Thresholds::default();
        assert_eq!(frac(t.min_eq_drop_pct), 0.02);
        assert_eq!(frac(t.min_oe_drop_pct), 0.01);
        assert_eq!(frac(t.min_simulation_oe_drop_pct), 0.08);
        assert_eq!(frac(t.min_structured_share_pct), 0.25);
        assert_eq!(frac(t.consistency_tol_pct), 0.35);
        assert_eq!(frac(t.min_signature_share_pct), 0.15);
        assert_eq!(frac(t.structure_left_pct), 0.5);
    }
}
