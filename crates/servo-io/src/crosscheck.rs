//! Logs are what their headers say: where two signals overlap, they are checked against each
//! other when the log is read ([`crate::Registry::read`], so by every command).
//!
//! The angle and the speed of one shaft overlap: over any stretch of the log the angle moves by
//! the integral of the speed. The ratio of the two (least squares over windows of
//! [`WINDOW_S`]) is 1 for a consistent log. A column in another unit than its header or map says
//! makes it a unit's factor: 57.3 (an angle in degrees read as rad), 1/57.3 (a speed in deg/s read
//! as rad/s), 1/(2 pi) (an angle in revolutions), 2 pi (a speed in rev/s), 2 pi / 60 (a speed in
//! rpm read as rad/s), 1000 (a milli-unit, or a time in ms read as s). Every number computed from
//! such a log (J_eq, B_eq, the model's fit, the design) is wrong by that factor, so the log is
//! refused with the unit to write. A factor that is no unit's but is large (the gear ratio N: a
//! speed of the other side of the gear) is refused too, saying so; a small disagreement (within
//! a factor [`WARN_RATIO`]) is a note only: a speed estimate's lag or filter.

use crate::columns::ColumnMap;
use crate::error::{anyhow, Result};
use crate::units::{Signal, Unit};
use servo_core::record::Record;

/// Length of the windows over which the angle's change is compared with the speed's integral
/// [s]: long enough that the encoder's quantisation and a speed estimate's lag (a few ms) do
/// not count, short enough for many windows on a short log.
pub const WINDOW_S: f64 = 0.02;

/// Ratios within this factor of 1 are consistent (a causal speed estimate lags and smooths).
pub const OK_RATIO: f64 = 1.25;

/// Ratios beyond [`OK_RATIO`] and within this factor of 1 are noted; beyond it, refused.
pub const WARN_RATIO: f64 = 2.0;

/// A ratio within this relative distance of a unit's factor is named as that unit (a unit
/// mismatch gives the factor exactly; lag and noise move it by a few per cent at most).
pub const MATCH_TOL: f64 = 0.04;

/// The fit of the angle's change on the speed's integral must explain this share of the
/// change (R^2); below, the two are too noisy or too unlike to compare and nothing is said.
pub const MIN_R2: f64 = 0.9;

/// Fewest windows with motion to compare on.
pub const MIN_WINDOWS: usize = 10;

/// The ratio (angle's change / speed's integral) over windows of `window` samples, and the R^2
/// of that fit. `None` when too few windows move or a signal is not finite there.
pub fn speed_ratio(time_s: &[f64], angle: &[f64], speed: &[f64]) -> Option<(f64, f64)> {
    let n = time_s.len().min(angle.len()).min(speed.len());
    if n < 3 {
        return None;
    }
    let dt = {
        let mut d: Vec<f64> = time_s[..n].windows(2).map(|w| w[1] - w[0]).collect();
        let mid = d.len() / 2;
        *d.select_nth_unstable_by(mid, f64::total_cmp).1
    };
    if !(dt > 0.0 && dt.is_finite()) {
        return None;
    }
    let m = ((WINDOW_S / dt).round() as usize).clamp(1, (n / (2 * MIN_WINDOWS)).max(1));
    let mut pairs = Vec::new();
    let mut k = 0;
    while k + m < n {
        let d = angle[k + m] - angle[k];
        let integral: f64 = (k..k + m)
            .map(|j| 0.5 * (speed[j] + speed[j + 1]) * (time_s[j + 1] - time_s[j]))
            .sum();
        if d.is_finite() && integral.is_finite() {
            pairs.push((integral, d));
        }
        k += m;
    }
    // Windows at rest carry nothing: the largest motion sets the scale.
    ratio_through_origin(&pairs, 1e-3)
}

/// The least-squares ratio y / x through the origin over the `(x, y)` pairs whose |x| exceeds
/// `min_share` of the largest, and the R^2 of that fit; `None` with fewer than [`MIN_WINDOWS`]
/// such pairs or nothing to compare.
fn ratio_through_origin(pairs: &[(f64, f64)], min_share: f64) -> Option<(f64, f64)> {
    let scale = pairs.iter().map(|(x, _)| x.abs()).fold(0.0, f64::max);
    if scale <= 0.0 {
        return None;
    }
    let (mut sxy, mut sxx, mut syy, mut count) = (0.0, 0.0, 0.0, 0usize);
    for &(x, y) in pairs.iter().filter(|(x, _)| x.abs() > min_share * scale) {
        sxy += x * y;
        sxx += x * x;
        syy += y * y;
        count += 1;
    }
    if count < MIN_WINDOWS || sxx <= 0.0 || syy <= 0.0 {
        return None;
    }
    let r = sxy / sxx;
    let rss = syy - 2.0 * r * sxy + r * r * sxx;
    Some((r, 1.0 - rss / syy))
}

/// The name of a unit in a sentence.
fn words(u: Unit) -> String {
    match u {
        Unit::Rad => "radians".into(),
        Unit::Deg => "degrees".into(),
        Unit::Rev => "revolutions (rotations)".into(),
        Unit::RadPerS => "rad/s".into(),
        Unit::DegPerS => "deg/s".into(),
        Unit::Rpm => "rpm".into(),
        Unit::RevPerS => "rev/s (rotations per second)".into(),
        u => u.to_string(),
    }
}

/// Units an angle or a speed column is commonly written in.
const ANGLES: [Unit; 3] = [Unit::Rad, Unit::Deg, Unit::Rev];
const SPEEDS: [Unit; 4] = [Unit::RadPerS, Unit::DegPerS, Unit::Rpm, Unit::RevPerS];

/// Checks every shaft whose angle and speed are both in `rec` (`theta_l` with `omega_l`,
/// `theta_m` with `omega_m`); `columns` is the column map the log was read with (`--columns`
/// form; `None`: servo's own signals in SI). Returns the notes (a small disagreement), or the
/// refusal naming the column, the unit it is in and the map to write.
pub fn check_speed_units(rec: &Record, columns: Option<&str>) -> Result<Vec<String>> {
    let map = columns.and_then(|c| ColumnMap::parse(c).ok());
    let mut notes = Vec::new();
    for (angle_sig, speed_sig, angle, speed) in [
        (
            Signal::ThetaL,
            Signal::OmegaL,
            &rec.theta_l_rad,
            &rec.omega_l_rad_s,
        ),
        (
            Signal::ThetaM,
            Signal::OmegaM,
            &rec.theta_m_rad,
            &rec.omega_m_rad_s,
        ),
    ] {
        let (Some(angle), Some(speed)) = (angle, speed) else {
            continue;
        };
        let Some((r, r2)) = speed_ratio(&rec.time_s, angle, speed) else {
            continue;
        };
        if r2 < MIN_R2 || !r.is_finite() || r <= 0.0 {
            continue;
        }
        if r.ln().abs() <= OK_RATIO.ln() {
            continue;
        }
        let entry = |s: Signal| map.as_ref().and_then(|m| m.get(s));
        let (ua, us) = (
            entry(angle_sig).map_or(Unit::Rad, |e| e.unit),
            entry(speed_sig).map_or(Unit::RadPerS, |e| e.unit),
        );
        let name = |s: Signal, u: Unit| match entry(s) {
            Some(e) => format!("`{}` ({s}, read as {u})", e.column),
            None => format!("{s} (in {u})"),
        };
        let (an, sn) = (name(angle_sig, ua), name(speed_sig, us));
        let said = format!(
            "{}: the angle {an} changes {} times as fast as the speed {sn} says",
            rec.source,
            servo_core::math::sig(r, 3)
        );
        let fix = |s: Signal, u: Unit| -> String {
            match &map {
                Some(m) => {
                    let mut m = m.clone();
                    if let Some(e) = m.entries.iter_mut().find(|e| e.signal == s) {
                        e.unit = u;
                    }
                    format!("--columns {m}")
                }
                None => {
                    format!("a column map that gives {s} in {u} (--columns ...,{s}=COLUMN:{u})")
                }
            }
        };
        let near = |pred: f64| (r / pred - 1.0).abs() < MATCH_TOL;
        // One column in another unit than it was read in.
        let mut named = None;
        if matches!(ua.dimension(), crate::units::Dimension::Angle) && !ua.is_linear() {
            for a in ANGLES.into_iter().filter(|a| *a != ua) {
                if near(ua.factor_to_si() / a.factor_to_si()) {
                    named = Some(format!(
                        "{said}: the angle is in {}, not {}. Every number computed from this log \
                         would be wrong by that factor; say its unit: {}",
                        words(a),
                        words(ua),
                        fix(angle_sig, a)
                    ));
                }
            }
        }
        if named.is_none() && !us.is_linear() {
            for s in SPEEDS.into_iter().filter(|s| *s != us) {
                if near(s.factor_to_si() / us.factor_to_si()) {
                    named = Some(format!(
                        "{said}: the speed is in {}, not {}. Every number computed from this log \
                         would be wrong by that factor; say its unit: {}",
                        words(s),
                        words(us),
                        fix(speed_sig, s)
                    ));
                }
            }
        }
        if named.is_none() && (near(1e3) || near(1e-3)) {
            named = Some(format!(
                "{said}: a factor of 1000 is a milli-unit: {}. Every number computed from this log \
                 would be wrong by that factor; give each column's unit with --columns (e.g. time=t:ms, \
                 i_a=ia:mA)",
                if r < 1.0 {
                    "the time is in ms but read as s, or the speed in milli-units"
                } else {
                    "the angle is in milli-units (mrad, counts?), or the time in us read as ms"
                }
            ));
        }
        if let Some(msg) = named {
            return Err(anyhow!("{msg}"));
        }
        let other = match angle_sig {
            Signal::ThetaL => ("theta_m", "omega_m", "motor"),
            _ => ("theta_l", "omega_l", "load"),
        };
        if r.ln().abs() > WARN_RATIO.ln() {
            let (big, which, sig) = if r > 1.0 {
                (r, "the angle", other.0)
            } else {
                (1.0 / r, "the speed", other.1)
            };
            return Err(anyhow!(
                "{said}, a factor no unit conversion explains. If the gear ratio N is about {}, {which} \
                 is the {} shaft's: map it as {sig} (--columns ...,{sig}=COLUMN); otherwise one of the two \
                 columns is not what its name says (check with `servo inspect`), and a log whose angle \
                 and speed disagree gives wrong numbers downstream. To use only one of them, give a \
                 --columns map without the other.",
                servo_core::math::sig(big, 3),
                other.2,
            ));
        }
        notes.push(format!(
            "{said} (a speed estimate's lag or filter, or a scale error of the speed): the \
             commands that use the logged speed take it as it is"
        ));
    }
    Ok(notes)
}

/// Ratios of the logged current to the voltage balance's within this factor of 1 are consistent:
/// the model's R_eq, k_e and k_drv (often a datasheet's) may be off by tens of per cent.
pub const CURRENT_OK_RATIO: f64 = 3.0;

/// A ratio within this relative distance of a unit's factor (1000, -1) is named as that unit:
/// wider than [`MATCH_TOL`], since the balance rests on the model's electrical constants.
pub const CURRENT_MATCH_TOL: f64 = 0.15;

/// The motor speed of `rec` [rad/s]: logged, or from the load speed, or the angles' derivative.
fn motor_speed(rec: &Record, n: f64) -> Option<Vec<f64>> {
    if let Some(w) = &rec.omega_m_rad_s {
        return Some(w.clone());
    }
    if let Some(w) = &rec.omega_l_rad_s {
        return Some(w.iter().map(|v| v * n).collect());
    }
    let (angle, scale) = match (&rec.theta_m_rad, &rec.theta_l_rad) {
        (Some(a), _) => (a, 1.0),
        (None, Some(a)) => (a, n),
        _ => return None,
    };
    let t = &rec.time_s;
    let len = t.len().min(angle.len());
    if len < 3 {
        return None;
    }
    Some(
        (0..len)
            .map(|k| {
                let (a, b) = (k.saturating_sub(1), (k + 1).min(len - 1));
                let dt = t[b] - t[a];
                if dt > 0.0 {
                    scale * (angle[b] - angle[a]) / dt
                } else {
                    0.0
                }
            })
            .collect(),
    )
}

/// The logged armature current against the current the armature's voltage balance gives
/// (handout eq. 1 at the scale of windows of [`WINDOW_S`], where L_a di/dt averages out):
/// i = (k_drv u - k_e w_m) / R_eq with the model's constants. Returns the ratio (logged /
/// balance, least squares through the origin) and the R^2 of that fit; `None` without u,
/// current or a speed, or when too few windows carry current.
pub fn current_ratio(rec: &Record, params: &servo_core::PlantParams) -> Option<(f64, f64)> {
    let (u, i) = (rec.u_v.as_ref()?, rec.i_a_a.as_ref()?);
    let w = motor_speed(rec, params.n)?;
    let r = params.r_eq();
    if !(r > 0.0 && r.is_finite() && params.k_e.is_finite() && params.k_drv.is_finite()) {
        return None;
    }
    let t = &rec.time_s;
    let n = t.len().min(u.len()).min(i.len()).min(w.len());
    if n < 3 {
        return None;
    }
    let dt = (t[n - 1] - t[0]) / (n - 1) as f64;
    if !(dt > 0.0 && dt.is_finite()) {
        return None;
    }
    let m = ((WINDOW_S / dt).round() as usize).clamp(1, (n / (2 * MIN_WINDOWS)).max(1));
    let mut pairs = Vec::new();
    let mut k = 0;
    while k + m <= n {
        let mean = |v: &[f64]| v[k..k + m].iter().sum::<f64>() / m as f64;
        let implied = (params.k_drv * mean(u) - params.k_e * mean(&w)) / r;
        let logged = mean(i);
        if implied.is_finite() && logged.is_finite() {
            pairs.push((implied, logged));
        }
        k += m;
    }
    // Windows with little current carry mostly the constants' errors and noise.
    ratio_through_origin(&pairs, 0.05)
}

/// Checks a voltage drive's logged current against its voltage balance ([`current_ratio`]):
/// a factor of about 1000 is a current in mA read as A, about -1 a current of the other sign;
/// both are refused with the fix. Another large disagreement is a note (the model's electrical
/// constants or the current's unit). `columns`: the column map the log was read with.
pub fn check_current_units(
    rec: &Record,
    params: &servo_core::PlantParams,
    columns: Option<&str>,
) -> Result<Vec<String>> {
    let Some((r, r2)) = current_ratio(rec, params) else {
        return Ok(Vec::new());
    };
    if !r.is_finite() || r2 < 0.5 {
        return Ok(Vec::new());
    }
    if r > 0.0 && r.ln().abs() <= CURRENT_OK_RATIO.ln() {
        return Ok(Vec::new());
    }
    let map = columns.and_then(|c| ColumnMap::parse(c).ok());
    let entry = map.as_ref().and_then(|m| m.get(Signal::IA));
    let (name, unit) = match entry {
        Some(e) => (format!("`{}` (i_a, read as {})", e.column, e.unit), e.unit),
        None => ("i_a (in A)".to_string(), Unit::Ampere),
    };
    let said = format!(
        "{}: the logged current {name} is {} times the current the armature's voltage balance gives          (k_drv u - k_e w_m) / R_eq with the model's k_drv = {}, k_e = {} V s/rad, R_eq = {} ohm",
        rec.source,
        servo_core::math::sig(r, 3),
        servo_core::math::sig(params.k_drv, 4),
        servo_core::math::sig(params.k_e, 4),
        servo_core::math::sig(params.r_eq(), 4)
    );
    let near = |pred: f64| (r / pred - 1.0).abs() < CURRENT_MATCH_TOL;
    if unit == Unit::Ampere && near(1e3) {
        let fix = match &map {
            Some(m) => {
                let mut m = m.clone();
                if let Some(e) = m.entries.iter_mut().find(|e| e.signal == Signal::IA) {
                    e.unit = Unit::Milliampere;
                }
                format!("--columns {m}")
            }
            None => "a column map that gives i_a in mA (--columns ...,i_a=COLUMN:mA)".to_string(),
        };
        return Err(crate::error::anyhow!(
            "{said}: the current is in milliamperes, not amperes. Every number computed from it              (R_eq, k_drv, J_eq, the friction) would be wrong by that factor; say its unit: {fix}"
        ));
    }
    if near(-1.0) {
        return Err(crate::error::anyhow!(
            "{said}: the current has the other sign than u and the speed (a sensor or shunt wired              the other way). servo takes positive current as driving the motor forward, with              positive u and speed: negate the column before reading it"
        ));
    }
    Ok(vec![format!(
        "{said}: check the current's unit and sign, and the model's electrical constants          (R_a, R_s, k_e, k_drv; --params): the electrical balance and every estimate that uses          the current rest on them"
    )])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(scale_angle: f64, scale_speed: f64) -> Record {
        let t: Vec<f64> = (0..3000).map(|k| k as f64 * 1e-3).collect();
        let th: Vec<f64> = t
            .iter()
            .map(|t| scale_angle * (2.0 * t + (3.0 * t).sin()))
            .collect();
        let w: Vec<f64> = t
            .iter()
            .map(|t| scale_speed * (2.0 + 3.0 * (3.0 * t).cos()))
            .collect();
        Record {
            source: "log.csv".into(),
            time_s: t,
            theta_l_rad: Some(th),
            omega_l_rad_s: Some(w),
            ..Record::default()
        }
    }

    #[test]
    fn consistent_log_passes() {
        assert!(check_speed_units(&rec(1.0, 1.0), None).unwrap().is_empty());
        let (r, r2) = {
            let x = rec(1.0, 1.0);
            speed_ratio(
                &x.time_s,
                x.theta_l_rad.as_ref().unwrap(),
                x.omega_l_rad_s.as_ref().unwrap(),
            )
            .unwrap()
        };
        assert!((r - 1.0).abs() < 1e-3 && r2 > 0.999, "{r} {r2}");
    }

    #[test]
    fn units_are_named_with_the_fix() {
        let cols = "time=t_s,theta_l=thl_rad,omega_l=wl_rad_s";
        for (a, s, needle, fix) in [
            (
                180.0 / std::f64::consts::PI,
                1.0,
                "degrees",
                "theta_l=thl_rad:deg",
            ),
            (
                1.0 / (2.0 * std::f64::consts::PI),
                1.0,
                "revolutions",
                "theta_l=thl_rad:rev",
            ),
            (
                1.0,
                60.0 / (2.0 * std::f64::consts::PI),
                "rpm",
                "omega_l=wl_rad_s:rpm",
            ),
            (
                1.0,
                180.0 / std::f64::consts::PI,
                "deg/s",
                "omega_l=wl_rad_s:deg/s",
            ),
        ] {
            let e = check_speed_units(&rec(a, s), Some(cols))
                .unwrap_err()
                .to_string();
            assert!(e.contains(needle) && e.contains(fix), "{e}");
        }
        let e = check_speed_units(&rec(1.0, 14.0), Some(cols))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("gear ratio N is about 14.0") && e.contains("omega_m"),
            "{e}"
        );
        let e = check_speed_units(&rec(1000.0, 1.0), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("1000"), "{e}");
        let notes = check_speed_units(&rec(1.0, 1.5), None).unwrap();
        assert_eq!(notes.len(), 1, "{notes:?}");
    }

    #[test]
    fn at_rest_or_noise_says_nothing() {
        let mut r = rec(1.0, 1.0);
        r.omega_l_rad_s = Some(vec![0.0; r.time_s.len()]);
        assert!(check_speed_units(&r, None).unwrap().is_empty());
    }

    /// A voltage-driven motor (handout eq. 1 with L_a di/dt, a first-order mechanical load and
    /// a sensor lag left out): its current scaled by `scale`, with a model whose R_eq is off by
    /// `r_err` (a datasheet's constants are not the motor's).
    fn electrical(scale: f64, r_err: f64) -> (Record, servo_core::PlantParams) {
        let p = servo_core::PlantParams::default();
        let (k_e, k_t, n) = (p.k_e, p.k_t, p.n);
        let dt = 1e-3;
        let (mut w, mut i, mut th) = (0.0f64, 0.0f64, 0.0f64);
        let (mut ts, mut us, mut is, mut ths) = (vec![], vec![], vec![], vec![]);
        for k in 0..4000 {
            let t = k as f64 * dt;
            let u = 4.0 * (2.1 * t).sin() + 1.5 * (7.3 * t).sin();
            let di = (p.k_drv * u - p.r_eq() * i - k_e * w) / p.l_a;
            // Implicit enough for the 1 ms step: the electrical pole is fast.
            i += di * dt / (1.0 + p.r_eq() * dt / p.l_a);
            let dw = (k_t * i - 2e-6 * w) / 4e-6;
            w += dw * dt;
            th += w / n * dt;
            ts.push(t);
            us.push(u);
            is.push(scale * i);
            ths.push(th);
        }
        let rec = Record {
            source: "elec.csv".into(),
            time_s: ts,
            u_v: Some(us),
            i_a_a: Some(is),
            theta_l_rad: Some(ths),
            ..Record::default()
        };
        let mut model = p;
        model.r_a *= r_err;
        model.r_s *= r_err;
        (rec, model)
    }

    #[test]
    fn a_current_consistent_with_its_voltage_balance_passes() {
        for r_err in [1.0, 0.7, 1.4] {
            let (rec, p) = electrical(1.0, r_err);
            let (ratio, r2) = current_ratio(&rec, &p).expect("a ratio");
            assert!(r2 > 0.9, "R^2 {r2}");
            assert!(
                (ratio / r_err - 1.0).abs() < 0.1,
                "ratio {ratio} for R off by {r_err}"
            );
            assert!(check_current_units(&rec, &p, None).unwrap().is_empty());
        }
    }

    #[test]
    fn a_current_in_milliamperes_or_of_the_other_sign_is_named_with_the_fix() {
        let (rec, p) = electrical(1000.0, 1.1);
        let e = check_current_units(&rec, &p, Some("time=t,u=u_V,i_a=cur_A,theta_l=q"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("milliamperes"), "{e}");
        assert!(e.contains("i_a=cur_A:mA"), "{e}");
        let (rec, p) = electrical(-1.0, 0.9);
        let e = check_current_units(&rec, &p, None).unwrap_err().to_string();
        assert!(e.contains("other sign"), "{e}");
        // A factor that is no unit's is a note naming the constants it rests on.
        let (rec, p) = electrical(8.0, 1.0);
        let notes = check_current_units(&rec, &p, None).unwrap();
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(notes[0].contains("R_eq"), "{}", notes[0]);
    }
}
