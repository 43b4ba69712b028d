//! Matrix exponential of a small fixed-size matrix (scaling and squaring with a Taylor series),
//! used once per simulator to discretise the linear dynamics exactly. No heap.

/// exp(A) for an N x N matrix, relative accuracy ~1e-15 for any norm (the matrix is scaled by
/// 2^-s until its infinity norm is <= 1/2, the Taylor series is summed to machine precision, and
/// the result squared s times).
pub fn expm<const N: usize>(a: &[[f64; N]; N]) -> [[f64; N]; N] {
    let norm = a
        .iter()
        .map(|row| row.iter().map(|x| x.abs()).sum::<f64>())
        .fold(0.0f64, f64::max);
    let mut s = 0u32;
    let mut scale = 1.0;
    while norm * scale > 0.5 && s < 1000 {
        scale *= 0.5;
        s += 1;
    }
    let mut x = [[0.0; N]; N];
    for i in 0..N {
        for j in 0..N {
            x[i][j] = a[i][j] * scale;
        }
    }
    // Taylor series: sum_k X^k / k!, up to 30 terms (||X|| <= 1/2 so 0.5^20/20! is far below eps).
    let mut result = identity::<N>();
    let mut term = identity::<N>();
    for k in 1..=30 {
        term = mul(&term, &x);
        let inv_k = 1.0 / k as f64;
        let mut largest = 0.0f64;
        for row in term.iter_mut() {
            for v in row.iter_mut() {
                *v *= inv_k;
                largest = largest.max(v.abs());
            }
        }
        for i in 0..N {
            for j in 0..N {
                result[i][j] += term[i][j];
            }
        }
        if largest < 1e-18 {
            break;
        }
    }
    for _ in 0..s {
        result = mul(&result, &result);
    }
    result
}

fn identity<const N: usize>() -> [[f64; N]; N] {
    let mut m = [[0.0; N]; N];
    for (i, row) in m.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    m
}

fn mul<const N: usize>(a: &[[f64; N]; N], b: &[[f64; N]; N]) -> [[f64; N]; N] {
    let mut c = [[0.0; N]; N];
    for i in 0..N {
        for k in 0..N {
            let aik = a[i][k];
            if aik == 0.0 {
                continue;
            }
            for j in 0..N {
                c[i][j] += aik * b[k][j];
            }
        }
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_and_decay_by_hand() {
        // exp([[0, w], [-w, 0]] t) = [[cos, sin], [-sin, cos]]
        let w: f64 = 3.7;
        let e = expm(&[[0.0, w], [-w, 0.0]]);
        assert!((e[0][0] - w.cos()).abs() < 1e-14);
        assert!((e[0][1] - w.sin()).abs() < 1e-14);
        // Jordan block: exp([[a, 1], [0, a]]) = e^a [[1, 1], [0, 1]].
        let e = expm(&[[-5.0, 1.0], [0.0, -5.0]]);
        let d = (-5.0f64).exp();
        assert!((e[0][0] - d).abs() / d < 1e-12);
        assert!((e[0][1] - d).abs() / d < 1e-12);
        assert!(e[1][0].abs() < 1e-18);
        // Strongly stiff: absolute accuracy, no overflow.
        let e = expm(&[[-1e6, 0.0], [1.0, 0.0]]);
        assert!(
            e[0][0].abs() < 1e-14
                && (e[1][0] - 1e-6).abs() < 1e-15
                && (e[1][1] - 1.0).abs() < 1e-15
        );
    }
}
