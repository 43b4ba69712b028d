//! `--exact`: gains whose ACHIEVED crossover and phase margin equal the spec on the loop that will
//! actually run: discrete PID (with the real derivative) and the ZOH-discretised plant at T_s.
//!
//! At z_gc = e^{j w_gc T_s} the loop must satisfy C(z_gc) P(z_gc) = e^{j(-pi + phi_m)}. C(z) is
//! linear in (K_P, K_I, K_D): PI and PD follow from two real linear equations; the PID with
//! T_I = alpha T_D is solved for T_D by bisection on the phase of 1 + I(z)/(alpha T_D) + T_D D(z),
//! then K_P from the modulus.

use super::bode::{ControllerKind, PidGains};
use super::controller::{discrete_response, Discretization};
use super::ss::DiscreteStateSpace;
use super::{c_abs, c_arg, c_expj, Complex, DesignError, LoopSpec};
use crate::design::bode::wrap_pi;
use crate::math;

/// Solves for the gains; `guess` (the handout design) picks the root when several exist.
pub fn solve(
    kind: ControllerKind,
    spec: &LoopSpec,
    alpha: f64,
    tl_s: f64,
    plant: &DiscreteStateSpace,
    method: Discretization,
    guess: &PidGains,
) -> Result<PidGains, DesignError> {
    spec.validate()?;
    let (w, ts) = (spec.omega_gc, plant.ts_s);
    if w * ts >= math::PI {
        return Err(DesignError::OutOfRange {
            name: "w_gc [rad/s]",
            value: w,
            why: "the crossover must lie below the Nyquist frequency pi/T_s (lower --wc or --ts)",
        });
    }
    let p = plant.response(w);
    let c = c_expj(-math::PI + spec.phase_margin) / p;
    let unit = |ki: f64, kd: f64| {
        discrete_response(
            &PidGains {
                kp: 0.0,
                ki,
                kd,
                tl_s,
            },
            ts,
            method,
            w,
        )
    };
    let (i, d) = (unit(1.0, 0.0), unit(0.0, 1.0));
    let g = match kind {
        ControllerKind::Pi => {
            let ki = c.im / i.im;
            PidGains {
                kp: c.re - ki * i.re,
                ki,
                kd: 0.0,
                tl_s: 0.0,
            }
        }
        ControllerKind::Pd => {
            let kd = c.im / d.im;
            PidGains {
                kp: c.re - kd * d.re,
                ki: 0.0,
                kd,
                tl_s,
            }
        }
        ControllerKind::Pid => {
            let shape = |td: f64| Complex::new(1.0, 0.0) + i / (alpha * td) + d * td;
            let f = |td: f64| wrap_pi(c_arg(shape(td)) - c_arg(c));
            // scan T_D on a log grid around the handout's value, keep the sign change nearest to it
            let td0 = if guess.td_s().is_finite() && guess.td_s() > 0.0 {
                guess.td_s()
            } else {
                1.0 / w
            };
            let (lo, hi) = (math::ln(td0 * 1e-3), math::ln(td0 * 1e3));
            let n = 600;
            let mut best: Option<(f64, f64, f64)> = None;
            let mut prev = (lo, f(math::exp(lo)));
            for k in 1..=n {
                let x = lo + (hi - lo) * k as f64 / n as f64;
                let fx = f(math::exp(x));
                // a genuine root, not a jump of the wrapped phase across +-pi
                if (prev.1 > 0.0) != (fx > 0.0) && (prev.1 - fx).abs() < 1.0 {
                    let dist = (0.5 * (prev.0 + x) - math::ln(td0)).abs();
                    let better = match best {
                        None => true,
                        Some(b) => dist < b.2,
                    };
                    if better {
                        best = Some((prev.0, x, dist));
                    }
                }
                prev = (x, fx);
            }
            let (mut a, mut b, _) = best.ok_or(DesignError::NoSolution(
                "--exact: no derivative time T_D gives the required phase at w_gc with this alpha, T_L and T_s; \
                 lower the phase margin or w_gc, or shorten T_s",
            ))?;
            let fa = f(math::exp(a));
            for _ in 0..100 {
                let m = 0.5 * (a + b);
                if (f(math::exp(m)) > 0.0) == (fa > 0.0) {
                    a = m;
                } else {
                    b = m;
                }
            }
            let td = math::exp(0.5 * (a + b));
            let kp = c_abs(c) / c_abs(shape(td));
            PidGains {
                kp,
                ki: kp / (alpha * td),
                kd: kp * td,
                tl_s,
            }
        }
    };
    if !(g.kp > 0.0
        && g.ki >= 0.0
        && g.kd >= 0.0
        && g.kp.is_finite()
        && g.ki.is_finite()
        && g.kd.is_finite())
    {
        return Err(DesignError::NoSolution(
            "--exact: matching the spec with the derivative filter and the ZOH delay would need a negative gain; \
             lower the phase margin or w_gc, shorten T_s, or raise --tl-factor",
        ));
    }
    Ok(g)
}
