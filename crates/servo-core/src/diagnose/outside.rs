//! Shapes no catalogue effect makes. When they carry the residual, what is missing is not a set
//! of catalogue effects, and the joint search (stage 8, most of the time of an "unexplained"
//! verdict) is not run: a shape of the measured friction curve that no catalogue friction has
//! ([`super::friction_curve::outside_catalogue`]), or a residual periodic in angle at an order
//! no catalogue torque locked to an angle takes, or whose amplitude changes with speed
//! ([`periodic`]).
//!
//! The catalogue's angle-locked torques declare their orders ([`EffectModel::angle_orders`]):
//! a motor torque in cycles per motor revolution, a load torque in cycles per load revolution,
//! each with an amplitude independent of speed. A residual periodic at 7.5 cycles per motor
//! revolution (a ripple of a motor with a fractional slot count, a gear mesh's tooth frequency
//! over a gear ratio that is no whole number) is none of theirs, nor is an eccentric encoder's
//! error, which grows with speed in the balances; the joint search would fit every
//! angle-locked candidate that half matches it in sub-stepped simulations and refuse them at the
//! end (24 s of the 25 s of a minute of such logs).

use super::friction_curve::FrictionCurve;
use super::structure::{BalanceReport, Periodic, Signature};
use super::thresholds::{frac, Thresholds};
use crate::effects::{ActsOn, EffectKind, EffectModel, GridContext};
use alloc::string::String;
use alloc::vec::Vec;

/// The orders one catalogue effect's torque locked to an angle takes.
#[derive(Debug, Clone, PartialEq)]
pub struct AngleOrders {
    /// The effect's name.
    pub effect: &'static str,
    /// On the motor angle (a motor torque) or the load angle (a load torque).
    pub motor_side: bool,
    /// Cycles per revolution of that side.
    pub orders: Vec<f64>,
}

/// Every catalogue effect locked to an angle, with its orders under the search's context.
pub fn catalogue_orders(ctx: &GridContext) -> Vec<AngleOrders> {
    EffectKind::ALL
        .into_iter()
        .filter_map(|k| {
            let m: &dyn EffectModel = k.model();
            let orders = m.angle_orders(ctx)?;
            Some(AngleOrders {
                effect: m.name(),
                motor_side: m.acts_on() == ActsOn::MotorTorque,
                orders,
            })
        })
        .collect()
}

/// Is a residual periodic as `p` a shape no catalogue effect makes: an amplitude that changes
/// with speed, or at least `th.periodic_order_gap` cycles per revolution from every order of
/// `catalogue` on its side?
pub fn periodic(p: &Periodic, catalogue: &[AngleOrders], th: &Thresholds) -> bool {
    if !p.speed_independent {
        return true;
    }
    catalogue.iter().all(|a| {
        let at = if a.motor_side {
            p.cycles_per_motor_rev
        } else {
            p.cycles_per_load_rev
        };
        a.orders
            .iter()
            .all(|o| (at - o).abs() >= th.periodic_order_gap)
    })
}

/// Why the joint search need not run, as a sentence of the verdict, or `None` (it must run):
/// the friction curve's shape ([`super::friction_curve::outside_catalogue`]), else every
/// balance above its floor led by a periodic shape no catalogue effect makes that carries at
/// least `joint_skip_periodic_share_pct` of its held-out residual.
pub fn why_not_searched(
    curve: Option<&FrictionCurve>,
    balances: &[BalanceReport],
    catalogue: &[AngleOrders],
    th: &Thresholds,
) -> Option<String> {
    if let Some(why) = super::friction_curve::outside_catalogue(curve, balances, th) {
        return Some(why);
    }
    let above: Vec<&BalanceReport> = balances.iter().filter(|b| b.above_noise).collect();
    let leads: Vec<(&BalanceReport, &Signature)> = above
        .iter()
        .filter_map(|b| {
            let s = b.signatures.first()?;
            let outside = s.periodic.is_some_and(|p| periodic(&p, catalogue, th));
            (outside && s.share >= frac(th.joint_skip_periodic_share_pct)).then_some((*b, s))
        })
        .collect();
    if above.is_empty() || leads.len() < above.len() {
        return None;
    }
    let each: Vec<String> = leads
        .iter()
        .map(|(b, s)| {
            alloc::format!(
                "the {}'s residual is {} ({:.0} % of its held-out residual)",
                b.equation.name(),
                s.description,
                100.0 * s.share
            )
        })
        .collect();
    let theirs: Vec<String> = catalogue
        .iter()
        .map(|a| {
            let side = if a.motor_side { "motor" } else { "load" };
            match (a.orders.first(), a.orders.last()) {
                (Some(lo), Some(hi)) if a.orders.len() > 1 => {
                    alloc::format!("{} {lo:.0}-{hi:.0} per {side} revolution", a.effect)
                }
                _ => alloc::format!(
                    "{} {} per {side} revolution",
                    a.effect,
                    a.orders
                        .iter()
                        .map(|o| alloc::format!("{o:.0}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            }
        })
        .collect();
    Some(alloc::format!(
        " No set of catalogue effects was searched jointly: a shape periodic in angle that no catalogue effect makes carries at least {:.0} % of every balance above its noise floor: {}. The catalogue's torques locked to an angle keep their amplitude at every speed and take whole orders ({}); a shape {:.2} cycles per revolution or more from them is none of theirs.",
        th.joint_skip_periodic_share_pct,
        each.join("; "),
        theirs.join(", "),
        th.periodic_order_gap
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::structure::BalanceKind;
    use crate::fit::model::Equation;

    fn ripple(cycles_per_motor_rev: f64, n: f64, speed_independent: bool) -> Periodic {
        Periodic {
            cycles_per_load_rev: cycles_per_motor_rev * n,
            cycles_per_motor_rev,
            speed_independent,
        }
    }

    fn ctx() -> GridContext {
        GridContext {
            omega_l_max_rad_s: 10.0,
            u_max_v: 5.0,
            dt_s: 1e-3,
            max_delay_s: 0.05,
            max_harmonic: 40,
        }
    }

    /// The registry's angle-locked torques answer for themselves: a whole order per motor
    /// revolution (a motor torque's) and one per load revolution (a load torque's) are the
    /// catalogue's; half orders, orders above the search and a speed-dependent amplitude are not.
    #[test]
    fn orders_the_catalogue_makes_are_its_own() {
        let th = Thresholds::default();
        let cat = catalogue_orders(&ctx());
        assert!(cat.iter().any(|a| a.motor_side), "{cat:?}");
        assert!(cat.iter().any(|a| !a.motor_side), "{cat:?}");
        let n = 14.0;
        for (p, outside) in [
            (ripple(7.0, n, true), false),
            (ripple(7.1, n, true), false),
            (ripple(1.0 / n, n, true), false),
            (ripple(7.5, n, true), true),
            (ripple(41.0, n, true), true),
            (ripple(2.0 / n, n, true), true),
            (ripple(7.0, n, false), true),
            (ripple(1.0 / n, n, false), true),
        ] {
            assert_eq!(periodic(&p, &cat, &th), outside, "{p:?}");
        }
    }

    fn balance(
        equation: Equation,
        lead: Option<(Periodic, f64)>,
        kind: &'static str,
    ) -> BalanceReport {
        BalanceReport {
            equation,
            balance: BalanceKind::Torque,
            rms: 6.0,
            floor: 1.0,
            ratio_to_noise: 6.0,
            signatures: alloc::vec![Signature {
                kind,
                description: String::from("a shape"),
                share: lead.map_or(0.9, |l| l.1),
                explained_rms: 5.0,
                on_simulation: false,
                measured_on: String::new(),
                periodic: lead.map(|l| l.0),
            }],
            above_noise: true,
            experiment: String::new(),
            resonance: None,
            resonance_band_hz: None,
        }
    }

    /// The search is skipped only when every balance above its floor is led by a periodic shape
    /// outside the catalogue with at least the bar's share, and the sentence says which.
    #[test]
    fn only_a_shape_outside_the_catalogue_leading_every_balance_skips_the_search() {
        let th = Thresholds::default();
        let cat = catalogue_orders(&ctx());
        let n = 14.0;
        let torque =
            |p: Periodic, share: f64| balance(Equation::Torque, Some((p, share)), "load_angle");
        let half = ripple(7.5, n, true);
        let why = why_not_searched(None, &[torque(half, 0.96)], &cat, &th);
        let why = why.expect("a ripple at 7.5 per motor revolution is outside the catalogue");
        assert!(why.contains("torque balance's residual"), "{why}");
        assert!(why.contains("96 %"), "{why}");
        // Below the bar, at a catalogue order, or beside another balance led by something else.
        assert_eq!(
            why_not_searched(None, &[torque(half, 0.4)], &cat, &th),
            None
        );
        let whole = ripple(7.0, n, true);
        assert_eq!(
            why_not_searched(None, &[torque(whole, 0.96)], &cat, &th),
            None
        );
        let offset = balance(Equation::Electrical, None, "offset");
        assert_eq!(
            why_not_searched(None, &[torque(half, 0.96), offset.clone()], &cat, &th),
            None
        );
        // A balance below its floor does not count.
        let quiet = BalanceReport {
            above_noise: false,
            ..offset
        };
        assert!(why_not_searched(None, &[torque(half, 0.96), quiet], &cat, &th).is_some());
    }
}
