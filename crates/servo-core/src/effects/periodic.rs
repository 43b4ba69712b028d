//! Shared shapes of torques periodic in an angle (a sin/cos pair per harmonic), used by the
//! periodic effects' regressors. Not an effect.

use crate::math;

/// A periodic torque per unit amplitude: the (sin, cos) pair of `harmonic` x `angle`
/// (amplitude sin(h theta + phase) = A cos(phase) sin(h theta) + A sin(phase) cos(h theta)).
#[inline]
#[allow(clippy::identity_op)]
pub fn pair(angle: f64, harmonic: f64) -> (f64, f64) {
    // 1 sin(h theta + 0) and 1 sin(h theta + pi/2), written as the torques are.
    (
        1.0 * math::sin(harmonic * angle + 0.0),
        1.0 * math::sin(harmonic * angle + core::f64::consts::FRAC_PI_2),
    )
}

/// Regressor `j` (0: sin, 1: cos) of a periodic torque of `harmonic` x `angle` whose angle turns
/// at `speed` [rad/s], scaled to the motor by `scale`. Above about twice the filter cut-off the
/// sampled sin/cos alias into the band the fit sees, while the measured response holds none of
/// it: the regressor is tapered out there.
#[inline]
pub fn periodic_regressor(
    angle: f64,
    speed: f64,
    harmonic: f64,
    scale: f64,
    filter_hz: f64,
    j: usize,
) -> f64 {
    let f = harmonic * speed.abs() / math::TAU;
    let taper = ((4.0 * filter_hz - f) / (2.0 * filter_hz)).clamp(0.0, 1.0);
    if taper == 0.0 {
        return 0.0;
    }
    let p = pair(angle, harmonic);
    (if j == 0 { p.0 } else { p.1 }) * scale * taper
}

/// Amplitude and phase from the fitted (A cos(phase), A sin(phase)) pair.
#[inline]
pub fn amplitude_phase(c: &[f64]) -> (f64, f64) {
    let a = c.first().copied().unwrap_or(0.0);
    let b = c.get(1).copied().unwrap_or(0.0);
    (math::hypot(a, b), math::atan2(b, a))
}

/// Standard error of the amplitude from those of the pair.
#[inline]
pub fn amplitude_std_err(se: &[f64]) -> f64 {
    let a = se.first().copied().unwrap_or(0.0);
    let b = se.get(1).copied().unwrap_or(0.0);
    math::sqrt(0.5 * (a * a + b * b))
}

/// Standard error of the phase [rad] from the fitted pair `c` and its standard errors `se`
/// (the amplitude's error turned through the amplitude: se_A / A for a round error ellipse);
/// `None` when the amplitude is within twice its error of zero, where the phase is not
/// determined.
#[inline]
pub fn phase_std_err(c: &[f64], se: &[f64]) -> Option<f64> {
    let (a, _) = amplitude_phase(c);
    let s = amplitude_std_err(se);
    (s > 0.0 && a > 2.0 * s).then(|| s / a)
}

/// The taper of a periodic regressor turning at `speed` [rad/s] with `harmonic` cycles per turn
/// (see [`periodic_regressor`]): 1 below twice the filter cut-off, 0 beyond four times.
#[inline]
pub fn taper(speed: f64, harmonic: f64, filter_hz: f64) -> f64 {
    let f = harmonic * speed.abs() / math::TAU;
    ((4.0 * filter_hz - f) / (2.0 * filter_hz)).clamp(0.0, 1.0)
}

/// (sin(m x), cos(m x)) from (cos x, sin x) by binary exponentiation of the unit phasor (a few
/// products instead of two trigonometric calls).
#[inline]
pub fn phasor_pow(c1: f64, s1: f64, m: u32) -> (f64, f64) {
    let (mut rc, mut rs) = (1.0, 0.0);
    let (mut bc, mut bs) = (c1, s1);
    let mut e = m;
    while e > 0 {
        if e & 1 == 1 {
            (rc, rs) = (rc * bc - rs * bs, rc * bs + rs * bc);
        }
        (bc, bs) = (bc * bc - bs * bs, 2.0 * bc * bs);
        e >>= 1;
    }
    (rs, rc)
}
