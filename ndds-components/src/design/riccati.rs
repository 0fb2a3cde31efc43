//! The discrete algebraic Riccati equation and the two gains it gives: the LQR state feedback
//! and the steady-state Kalman filter.

use nalgebra::DMatrix;

/// Iterates a discrete Riccati equation to its fixed point (at most 100 000 steps).
fn riccati(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Option<DMatrix<f64>> {
    let mut p = q.clone();
    for _ in 0..100_000 {
        let s = r + b.transpose() * &p * b;
        let gain = s.try_inverse()? * b.transpose() * &p * a;
        let next = q + a.transpose() * &p * a - a.transpose() * &p * b * &gain;
        let change = (&next - &p).abs().max();
        p = next;
        if !change.is_finite() {
            return None; // diverged: no stabilising solution
        }
        if change <= 1e-12 * (1.0 + p.abs().max()) {
            return Some(p);
        }
    }
    None
}

/// The discrete LQR gain `K` (u = −K·x) for `x⁺ = A·x + B·u` with costs `Q`, `R`.
pub fn dlqr(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Option<DMatrix<f64>> {
    let p = riccati(a, b, q, r)?;
    Some((r + b.transpose() * &p * b).try_inverse()? * b.transpose() * &p * a)
}

/// The steady-state Kalman filter gain `L` (x̂ = x̂⁻ + L·(y − C·x̂⁻)) for process noise `Qn` and
/// measurement noise `Rn`.
pub fn kalman_gain(
    a: &DMatrix<f64>,
    c: &DMatrix<f64>,
    qn: &DMatrix<f64>,
    rn: &DMatrix<f64>,
) -> Option<DMatrix<f64>> {
    let p = riccati(&a.transpose(), &c.transpose(), qn, rn)?;
    Some(&p * c.transpose() * (c * &p * c.transpose() + rn).try_inverse()?)
}

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;

    use super::{dlqr, kalman_gain};
    use crate::testing::{one, scalar_gain, scalar_riccati};

    #[test]
    fn dlqr_matches_the_scalar_closed_form() {
        let golden = (1.0 + 5f64.sqrt()) / 2.0;
        assert!((scalar_riccati(1.0, 1.0, 1.0, 1.0) - golden).abs() < 1e-12);
        for (a, b, q, r) in [
            (1.0, 1.0, 1.0, 1.0),
            (1.2, 0.5, 2.0, 0.3),
            (0.9, 2.0, 0.1, 5.0),
        ] {
            let k = dlqr(&one(a), &one(b), &one(q), &one(r)).expect("a design")[0];
            let expected = scalar_gain(a, b, q, r);
            assert!((k - expected).abs() < 1e-9, "{k} vs {expected}");
        }
        assert!((scalar_gain(1.0, 1.0, 1.0, 1.0) - 0.618_034).abs() < 1e-6);
    }

    #[test]
    fn the_kalman_gain_is_the_dual_problem() {
        // a = c = 1, Qn = Rn = 1: L = P/(P + 1) with P the golden ratio, which is the LQR gain.
        let l = kalman_gain(&one(1.0), &one(1.0), &one(1.0), &one(1.0)).expect("a design")[0];
        assert!((l - scalar_gain(1.0, 1.0, 1.0, 1.0)).abs() < 1e-9, "{l}");
        // An unstable mode the input cannot reach has no stabilising solution.
        let a = DMatrix::from_row_slice(2, 2, &[1.5, 0.0, 0.0, 0.5]);
        let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
        assert!(dlqr(&a, &b, &DMatrix::identity(2, 2), &one(1.0)).is_none());
    }
}
