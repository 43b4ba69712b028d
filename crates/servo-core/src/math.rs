//! Scalar maths that works with and without `std` (libm underneath).
//!
//! Core code calls these instead of the inherent `f64` methods, which do not exist in `no_std`.

#[inline]
pub fn sqrt(x: f64) -> f64 {
    libm::sqrt(x)
}
/// sin x: the platform's in std builds (libm's reduces a large argument slowly, and the
/// simulation of a torque locked to the motor angle calls it at every sub-step with arguments of
/// thousands of radians: 31 % of a diagnosis's CPU time with such a torque), libm's without std.
#[inline]
pub fn sin(x: f64) -> f64 {
    #[cfg(feature = "std")]
    {
        x.sin()
    }
    #[cfg(not(feature = "std"))]
    {
        libm::sin(x)
    }
}
/// cos x: the platform's in std builds, libm's without std (see [`sin`]).
#[inline]
pub fn cos(x: f64) -> f64 {
    #[cfg(feature = "std")]
    {
        x.cos()
    }
    #[cfg(not(feature = "std"))]
    {
        libm::cos(x)
    }
}
#[inline]
pub fn tan(x: f64) -> f64 {
    libm::tan(x)
}
#[inline]
pub fn atan(x: f64) -> f64 {
    libm::atan(x)
}
#[inline]
pub fn atan2(y: f64, x: f64) -> f64 {
    libm::atan2(y, x)
}
/// e^x: the platform's `exp` in std builds (about twice as fast as libm's, and the
/// simulation's friction laws call it at every sub-step), libm's without std.
#[inline]
pub fn exp(x: f64) -> f64 {
    #[cfg(feature = "std")]
    {
        x.exp()
    }
    #[cfg(not(feature = "std"))]
    {
        libm::exp(x)
    }
}
#[inline]
pub fn ln(x: f64) -> f64 {
    libm::log(x)
}
#[inline]
pub fn log10(x: f64) -> f64 {
    libm::log10(x)
}
#[inline]
pub fn pow(x: f64, y: f64) -> f64 {
    libm::pow(x, y)
}
#[inline]
pub fn tanh(x: f64) -> f64 {
    libm::tanh(x)
}
#[inline]
pub fn floor(x: f64) -> f64 {
    libm::floor(x)
}
#[inline]
pub fn round(x: f64) -> f64 {
    libm::round(x)
}
#[inline]
pub fn hypot(x: f64, y: f64) -> f64 {
    libm::hypot(x, y)
}
/// Sign with sign(0) = 0 (the handout's sign function).
#[inline]
pub fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}
/// Remainder of `x / m` in [0, m).
#[inline]
pub fn rem_euclid(x: f64, m: f64) -> f64 {
    let r = libm::fmod(x, m);
    if r < 0.0 {
        r + m
    } else {
        r
    }
}
pub use core::f64::consts::PI;
/// 2 pi.
pub const TAU: f64 = core::f64::consts::TAU;

/// A number for a message: plain decimal when its magnitude is ordinary (1e-4 .. 1e6, or 0),
/// scientific otherwise (`1e308`, not a 309-digit integer; `2.5e-9`, not `0.0000000025`).
/// Non-finite values print as Rust does (`inf`, `NaN`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Num(pub f64);

impl core::fmt::Display for Num {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let a = if self.0 < 0.0 { -self.0 } else { self.0 };
        if self.0 == 0.0 || !self.0.is_finite() || (1e-4..1e6).contains(&a) {
            core::fmt::Display::fmt(&self.0, f)
        } else {
            core::fmt::LowerExp::fmt(&self.0, f)
        }
    }
}

/// The element a full ascending sort (total order) of `v` would put at index `k` (clamped to
/// the last), selected in linear time; `v` is reordered. `None` when `v` is empty.
pub fn order_statistic(v: &mut [f64], k: usize) -> Option<f64> {
    let k = k.min(v.len().checked_sub(1)?);
    Some(*v.select_nth_unstable_by(k, f64::total_cmp).1)
}

#[cfg(test)]
mod num_tests {
    use super::Num;
    extern crate std;
    use std::format;

    #[test]
    fn extreme_numbers_print_in_scientific_notation() {
        assert_eq!(format!("{}", Num(1e308)), "1e308");
        assert_eq!(format!("{}", Num(-1.5e300)), "-1.5e300");
        assert_eq!(format!("{}", Num(2.5e-9)), "2.5e-9");
        assert_eq!(format!("{}", Num(7.682e-3)), "0.007682");
        assert_eq!(format!("{}", Num(1200.0)), "1200");
        assert_eq!(format!("{}", Num(0.0)), "0");
        assert_eq!(format!("{}", Num(f64::INFINITY)), "inf");
    }
}

/// `n` points from `a` to `b` inclusive, spaced evenly.
#[cfg(feature = "alloc")]
pub fn linspace(a: f64, b: f64, n: usize) -> alloc::vec::Vec<f64> {
    if n < 2 {
        return alloc::vec![a];
    }
    (0..n)
        .map(|i| a + (b - a) * i as f64 / (n - 1) as f64)
        .collect()
}

/// `n` points from `a` to `b` inclusive, spaced evenly on a log scale (a, b > 0).
#[cfg(feature = "alloc")]
pub fn logspace(a: f64, b: f64, n: usize) -> alloc::vec::Vec<f64> {
    linspace(ln(a), ln(b), n).into_iter().map(exp).collect()
}

/// `x` with `digits` significant figures (at least 1), in plain decimals between 1e-3 and 1e6
/// and in scientific notation (`1.16e-7`) outside: `sig(0.012345, 3)` is `0.0123`,
/// `sig(20765.5, 3)` is `20800`, `sig(-1.1604e-7, 3)` is `-1.16e-7`. Non-finite values print
/// as Rust prints them (`NaN`, `inf`).
#[cfg(feature = "alloc")]
pub fn sig(x: f64, digits: usize) -> alloc::string::String {
    let digits = digits.max(1);
    if !x.is_finite() {
        return alloc::format!("{x}");
    }
    if x == 0.0 {
        return "0".into();
    }
    let a = x.abs();
    if !(1e-3..1e6).contains(&a) {
        return alloc::format!("{:.*e}", digits - 1, x);
    }
    // the exponent of the rounded value (9.996 with 3 figures is 10.0: exponent 1)
    let e = floor(log10(a)) as i32;
    let scale = pow(10.0, (digits as i32 - 1 - e) as f64);
    let r = round(a * scale) / scale;
    let e = floor(log10(r)) as i32;
    let decimals = (digits as i32 - 1 - e).max(0) as usize;
    alloc::format!("{:.*}", decimals, if x < 0.0 { -r } else { r })
}

/// A change from `before` to `after` for a person to read: `+20.9 %` (3 significant figures)
/// when `before` is a value to compare with; `new, was 0` when it was zero (a percentage of
/// zero is no number); `1.2e5 times` when the percentage would pass 10^4 %; `sign changed` when
/// it crossed zero; `n/a` when either is not finite. Never more than about six significant
/// figures, whatever the values.
#[cfg(feature = "alloc")]
pub fn change(before: f64, after: f64) -> alloc::string::String {
    if !before.is_finite() || !after.is_finite() {
        return "n/a".into();
    }
    if before == after {
        return "no change".into();
    }
    if before == 0.0 {
        return "new, was 0".into();
    }
    if after == 0.0 {
        return "-100 %, now 0".into();
    }
    if (before < 0.0) != (after < 0.0) {
        return "sign changed".into();
    }
    let rel = 100.0 * (after - before) / before.abs();
    if rel.abs() >= 1e4 {
        return alloc::format!("{} times", sig(after / before, 3));
    }
    alloc::format!(
        "{}{} %",
        if rel >= 0.0 { "+" } else { "-" },
        sig(rel.abs(), 3)
    )
}

#[cfg(all(test, feature = "alloc"))]
mod change_tests {
    use super::change;

    #[test]
    fn readable_changes() {
        assert_eq!(change(4.6824e-7, 5.66e-7), "+20.9 %");
        assert_eq!(change(0.0, 8.0651e-10), "new, was 0");
        assert_eq!(change(1e-300, 8.0651e-10), "8.07e290 times");
        assert_eq!(change(2.0, 1.0), "-50.0 %");
        assert_eq!(change(1.0, -1.0), "sign changed");
        assert_eq!(change(1.0, 0.0), "-100 %, now 0");
        assert_eq!(change(f64::NAN, 1.0), "n/a");
        for (a, b) in [(1e-300, 1.0), (3.0, 3.0000001), (-1e-9, -7e9)] {
            assert!(change(a, b).len() < 20, "{}", change(a, b));
        }
    }
}

#[cfg(all(test, feature = "alloc"))]
mod sig_tests {
    use super::sig;

    #[test]
    fn significant_figures() {
        assert_eq!(sig(0.012345, 3), "0.0123");
        assert_eq!(sig(20765.5, 3), "20800");
        assert_eq!(sig(-1.1604e-7, 3), "-1.16e-7");
        assert_eq!(sig(9.996, 3), "10.0");
        assert_eq!(sig(3.23341, 5), "3.2334");
        assert_eq!(sig(100.0, 4), "100.0");
        assert_eq!(sig(0.0, 3), "0");
        assert_eq!(sig(1.5e6, 2), "1.5e6");
    }
}

/// Lag-1 autocorrelation of a residual (rows in order), clamped to [0, 0.99]: the correlation
/// the effective number of independent rows of an information criterion is computed with.
pub fn lag1(r: &[f64]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for w in r.windows(2) {
        num += w[0] * w[1];
    }
    for v in r {
        den += v * v;
    }
    if den > 0.0 {
        (num / den).clamp(0.0, 0.99)
    } else {
        0.0
    }
}

/// Solves the small symmetric normal equations `a x = b` of `p` unknowns (`a` row-major, p x p,
/// and `b` overwritten) by Gaussian elimination with partial pivoting, after adding `ridge_rel`
/// times the largest diagonal element to the diagonal; writes `x` (length p). False when the
/// matrix is zero or singular, or a coefficient is not finite.
pub fn solve_normal(a: &mut [f64], b: &mut [f64], x: &mut [f64], p: usize, ridge_rel: f64) -> bool {
    if a.len() < p * p || b.len() < p || x.len() < p {
        return false;
    }
    let scale = (0..p).map(|u| a[u * p + u]).fold(0.0f64, f64::max);
    if scale.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
        return false;
    }
    for u in 0..p {
        a[u * p + u] += ridge_rel * scale;
    }
    for c in 0..p {
        let Some(piv) = (c..p).max_by(|&r, &s| a[r * p + c].abs().total_cmp(&a[s * p + c].abs()))
        else {
            return false;
        };
        if a[piv * p + c].abs() < 1e-300 {
            return false;
        }
        if piv != c {
            for k in 0..p {
                a.swap(c * p + k, piv * p + k);
            }
            b.swap(c, piv);
        }
        for r in c + 1..p {
            let f = a[r * p + c] / a[c * p + c];
            for k in c..p {
                a[r * p + k] -= f * a[c * p + k];
            }
            b[r] -= f * b[c];
        }
    }
    for c in (0..p).rev() {
        let mut s = b[c];
        for k in c + 1..p {
            s -= a[c * p + k] * x[k];
        }
        x[c] = s / a[c * p + c];
    }
    x[..p].iter().all(|v| v.is_finite())
}
