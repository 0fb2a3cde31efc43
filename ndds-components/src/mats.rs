//! A module's CSMats and its own buffers: declaring parameter CSMats, copying values in and
//! out (one guard at a time), and the checked matrix product routines use on the copies.
//!
//! Built-in modules never hold two CSMat guards at once: each routine copies what it reads into
//! a buffer of its own, computes on the buffers, and copies the result out. CSMats that cross
//! habitats are locked per access, so habitats that feed each other cannot deadlock.

use nalgebra::DMatrix;

use ndds_runtime::csmat::CsMat;
use ndds_runtime::{Binder, Mat, ModuleError, RoutineResult, Shape};

use crate::params::failed;

/// Fails when two of a module's CSMats are the same (a module holds both guards at once).
pub(crate) fn distinct(names: &[&str]) -> Result<(), ModuleError> {
    for (i, a) in names.iter().enumerate() {
        if names[i + 1..].contains(a) {
            return Err(failed(format!(
                "CSMat `{a}` is used twice by this module; inputs and outputs must differ"
            )));
        }
    }
    Ok(())
}

/// Copies `mat`'s values into the module's own `buffer` and releases the lock at once.
/// Allocates only when the shape changes (the first sample).
pub(crate) fn copy_in(mat: &Mat, buffer: &mut DMatrix<f64>) {
    let value = mat.read();
    if buffer.shape() == value.shape() {
        buffer.copy_from(value.matrix());
    } else {
        *buffer = value.matrix().clone();
    }
}

/// Writes `values` into `mat` (same shape required).
pub(crate) fn copy_out(mat: &Mat, values: &DMatrix<f64>) -> RoutineResult {
    let mut out = mat.write();
    if out.shape() != values.shape() {
        return Err(shape_error(
            "output",
            out.name(),
            out.shape(),
            values.shape(),
        ));
    }
    out.matrix_mut().copy_from(values);
    Ok(())
}

/// "`what` `name` is `got`, expected `expected`", for a CSMat of the wrong shape.
pub(crate) fn shape_error(
    what: &str,
    name: &str,
    got: (usize, usize),
    expected: (usize, usize),
) -> ModuleError {
    failed(format!(
        "{what} `{name}` is {}x{}, expected {}x{}",
        got.0, got.1, expected.0, expected.1
    ))
}

/// The shape of `mat` if it exists, else `fallback`.
pub(crate) fn shape_of(mat: &Mat, fallback: Shape) -> Shape {
    if mat.is_bound() {
        mat.shape().into()
    } else {
        fallback
    }
}

/// A matrix parameter CSMat `"{module}.{name}"` created from `value`.
pub(crate) fn matrix_param(b: &mut Binder<'_>, name: &str, value: &DMatrix<f64>) -> Mat {
    let full = format!("{}.{name}", b.module_name());
    let mut mat = CsMat::zeros(&full, value.nrows(), value.ncols());
    mat.matrix_mut().copy_from(value);
    b.param_or(&full, mat)
}

/// `out = alpha·a·b + beta·out`, with the shapes checked first (nalgebra would panic).
pub(crate) fn gemm(
    out: &mut DMatrix<f64>,
    alpha: f64,
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    beta: f64,
) -> RoutineResult {
    if a.ncols() != b.nrows() || out.nrows() != a.nrows() || out.ncols() != b.ncols() {
        return Err(failed(format!(
            "matrix product of {}x{} and {}x{} into {}x{}",
            a.nrows(),
            a.ncols(),
            b.nrows(),
            b.ncols(),
            out.nrows(),
            out.ncols()
        )));
    }
    out.gemm(alpha, a, b, beta);
    Ok(())
}
