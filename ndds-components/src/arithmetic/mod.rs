//! Arithmetic on signals: gains, sums, products and the two static nonlinearities of control
//! loops.
//!
//! | type         | module                             | reads    | writes   | value                                |
//! |--------------|------------------------------------|----------|----------|--------------------------------------|
//! | `gain`       | [`Gain`](crate::Gain)              | `input`  | `output` | `k·u`                                |
//! | `sum`        | [`Sum`](crate::Sum)                | `inputs` | `output` | `Σ signs[i]·inputs[i]`               |
//! | `product`    | [`Product`](crate::Product)        | `inputs` | `output` | element-wise or matrix product       |
//! | `saturation` | [`Saturation`](crate::Saturation)  | `input`  | `output` | `min(max(u, lower), upper)`          |
//! | `dead_band`  | [`DeadBand`](crate::DeadBand)      | `input`  | `output` | 0 inside `[lower, upper]`, shifted u |
//!
//! Every input is read in `execute` (direct feedthrough). Bounds (`lower`, `upper`, `width`)
//! are lists with one value for every element or one value per element (column-major, which
//! for a column is row by row); they are the tunable parameter CSMats `<module>.lower` and
//! `<module>.upper` (for a dead band given a `width`: `−width` and `width`). This file holds
//! what the modules with several inputs share.

mod bounded;
pub(crate) mod dead_band;
pub(crate) mod gain;
pub(crate) mod product;
pub(crate) mod saturation;
pub(crate) mod sum;

use ndds_runtime::{Binder, Mat, ModuleError, Params, Registry, Shape};

use crate::mats::{distinct, shape_of};
use crate::params::failed;

fn shape_text((rows, cols): (usize, usize)) -> String {
    format!("{rows}x{cols}")
}

/// Declares `names` as feedthrough inputs (at least one; none of them `output`). With
/// `same_shape`, the second and later are expected to have the first one's shape.
fn declare_inputs(
    b: &mut Binder<'_>,
    names: &[&str],
    output: &str,
    same_shape: bool,
) -> Result<Vec<Mat>, ModuleError> {
    let Some(first) = names.first() else {
        return Err(ModuleError::param("inputs", "expected at least one CSMat"));
    };
    for name in names {
        distinct(&[name, output])?;
    }
    let first = b.input(first, Shape::Any);
    let shape = if same_shape {
        shape_of(&first, Shape::Any)
    } else {
        Shape::Any
    };
    let mut mats = vec![first];
    for name in &names[1..] {
        let mat = b.input(name, shape);
        if let (Shape::Exact(rows, cols), true) = (shape, mat.is_bound())
            && mat.shape() != (rows, cols)
        {
            return Err(ModuleError::param(
                "inputs",
                format!(
                    "`{name}` is {} but `{}` is {rows}x{cols}; all inputs must have one shape",
                    shape_text(mat.shape()),
                    names[0]
                ),
            ));
        }
        mats.push(mat);
    }
    Ok(mats)
}

/// The error for an input whose shape differs from the first input's (met while sampling).
fn mismatch(
    input: &Mat,
    shape: (usize, usize),
    first: &Mat,
    expected: (usize, usize),
) -> ModuleError {
    failed(format!(
        "input `{}` is {} but `{}` is {}; all inputs must have one shape",
        input.name(),
        shape_text(shape),
        first.name(),
        shape_text(expected)
    ))
}

/// The `inputs` parameter: the names of the CSMats a module with several inputs reads.
fn input_names(p: &Params) -> Result<Vec<String>, ModuleError> {
    Ok(p.texts("inputs")?)
}

/// Registers the arithmetic modules.
pub(crate) fn register(registry: &mut Registry) {
    gain::register(registry);
    sum::register(registry);
    product::register(registry);
    saturation::register(registry);
    dead_band::register(registry);
}

#[cfg(test)]
pub(crate) mod testing {
    use ndds_runtime::{Params, Runtime};

    use crate::testing::Outcome;

    /// Installs `m` of `type_name` writing `y`, runs one sample and returns `y` column-major.
    pub(crate) fn once(rt: &Runtime, type_name: &str, params: Params) -> Outcome<Vec<f64>> {
        rt.install_component("h", "m", type_name, &params.with("output", "y"))?;
        let h = rt.habitat("h");
        h.start()?;
        h.step()?;
        assert_eq!(h.stats().module_errors, 0);
        Ok(rt.mat("y").read().matrix().iter().copied().collect())
    }

    /// `names` as owned strings (an `inputs` parameter).
    pub(crate) fn names(names: &[&str]) -> Vec<String> {
        names.iter().map(|n| (*n).to_owned()).collect()
    }
}
