//! `product`: the element-wise or matrix product of inputs.

use nalgebra::DMatrix;

use ndds_runtime::{Binder, Mat, ModuleError, RoutineResult, SampleContext, SampleModule, Shape};
use ndds_runtime::{ComponentSpec, ParamKind as K, ParamSpec as P, Registry};

use super::{declare_inputs, input_names, mismatch, shape_text};
use crate::mats::{copy_in, copy_out};
use crate::params::failed;

/// A product of `inputs`: element by element (all of one shape), or with `matrix` the matrix
/// product `inputs[0]·inputs[1]·…` in order (the output is rows of the first × columns of
/// the last; inner dimensions must agree).
///
/// For a matrix product the output CSMat is created when the first and last inputs exist at
/// install; otherwise the application must create it.
pub struct Product {
    inputs: Vec<Mat>,
    output: Mat,
    matrix: bool,
    /// Element-wise: `[running product, next input]`. Matrix: one copy of each input.
    values: Vec<DMatrix<f64>>,
    /// Matrix: `partial[k]` is the product of inputs `0..=k + 1`.
    partial: Vec<DMatrix<f64>>,
}

impl Product {
    /// Multiplies `inputs` into `output`, element by element or (`matrix`) as matrices.
    pub fn new(
        b: &mut Binder<'_>,
        inputs: &[&str],
        output: &str,
        matrix: bool,
    ) -> Result<Self, ModuleError> {
        let mats = declare_inputs(b, inputs, output, !matrix)?;
        let n = mats.len();
        let output = if matrix {
            let shape = Self::matrix_shape(&mats)?;
            b.output(output, shape)
        } else {
            b.output_same_as(output, &mats[0])
        };
        Ok(Self {
            inputs: mats,
            output,
            matrix,
            values: vec![DMatrix::zeros(0, 0); if matrix { n } else { 2 }],
            partial: vec![DMatrix::zeros(0, 0); n - 1],
        })
    }

    /// The shape of the matrix product if the first and last inputs exist, checking the
    /// inner dimensions of the inputs that exist.
    fn matrix_shape(mats: &[Mat]) -> Result<Shape, ModuleError> {
        for pair in mats.windows(2) {
            let (left, right) = (&pair[0], &pair[1]);
            if left.is_bound() && right.is_bound() && left.shape().1 != right.shape().0 {
                return Err(ModuleError::param(
                    "inputs",
                    format!(
                        "cannot multiply `{}` ({}) by `{}` ({}): inner dimensions differ",
                        left.name(),
                        shape_text(left.shape()),
                        right.name(),
                        shape_text(right.shape())
                    ),
                ));
            }
        }
        let (first, last) = (&mats[0], &mats[mats.len() - 1]);
        Ok(if first.is_bound() && last.is_bound() {
            Shape::Exact(first.shape().0, last.shape().1)
        } else {
            Shape::Any
        })
    }

    fn element_wise(&mut self) -> RoutineResult {
        let [product, term] = &mut self.values[..] else {
            return Err(failed("product: buffers missing"));
        };
        copy_in(&self.inputs[0], product);
        for input in &self.inputs[1..] {
            copy_in(input, term);
            if term.shape() != product.shape() {
                return Err(mismatch(
                    input,
                    term.shape(),
                    &self.inputs[0],
                    product.shape(),
                ));
            }
            product.component_mul_assign(term);
        }
        copy_out(&self.output, product)
    }

    fn matrix_product(&mut self) -> RoutineResult {
        for (input, value) in self.inputs.iter().zip(&mut self.values) {
            copy_in(input, value);
        }
        for k in 1..self.inputs.len() {
            let (done, rest) = self.partial.split_at_mut(k - 1);
            let left = if k == 1 {
                &self.values[0]
            } else {
                &done[k - 2]
            };
            let right = &self.values[k];
            if left.ncols() != right.nrows() {
                return Err(failed(format!(
                    "product: the product up to `{}` is {} but `{}` is {}; inner dimensions differ",
                    self.inputs[k - 1].name(),
                    shape_text(left.shape()),
                    self.inputs[k].name(),
                    shape_text(right.shape())
                )));
            }
            let out = &mut rest[0];
            if out.shape() != (left.nrows(), right.ncols()) {
                *out = DMatrix::zeros(left.nrows(), right.ncols());
            }
            out.gemm(1.0, left, right, 0.0);
        }
        let result = self.partial.last().unwrap_or(&self.values[0]);
        copy_out(&self.output, result)
    }
}

impl SampleModule for Product {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        if self.matrix {
            self.matrix_product()
        } else if self.inputs.len() == 1 {
            copy_in(&self.inputs[0], &mut self.values[0]);
            copy_out(&self.output, &self.values[0])
        } else {
            self.element_wise()
        }
    }
}

const PRODUCT: ComponentSpec = ComponentSpec {
    name: "product",
    summary: "Element-wise product of the inputs (all of one shape), or with `matrix` the \
              matrix product inputs[0]·inputs[1]·… in order.",
    params: &[
        P::required("inputs", K::Inputs, "the factors (at least one)"),
        P::required(
            "output",
            K::Output,
            "the product: the inputs' shape, or rows of the first × columns of the last",
        ),
        P::optional(
            "matrix",
            K::Bool,
            "false",
            "matrix product instead of element-wise (inner dimensions must agree)",
        ),
    ],
};

/// Registers `product`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add_with(&PRODUCT, |b, p| {
        let inputs = input_names(p)?;
        let names: Vec<&str> = inputs.iter().map(String::as_str).collect();
        Product::new(b, &names, p.text("output")?, p.bool_or("matrix", false)?)
    });
}

#[cfg(test)]
mod tests {
    use ndds_runtime::{CsMat, Params};

    use crate::arithmetic::testing::{names, once};
    use crate::testing::{TestResult, assert_refuses, refusal, runtime};

    #[test]
    fn product_element_wise_and_matrix() -> TestResult {
        let rt = runtime(100.0, &[("a", &[1.0, 2.0]), ("b", &[3.0, 4.0])])?;
        let params = Params::new().with("inputs", names(&["a", "b", "a"]));
        assert_eq!(once(&rt, "product", params)?, [3.0, 16.0]);

        // [[1 2 3] [4 5 6]] · [[1 0] [0 1] [1 1]] = [[4 5] [10 11]]; · [1 -1]ᵀ = [-1 -1]ᵀ
        let rt = runtime(100.0, &[("v", &[1.0, -1.0])])?;
        rt.create_mat(CsMat::from_row_slice(
            "A",
            2,
            3,
            &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        )?)?;
        rt.create_mat(CsMat::from_row_slice(
            "B",
            3,
            2,
            &[1.0, 0.0, 0.0, 1.0, 1.0, 1.0],
        )?)?;
        let params = Params::new()
            .with("inputs", names(&["A", "B", "v"]))
            .with("matrix", true);
        assert_eq!(once(&rt, "product", params)?, [-1.0, -1.0]);
        assert_eq!(rt.mat("y").shape(), (2, 1));
        Ok(())
    }

    #[test]
    fn matrix_product_checks_inner_dimensions() -> TestResult {
        let rt = runtime(100.0, &[])?;
        rt.create_mat(CsMat::zeros("A", 2, 3))?;
        rt.create_mat(CsMat::zeros("C", 2, 2))?;
        let params = Params::new()
            .with("inputs", names(&["A", "C"]))
            .with("matrix", true)
            .with("output", "y");
        let err = refusal(&rt, "product", &params);
        assert_refuses(&err, "inputs", &["inner dimensions"]);

        // Shapes unknown at install: the mismatch is a failed sample, not a panic.
        let rt = runtime(100.0, &[])?;
        let params = Params::new()
            .with("inputs", names(&["P", "Q"]))
            .with("matrix", true)
            .with("output", "y");
        rt.install_component("h", "m", "product", &params)?;
        rt.create_mat(CsMat::zeros("P", 2, 2))?;
        rt.create_mat(CsMat::zeros("Q", 3, 1))?;
        rt.create_mat(CsMat::zeros("y", 2, 1))?;
        let h = rt.habitat("h");
        h.start()?;
        h.step()?;
        assert_eq!(h.stats().module_errors, 1);
        Ok(())
    }
}
