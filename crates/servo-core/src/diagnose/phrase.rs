//! The words of a diagnosis' figures, written in one place so that the text report, the
//! ranking table, the JSON `evidence` and the HTML report say the same thing the same way:
//! a change is "lowers ... by 24.9 %" or "raises ... by 24.9 %" (never "lowers by -24.9 %"),
//! and the two residual figures have two names:
//!
//! * the **RMS drop** of an equation's held-out residual (the ranking's "eq. RMS drop",
//!   [`Candidate::error_reduction_pct`](crate::verdict::Candidate::error_reduction_pct)),
//! * the **squared-residual drop** (1 - RSS_with / RSS_without, the figure the bar
//!   `min_eq_drop_pct` judges), about twice the RMS drop when both are small.

use crate::math;
use alloc::format;
use alloc::string::String;

/// Name of the held-out RMS reduction of an equation's residual (the ranking's column).
pub const RMS_DROP: &str = "held-out residual RMS drop";
/// Short column header of [`RMS_DROP`].
pub const RMS_DROP_COLUMN: &str = "eq. RMS drop";
/// Name of the held-out drop of the squared residual (the `min_eq_drop_pct` bar's figure).
pub const SQUARED_DROP: &str = "held-out squared-residual drop";
/// Name of the held-out drop of the simulation (output-error) cost.
pub const SIM_DROP: &str = "held-out simulation drop";

/// A percentage with 3 significant figures, at least one decimal below 100 (`24.9`, `0.512`,
/// `150`).
pub fn pct(x: f64) -> String {
    if x.abs() >= 100.0 {
        format!("{x:.0}")
    } else if x.abs() >= 0.1 || x == 0.0 {
        format!("{x:.1}")
    } else {
        math::sig(x, 2)
    }
}

/// "lowers `what` by X %" for a drop `drop_pct` >= 0, "raises `what` by X %" for a negative
/// one (the error grew): never a double negative.
pub fn change(what: &str, drop_pct: f64) -> String {
    if drop_pct >= 0.0 {
        format!("lowers {what} by {} %", pct(drop_pct))
    } else {
        format!("raises {what} by {} %", pct(-drop_pct))
    }
}

/// "removes X % of the held-out `eq` residual (RMS)" for a positive RMS drop, "adds X % to the
/// held-out `eq` residual (RMS)" for a negative one.
pub fn rms_drop(eq: &str, drop_pct: f64) -> String {
    if drop_pct >= 0.0 {
        format!(
            "removes {} % of the held-out {eq} residual (RMS)",
            pct(drop_pct)
        )
    } else {
        format!(
            "adds {} % to the held-out {eq} residual (RMS)",
            pct(-drop_pct)
        )
    }
}

/// The squared-residual drop [%] of an RMS drop [%]: 1 - (1 - r)^2.
pub fn squared_from_rms(rms_drop_pct: f64) -> f64 {
    let r = 1.0 - rms_drop_pct / 100.0;
    100.0 * (1.0 - r * r)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_double_negatives() {
        assert_eq!(
            change("the held-out simulation error", -24.9),
            "raises the held-out simulation error by 24.9 %"
        );
        assert_eq!(change("it", 3.04), "lowers it by 3.0 %");
        assert_eq!(
            rms_drop("torque", -2.0),
            "adds 2.0 % to the held-out torque residual (RMS)"
        );
        assert!((squared_from_rms(1.5) - 2.9775).abs() < 1e-9);
    }
}
