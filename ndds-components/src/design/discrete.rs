//! Discrete time: the zero-order-hold discretisation of a continuous model, and the spectral
//! radius that says whether a discrete closed loop is stable.

use nalgebra::DMatrix;
use nalgebra::linalg::Schur;

/// Zero-order-hold discretisation of `ẋ = A·x + B·u` at period `dt`: `(Ad, Bd)` from the
/// matrix exponential of `[[A, B], [0, 0]]·dt`.
pub fn discretize(a: &DMatrix<f64>, b: &DMatrix<f64>, dt: f64) -> (DMatrix<f64>, DMatrix<f64>) {
    let (n, m) = (a.nrows(), b.ncols());
    let mut aug = DMatrix::zeros(n + m, n + m);
    aug.view_mut((0, 0), (n, n)).copy_from(&(a * dt));
    aug.view_mut((0, n), (n, m)).copy_from(&(b * dt));
    let e = aug.exp();
    (
        e.view((0, 0), (n, n)).into_owned(),
        e.view((0, n), (n, m)).into_owned(),
    )
}

/// The largest eigenvalue modulus of `m` (NaN if the eigenvalues cannot be computed).
pub(crate) fn spectral_radius(m: &DMatrix<f64>) -> f64 {
    Schur::try_new(m.clone(), 1e-14, 10_000)
        .map(|s| {
            s.complex_eigenvalues()
                .iter()
                .map(|z| z.norm())
                .fold(0.0, f64::max)
        })
        .unwrap_or(f64::NAN)
}

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;

    use super::{discretize, spectral_radius};

    #[test]
    fn a_double_integrator_discretizes_exactly() {
        // ẋ = [[0, 1], [0, 0]]·x + [0, 1]ᵀ·u: Ad = [[1, dt], [0, 1]], Bd = [dt²/2, dt]ᵀ.
        let dt = 0.1;
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]);
        let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
        let (ad, bd) = discretize(&a, &b, dt);
        let expected = DMatrix::from_row_slice(2, 2, &[1.0, dt, 0.0, 1.0]);
        assert!((ad - expected).abs().max() < 1e-12);
        let expected = DMatrix::from_row_slice(2, 1, &[dt * dt / 2.0, dt]);
        assert!((bd - expected).abs().max() < 1e-12);
    }

    #[test]
    fn the_spectral_radius_is_the_largest_eigenvalue_modulus() {
        let diagonal = DMatrix::from_row_slice(2, 2, &[0.5, 0.0, 0.0, -2.0]);
        assert!((spectral_radius(&diagonal) - 2.0).abs() < 1e-12);
        // A rotation by 90° scaled by 0.9: eigenvalues ±0.9i.
        let rotation = DMatrix::from_row_slice(2, 2, &[0.0, -0.9, 0.9, 0.0]);
        assert!((spectral_radius(&rotation) - 0.9).abs() < 1e-12);
    }
}
