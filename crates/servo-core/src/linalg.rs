//! Dense linear algebra that core code needs with and without a heap.
//!
//! [`expm`] is generic over nalgebra's dimensions: the simulator calls it on fixed-size
//! `SMatrix` values (stack only, no allocator, `no_std`) and the controller design on `DMatrix`
//! values (behind the `alloc` feature); both run the same code.

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim, OMatrix};

/// exp(A) of a square matrix by scaling and squaring with a Taylor series, relative accuracy
/// ~1e-15 for any norm: A is scaled by 2^-s until its infinity norm (largest row sum of |a_ij|)
/// is <= 1/2, the series sum_k X^k / k! is summed until its terms fall below 1e-18 (at most 30
/// terms; 0.5^17/17! is already below that), and the result is squared s times.
///
/// A non-finite entry gives a non-finite result (the scaling stops after 1000 halvings).
pub fn expm<D: Dim>(a: &OMatrix<f64, D, D>) -> OMatrix<f64, D, D>
where
    DefaultAllocator: Allocator<D, D>,
{
    let norm = a
        .row_iter()
        .map(|row| row.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0f64, f64::max);
    let mut s = 0u32;
    let mut scale = 1.0;
    while norm * scale > 0.5 && s < 1000 {
        scale *= 0.5;
        s += 1;
    }
    let x = a * scale;
    let (rows, cols) = a.shape_generic();
    let mut result = OMatrix::<f64, D, D>::identity_generic(rows, cols);
    let mut term = result.clone();
    for k in 1..=30 {
        term = &term * &x;
        term *= 1.0 / k as f64;
        result += &term;
        if term.amax() < 1e-18 {
            break;
        }
    }
    for _ in 0..s {
        result = &result * &result;
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix2;

    fn rel_err(mine: &Matrix2<f64>, exact: &Matrix2<f64>) -> f64 {
        (mine - exact).amax() / exact.amax()
    }

    /// expm(a) agrees with the closed form `exact` to 1e-13 of its largest entry.
    fn assert_closed_form(a: Matrix2<f64>, exact: Matrix2<f64>, what: &str) {
        let err = rel_err(&expm(&a), &exact);
        assert!(err < 1e-13, "{what}: relative error {err}");
    }

    #[test]
    fn rotation_matches_cos_and_sin() {
        // exp([[0, w], [-w, 0]]) = [[cos w, sin w], [-sin w, cos w]]; w = 50 needs 7 squarings.
        for w in [0.3f64, 3.7, 50.0] {
            let exact = Matrix2::new(w.cos(), w.sin(), -w.sin(), w.cos());
            assert_closed_form(Matrix2::new(0.0, w, -w, 0.0), exact, &format!("w {w}"));
        }
    }

    #[test]
    fn distinct_real_eigenvalues_match_the_modal_closed_form() {
        // A = [[0, 1], [-2, -3]] has eigenvalues -1 and -2:
        // exp(A t) = e^-t [[2, 1], [-2, -1]] + e^-2t [[-1, -1], [2, 2]].
        for t in [0.01f64, 1.5, 8.0] {
            let (e1, e2) = ((-t).exp(), (-2.0 * t).exp());
            let exact = Matrix2::new(2.0 * e1 - e2, e1 - e2, -2.0 * e1 + 2.0 * e2, -e1 + 2.0 * e2);
            let a = Matrix2::new(0.0, 1.0, -2.0, -3.0) * t;
            assert_closed_form(a, exact, &format!("t {t}"));
        }
    }

    #[test]
    fn jordan_block_and_stiff_decay() {
        // exp([[a, 1], [0, a]]) = e^a [[1, 1], [0, 1]].
        let e = expm(&Matrix2::new(-5.0, 1.0, 0.0, -5.0));
        let d = (-5.0f64).exp();
        assert!(rel_err(&e, &Matrix2::new(d, d, 0.0, d)) < 1e-12);
        assert!(e[(1, 0)].abs() < 1e-18);
        // Strongly stiff: absolute accuracy, no overflow. exp([[-L, 0], [1, 0]]) =
        // [[e^-L, 0], [(1 - e^-L)/L, 1]].
        let e = expm(&Matrix2::new(-1e6, 0.0, 1.0, 0.0));
        assert!(e[(0, 0)].abs() < 1e-14);
        assert!((e[(1, 0)] - 1e-6).abs() < 1e-15);
        assert!((e[(1, 1)] - 1.0).abs() < 1e-15);
    }

    #[cfg(feature = "alloc")]
    #[test]
    fn matches_nalgebra_on_the_stiff_full_motor_model() {
        // Stiff: the electrical time constant is far shorter than the mechanical one.
        use crate::design::PlantModel;
        let ss = PlantModel::full(&crate::PlantParams::TABLE2).state_space();
        for ts in [1e-4, 1e-3, 1e-2] {
            let m = &ss.a * ts;
            let (mine, reference) = (expm(&m), m.exp());
            let err = (&mine - &reference).abs().max();
            assert!(
                err < 1e-12 * reference.abs().max().max(1.0),
                "ts {ts}: {err}"
            );
        }
    }

    #[cfg(feature = "alloc")]
    #[test]
    fn fixed_size_and_dynamic_matrices_give_the_same_result() {
        // The simulator's size (12 x 12), a dense matrix with entries of both signs.
        use nalgebra::{DMatrix, SMatrix};
        let f = |i: usize, j: usize| ((i * 7 + j * 3) % 11) as f64 * 0.4 - 2.0;
        let fixed = expm(&SMatrix::<f64, 12, 12>::from_fn(f));
        let dynamic = expm(&DMatrix::from_fn(12, 12, f));
        let reference = DMatrix::from_fn(12, 12, f).exp();
        let scale = reference.amax();
        for i in 0..12 {
            for j in 0..12 {
                assert!((fixed[(i, j)] - dynamic[(i, j)]).abs() < 1e-14 * scale);
                assert!(
                    (fixed[(i, j)] - reference[(i, j)]).abs() < 1e-12 * scale,
                    "({i}, {j}): {} vs {}",
                    fixed[(i, j)],
                    reference[(i, j)]
                );
            }
        }
    }
}
