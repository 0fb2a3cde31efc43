//! Arithmetic on signals: sums, products and the two static nonlinearities of control loops.
//!
//! | type         | module         | reads    | writes   | value                                |
//! |--------------|----------------|----------|----------|--------------------------------------|
//! | `sum`        | [`Sum`]        | `inputs` | `output` | `Σ signs[i]·inputs[i]`               |
//! | `product`    | [`Product`]    | `inputs` | `output` | element-wise or matrix product       |
//! | `saturation` | [`Saturation`] | `input`  | `output` | `min(max(u, lower), upper)`          |
//! | `dead_band`  | [`DeadBand`]   | `input`  | `output` | 0 inside `[lower, upper]`, shifted u |
//!
//! Every input is read in `execute` (direct feedthrough). Bounds (`lower`, `upper`, `width`)
//! are lists with one value for every element or one value per element (column-major, which
//! for a column is row by row); they are the tunable parameter CSMats `<module>.lower` and
//! `<module>.upper` (for a dead band given a `width`: `−width` and `width`).

use nalgebra::DMatrix;

use super::sources::param_checks::problem;
use super::{copy_in, copy_out, distinct, matrix_param, shape_of};
use ndds_runtime::Mat;
use ndds_runtime::{Binder, ModuleError, RoutineResult, SampleContext, SampleModule, Shape};
use ndds_runtime::{ComponentSpec, ParamKind as K, ParamSpec as P, Params, Registry};

fn failed(text: String) -> ModuleError {
    ModuleError::Failed(text)
}

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
        return Err(problem("inputs", "expected at least one CSMat"));
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
            return Err(problem(
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

/// The error for an input whose shape differs from the first input's.
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

/// A weighted sum: `output = Σ signs[i]·inputs[i]`, element by element, all inputs of one
/// shape (signs `[1, -1]` make an error signal `inputs[0] − inputs[1]`).
pub struct Sum {
    inputs: Vec<Mat>,
    signs: Vec<f64>,
    output: Mat,
    total: DMatrix<f64>,
    term: DMatrix<f64>,
}

impl Sum {
    /// Sums `inputs` weighted by `signs` (one per input) into `output` (their shape).
    pub fn new(
        b: &mut Binder<'_>,
        inputs: &[&str],
        signs: &[f64],
        output: &str,
    ) -> Result<Self, ModuleError> {
        if signs.len() != inputs.len() {
            return Err(problem(
                "signs",
                format!(
                    "has {} values for {} inputs; give one per input",
                    signs.len(),
                    inputs.len()
                ),
            ));
        }
        if let Some(bad) = signs.iter().find(|s| !s.is_finite()) {
            return Err(problem("signs", format!("{bad} is not a finite number")));
        }
        let inputs = declare_inputs(b, inputs, output, true)?;
        Ok(Self {
            output: b.output_same_as(output, &inputs[0]),
            inputs,
            signs: signs.to_vec(),
            total: DMatrix::zeros(0, 0),
            term: DMatrix::zeros(0, 0),
        })
    }
}

impl SampleModule for Sum {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        copy_in(&self.inputs[0], &mut self.total);
        self.total.scale_mut(self.signs[0]);
        for (input, &sign) in self.inputs.iter().zip(&self.signs).skip(1) {
            copy_in(input, &mut self.term);
            if self.term.shape() != self.total.shape() {
                let first = &self.inputs[0];
                return Err(mismatch(
                    input,
                    self.term.shape(),
                    first,
                    self.total.shape(),
                ));
            }
            self.total.zip_apply(&self.term, |t, x| *t += sign * x);
        }
        copy_out(&self.output, &self.total)
    }
}

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
                return Err(problem(
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
            return Err(failed("product: buffers missing".into()));
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

/// An element-wise map of `input` to `output` with per-element bounds (saturation, dead band).
/// The bounds are the tunable parameter CSMats `"{module}.lower"` and `"{module}.upper"`
/// (columns of one value, or one per element).
struct Bounded {
    input: Mat,
    output: Mat,
    lower: Mat,
    upper: Mat,
    lo: DMatrix<f64>,
    hi: DMatrix<f64>,
    value: DMatrix<f64>,
}

impl Bounded {
    /// `lower`/`upper` are named `names` in messages (`width` when the dead band was given one).
    fn new(
        b: &mut Binder<'_>,
        input: &str,
        output: &str,
        (lower, upper): (&[f64], &[f64]),
        names: (&str, &str),
    ) -> Result<Self, ModuleError> {
        distinct(&[input, output])?;
        let n = lower.len().max(upper.len());
        for (name, values) in [(names.0, lower), (names.1, upper)] {
            if values.is_empty() || (values.len() != 1 && values.len() != n) {
                return Err(problem(
                    name,
                    format!("has {} values; expected one value or {n}", values.len()),
                ));
            }
            if values.iter().any(|x| x.is_nan()) {
                return Err(problem(name, "NaN is not a bound"));
            }
        }
        for i in 0..n {
            let (lo, hi) = (lower[i % lower.len()], upper[i % upper.len()]);
            if lo > hi {
                return Err(problem(
                    names.0,
                    format!("{lo} is above `{}` {hi} (element {i})", names.1),
                ));
            }
        }
        let input = b.input(input, Shape::Any);
        if input.is_bound() && n > 1 && n != input.shape().0 * input.shape().1 {
            return Err(problem(
                names.0,
                format!(
                    "has {n} values but input `{}` has {} elements",
                    input.name(),
                    input.shape().0 * input.shape().1
                ),
            ));
        }
        let lo = DMatrix::from_column_slice(lower.len(), 1, lower);
        let hi = DMatrix::from_column_slice(upper.len(), 1, upper);
        Ok(Self {
            output: b.output_same_as(output, &input),
            input,
            lower: matrix_param(b, "lower", &lo),
            upper: matrix_param(b, "upper", &hi),
            lo,
            hi,
            value: DMatrix::zeros(0, 0),
        })
    }

    /// Reads the bounds and the input, then maps each element with `map(u, lower, upper)`.
    fn apply(&mut self, map: impl Fn(f64, f64, f64) -> f64) -> RoutineResult {
        copy_in(&self.lower, &mut self.lo);
        copy_in(&self.upper, &mut self.hi);
        copy_in(&self.input, &mut self.value);
        let count = self.value.len();
        for (mat, values) in [(&self.lower, &self.lo), (&self.upper, &self.hi)] {
            if values.is_empty() || (values.len() != 1 && values.len() != count) {
                return Err(failed(format!(
                    "bound `{}` has {} values but input `{}` has {count} elements",
                    mat.name(),
                    values.len(),
                    self.input.name()
                )));
            }
        }
        let (lower, upper) = (&self.lo, &self.hi);
        for (i, u) in self.value.iter_mut().enumerate() {
            let (lo, hi) = (lower[i % lower.len()], upper[i % upper.len()]);
            if lo.is_nan() || hi.is_nan() || lo > hi {
                return Err(failed(format!(
                    "`{}` {lo} is not ≤ `{}` {hi} (element {i})",
                    self.lower.name(),
                    self.upper.name()
                )));
            }
            *u = map(*u, lo, hi);
        }
        copy_out(&self.output, &self.value)
    }
}

/// Saturation: each element of `output` is `input` clamped to `[lower, upper]` (NaN stays
/// NaN).
pub struct Saturation(Bounded);

impl Saturation {
    /// Clamps `input` into `output` (same shape). `lower` and `upper` have one value, or one
    /// per element; `lower ≤ upper` element by element (infinite bounds are allowed).
    pub fn new(
        b: &mut Binder<'_>,
        input: &str,
        output: &str,
        lower: &[f64],
        upper: &[f64],
    ) -> Result<Self, ModuleError> {
        Bounded::new(b, input, output, (lower, upper), ("lower", "upper")).map(Self)
    }
}

impl SampleModule for Saturation {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        self.0.apply(|u, lo, hi| {
            if u < lo {
                lo
            } else if u > hi {
                hi
            } else {
                u
            }
        })
    }
}

/// Dead band: `output` is 0 while `lower ≤ input ≤ upper`, `input − upper` above and
/// `input − lower` below, so it is continuous (NaN stays NaN).
pub struct DeadBand(Bounded);

impl DeadBand {
    /// The dead band `[lower, upper]` (one value, or one per element; `lower ≤ upper`).
    pub fn new(
        b: &mut Binder<'_>,
        input: &str,
        output: &str,
        lower: &[f64],
        upper: &[f64],
    ) -> Result<Self, ModuleError> {
        Bounded::new(b, input, output, (lower, upper), ("lower", "upper")).map(Self)
    }

    /// The symmetric dead band `[−width, width]` (`width ≥ 0`, one value or one per element).
    pub fn symmetric(
        b: &mut Binder<'_>,
        input: &str,
        output: &str,
        width: &[f64],
    ) -> Result<Self, ModuleError> {
        if let Some(bad) = width.iter().find(|w| w.is_nan() || **w < 0.0) {
            return Err(problem("width", format!("{bad} is not ≥ 0")));
        }
        let lower: Vec<f64> = width.iter().map(|w| -w).collect();
        Bounded::new(b, input, output, (&lower, width), ("width", "width")).map(Self)
    }
}

impl SampleModule for DeadBand {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        self.0.apply(|u, lo, hi| {
            if u > hi {
                u - hi
            } else if u < lo {
                u - lo
            } else if u.is_nan() {
                u
            } else {
                0.0
            }
        })
    }
}

/// `sum`.
pub const SUM: ComponentSpec = ComponentSpec {
    name: "sum",
    summary: "output = Σ signs[i]·inputs[i], element by element; all inputs of one shape.",
    params: &[
        P::required(
            "inputs",
            K::Inputs,
            "the terms (at least one), all of one shape",
        ),
        P::required("output", K::Output, "the sum, the shape of the inputs"),
        P::optional(
            "signs",
            K::Numbers,
            "all 1",
            "one weight per input, e.g. [1, -1] for an error signal",
        ),
    ],
};

/// `product`.
pub const PRODUCT: ComponentSpec = ComponentSpec {
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

/// `saturation`.
pub const SATURATION: ComponentSpec = ComponentSpec {
    name: "saturation",
    summary: "Clamps each element to [lower, upper] (NaN stays NaN).",
    params: &[
        P::required("input", K::Input, "u, any shape"),
        P::required("output", K::Output, "y, the shape of u"),
        P::required(
            "lower",
            K::Numbers,
            "lower bound, one value or one per element (CSMat `<module>.lower`, tunable)",
        ),
        P::required(
            "upper",
            K::Numbers,
            "upper bound (≥ lower), one value or one per element (`<module>.upper`, tunable)",
        ),
    ],
};

/// `dead_band`.
pub const DEAD_BAND: ComponentSpec = ComponentSpec {
    name: "dead_band",
    summary: "0 inside [lower, upper], u − upper above it and u − lower below it (continuous). \
              Give `width` (the band [−width, width]) or both `lower` and `upper`; the edges \
              are the tunable CSMats `<module>.lower` and `<module>.upper`.",
    params: &[
        P::required("input", K::Input, "u, any shape"),
        P::required("output", K::Output, "y, the shape of u"),
        P::optional(
            "width",
            K::Numbers,
            "none",
            "half-width (≥ 0) of the band [−width, width]; one value or one per element",
        ),
        P::optional(
            "lower",
            K::Numbers,
            "−width",
            "lower edge of the band, with `upper` instead of `width`",
        ),
        P::optional(
            "upper",
            K::Numbers,
            "width",
            "upper edge of the band (≥ lower), with `lower` instead of `width`",
        ),
    ],
};

fn input_names(p: &Params) -> Result<Vec<String>, ModuleError> {
    Ok(p.texts("inputs")?)
}

fn dead_band(b: &mut Binder<'_>, p: &Params) -> Result<DeadBand, ModuleError> {
    let (input, output) = (p.text("input")?, p.text("output")?);
    match (p.has("width"), p.has("lower"), p.has("upper")) {
        (true, false, false) => DeadBand::symmetric(b, input, output, &p.numbers("width")?),
        (false, true, true) => {
            DeadBand::new(b, input, output, &p.numbers("lower")?, &p.numbers("upper")?)
        }
        (true, _, _) => Err(problem(
            "width",
            "give `width` or `lower` and `upper`, not both",
        )),
        (false, false, false) => Err(problem(
            "width",
            "missing: give `width`, or `lower` and `upper`",
        )),
        (false, true, false) => Err(problem("upper", "missing: `lower` needs `upper`")),
        (false, false, true) => Err(problem("lower", "missing: `upper` needs `lower`")),
    }
}

/// Registers this file's component types.
pub(crate) fn register(registry: &mut Registry) {
    registry.add(&SUM, |b, p| {
        let inputs = input_names(p)?;
        let names: Vec<&str> = inputs.iter().map(String::as_str).collect();
        let signs = p.numbers_or("signs", &vec![1.0; names.len()])?;
        Sum::new(b, &names, &signs, p.text("output")?)
    });
    registry.add(&PRODUCT, |b, p| {
        let inputs = input_names(p)?;
        let names: Vec<&str> = inputs.iter().map(String::as_str).collect();
        Product::new(b, &names, p.text("output")?, p.bool_or("matrix", false)?)
    });
    registry.add(&SATURATION, |b, p| {
        Saturation::new(
            b,
            p.text("input")?,
            p.text("output")?,
            &p.numbers("lower")?,
            &p.numbers("upper")?,
        )
    });
    registry.add(&DEAD_BAND, dead_band);
}

#[cfg(test)]
mod tests {
    use ndds_runtime::{Clock, CsMat, HabitatOptions, Params, Runtime};

    type TestResult = Result<(), Box<dyn std::error::Error>>;

    /// A runtime with a manual 100 Hz habitat `h` and the column CSMats `mats`.
    fn runtime(mats: &[(&str, &[f64])]) -> Result<Runtime, Box<dyn std::error::Error>> {
        let rt = Runtime::new("t");
        crate::register(&rt);
        rt.create_habitat("h", HabitatOptions::rate(100.0).clock(Clock::Manual))?;
        for (name, values) in mats {
            rt.create_mat(CsMat::from_row_slice(*name, values.len(), 1, values)?)?;
        }
        Ok(rt)
    }

    /// Installs `m` of `type_name` writing `y`, runs one sample and returns `y` column-major.
    fn once(
        rt: &Runtime,
        type_name: &str,
        params: Params,
    ) -> Result<Vec<f64>, Box<dyn std::error::Error>> {
        rt.install_component("h", "m", type_name, &params.with("output", "y"))?;
        let h = rt.habitat("h");
        h.start()?;
        h.step()?;
        assert_eq!(h.stats().module_errors, 0);
        Ok(rt.mat("y").read().matrix().iter().copied().collect())
    }

    fn names(names: &[&str]) -> Vec<String> {
        names.iter().map(|n| (*n).to_owned()).collect()
    }

    fn build_error(rt: &Runtime, type_name: &str, params: Params) -> String {
        match rt.install_component("h", "m", type_name, &params.with("output", "y")) {
            Ok(()) => panic!("{type_name} with bad parameters was installed"),
            Err(err) => err.to_string(),
        }
    }

    #[test]
    fn sum_weights_its_inputs_by_their_signs() -> TestResult {
        let mats: &[(&str, &[f64])] =
            &[("a", &[1.0, 2.0]), ("b", &[3.0, 5.0]), ("c", &[10.0, 10.0])];
        let params = Params::new()
            .with("inputs", names(&["a", "b", "c"]))
            .with("signs", vec![1.0, -1.0, 0.5]);
        assert_eq!(once(&runtime(mats)?, "sum", params)?, [3.0, 2.0]);
        let params = Params::new().with("inputs", names(&["a", "b", "c"]));
        assert_eq!(once(&runtime(mats)?, "sum", params)?, [14.0, 17.0]);
        Ok(())
    }

    #[test]
    fn product_element_wise_and_matrix() -> TestResult {
        let rt = runtime(&[("a", &[1.0, 2.0]), ("b", &[3.0, 4.0])])?;
        let params = Params::new().with("inputs", names(&["a", "b", "a"]));
        assert_eq!(once(&rt, "product", params)?, [3.0, 16.0]);

        // [[1 2 3] [4 5 6]] · [[1 0] [0 1] [1 1]] = [[4 5] [10 11]]; · [1 -1]ᵀ = [-1 -1]ᵀ
        let rt = runtime(&[("v", &[1.0, -1.0])])?;
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
        let rt = runtime(&[])?;
        rt.create_mat(CsMat::zeros("A", 2, 3))?;
        rt.create_mat(CsMat::zeros("C", 2, 2))?;
        let params = Params::new()
            .with("inputs", names(&["A", "C"]))
            .with("matrix", true);
        let err = build_error(&rt, "product", params);
        assert!(
            err.contains("`inputs`") && err.contains("inner dimensions"),
            "{err}"
        );

        // Shapes unknown at install: the mismatch is a failed sample, not a panic.
        let rt = runtime(&[])?;
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

    #[test]
    fn saturation_clamps_each_element() -> TestResult {
        let rt = runtime(&[("u", &[-5.0, 0.5, 5.0])])?;
        let params = Params::new()
            .with("input", "u")
            .with("lower", -1.0)
            .with("upper", vec![1.0, 1.0, 2.0]);
        assert_eq!(once(&rt, "saturation", params)?, [-1.0, 0.5, 2.0]);
        // The bounds are tunable; bounds that cross fail the sample, naming them.
        rt.mat("m.lower").write().set(0, 0, -10.0)?;
        let h = rt.habitat("h");
        h.step()?;
        assert_eq!(rt.mat("y").read().matrix().as_slice(), [-5.0, 0.5, 2.0]);
        rt.mat("m.lower").write().set(0, 0, 1.5)?;
        h.step()?;
        assert_eq!(h.stats().module_errors, 1);
        Ok(())
    }

    #[test]
    fn dead_band_is_zero_inside_and_continuous_outside() -> TestResult {
        let rt = runtime(&[("u", &[-3.0, -1.0, -0.5, 0.0, 0.5, 1.0, 3.0])])?;
        let params = Params::new().with("input", "u").with("width", 1.0);
        let out = once(&rt, "dead_band", params)?;
        assert_eq!(out, [-2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0]);

        let rt = runtime(&[("u", &[-3.0, -1.0, 0.0, 2.0, 3.0])])?;
        let params = Params::new()
            .with("input", "u")
            .with("lower", -1.0)
            .with("upper", 2.0);
        assert_eq!(once(&rt, "dead_band", params)?, [-2.0, 0.0, 0.0, 0.0, 1.0]);
        Ok(())
    }

    #[test]
    fn bad_parameters_fail_the_install_naming_them() -> TestResult {
        let rt = runtime(&[("u", &[0.0, 0.0]), ("v", &[0.0, 0.0, 0.0])])?;
        let bounds = |lower: f64, upper: f64| {
            Params::new()
                .with("input", "u")
                .with("lower", lower)
                .with("upper", upper)
        };
        let err = build_error(&rt, "saturation", bounds(2.0, 1.0));
        assert!(
            err.contains("`lower`") && err.contains("above `upper`"),
            "{err}"
        );
        let params = bounds(0.0, 1.0).with("lower", vec![0.0, 0.0, 0.0]);
        let err = build_error(&rt, "saturation", params);
        assert!(
            err.contains("`lower`") && err.contains("`u` has 2 elements"),
            "{err}"
        );
        let err = build_error(&rt, "dead_band", bounds(-1.0, 1.0).with("width", 1.0));
        assert!(err.contains("`width`") && err.contains("not both"), "{err}");
        let params = Params::new().with("input", "u").with("width", -1.0);
        let err = build_error(&rt, "dead_band", params);
        assert!(err.contains("`width`"), "{err}");
        let params = Params::new().with("input", "u").with("lower", -1.0);
        let err = build_error(&rt, "dead_band", params);
        assert!(err.contains("`upper`") && err.contains("missing"), "{err}");
        let params = Params::new()
            .with("inputs", names(&["u", "u"]))
            .with("signs", 1.0);
        let err = build_error(&rt, "sum", params);
        assert!(err.contains("`signs`") && err.contains("2 inputs"), "{err}");
        let params = Params::new().with("inputs", names(&["u", "v"]));
        let err = build_error(&rt, "sum", params);
        assert!(
            err.contains("`inputs`") && err.contains("one shape"),
            "{err}"
        );
        let params = Params::new().with("inputs", names(&["u", "y"]));
        let err = build_error(&rt, "sum", params);
        assert!(err.contains("`y`") && err.contains("twice"), "{err}");
        Ok(())
    }
}
