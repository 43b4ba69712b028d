//! `servo design`: names and phrases shared by the text and JSON reports.

use super::*;

pub(super) fn derivative_name(d: DerivativeOn) -> &'static str {
    match d {
        DerivativeOn::Error => "error",
        DerivativeOn::Measurement => "measurement",
    }
}

/// The structure in words.
pub(super) fn structure_words(st: &LoopStructure) -> String {
    format!(
        "derivative on the {}, {}, +-{} V limit, {} PID",
        derivative_name(st.derivative_on),
        match st.kw_per_s {
            Some(kw) => format!("back-calculation anti-windup K_w = {kw:.4} 1/s"),
            None => "no anti-windup".to_string(),
        },
        st.u_limit_v,
        st.discretization.name()
    )
}

/// Name of the speed figure in a table header.
pub(super) fn speed_label(sp: &TimeSpecs) -> String {
    match sp.speed {
        Some(SpeedTarget::Rise { .. }) => "rise 10-90 % [s]".into(),
        _ => format!("settling {} % [s]", (100.0 * sp.band()).round()),
    }
}

pub(super) fn speed_spec_s(sp: &TimeSpecs) -> Option<f64> {
    match sp.speed? {
        SpeedTarget::Settling { time_s, .. } | SpeedTarget::Rise { time_s } => Some(time_s),
    }
}
