//! The weights of an `lqg` design: read from parameters (a matrix, its diagonal or a number)
//! and checked (shape, symmetry, definiteness).

use nalgebra::linalg::SymmetricEigen;
use nalgebra::{DMatrix, DVector};

use ndds_runtime::{ModuleError, RoutineResult};

use crate::params::all_finite;

/// A weight or covariance parameter `m` (read as a matrix: a list is one column, a number
/// 1 × 1) as a `dim × dim` matrix: a matrix of that shape as it is, a list of `dim` numbers (a
/// row or a column) as its diagonal, one number times the identity.
pub(super) fn weight_matrix(
    name: &str,
    m: &DMatrix<f64>,
    dim: usize,
) -> Result<DMatrix<f64>, ModuleError> {
    if m.shape() == (dim, dim) {
        Ok(m.clone())
    } else if m.len() == 1 {
        Ok(DMatrix::identity(dim, dim) * m[0])
    } else if m.len() == dim && (m.nrows() == 1 || m.ncols() == 1) {
        Ok(DMatrix::from_diagonal(&DVector::from_iterator(
            dim,
            m.iter().copied(),
        )))
    } else {
        Err(ModuleError::param(
            name,
            format!(
                "expected a {dim} × {dim} matrix or its diagonal ({dim} numbers), got {} × {}",
                m.nrows(),
                m.ncols()
            ),
        ))
    }
}

/// Checks that `w` is `dim × dim`, finite, symmetric, and positive semi-definite (or definite).
pub(super) fn check_weight(
    name: &str,
    w: &DMatrix<f64>,
    dim: usize,
    definite: bool,
) -> RoutineResult {
    let bad = |why: String| Err(ModuleError::param(name, why));
    if w.shape() != (dim, dim) {
        return bad(format!(
            "expected {dim} × {dim}, got {} × {}",
            w.nrows(),
            w.ncols()
        ));
    }
    all_finite(name, w.as_slice())?;
    let scale = w.abs().max();
    if (w - w.transpose()).abs().max() > 1e-9 * (1.0 + scale) {
        return bad("not symmetric".into());
    }
    let lowest = SymmetricEigen::try_new(w.clone(), 1e-14, 10_000)
        .map(|e| e.eigenvalues.min())
        .unwrap_or(f64::NAN);
    let tolerance = 1e-12 * scale;
    let ok = if definite {
        lowest > tolerance
    } else {
        lowest >= -tolerance
    };
    if ok {
        Ok(())
    } else {
        let what = if definite {
            "definite"
        } else {
            "semi-definite"
        };
        bad(format!(
            "expected a positive {what} matrix, its lowest eigenvalue is {lowest:e}"
        ))
    }
}
