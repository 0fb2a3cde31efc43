//! Component types declared once: the [`Component`] trait that `#[derive(Component)]`
//! implements, and the checks its generated code shares with hand-written factories.
//!
//! A component type is a [`SampleModule`] plus what a description file needs to build it: its
//! [`ComponentSpec`] (name, summary, parameters with kinds, defaults, units and ranges) and a
//! factory from a table of parameters. The derive generates both from the struct's fields, so
//! the author writes only the routines:
//!
//! ```
//! use nalgebra::DMatrix;
//! use ndds_runtime::{Component, Mat, Registry, RoutineResult, SampleContext, SampleModule};
//!
//! /// A first-order low-pass filter: y += (u − y)·dt/(tau + dt).
//! #[derive(Component)]
//! #[component(name = "smooth")]
//! pub struct Smooth {
//!     /// u, any shape
//!     #[input]
//!     input: Mat,
//!     /// y, the shape of u
//!     #[output(same_as = input)]
//!     output: Mat,
//!     /// time constant
//!     #[param(tunable, default = 0.1, unit = "s", min = 0.0)]
//!     tau: Mat,
//!     /// the module's own copy of u (not a parameter)
//!     u: DMatrix<f64>,
//! }
//!
//! impl SampleModule for Smooth {
//!     fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
//!         let a = ctx.dt() / (self.tau.value(0, 0) + ctx.dt());
//!         self.u.clone_from(self.input.read().matrix());
//!         let mut y = self.output.write();
//!         y.matrix_mut().zip_apply(&self.u, |y, u| *y += (u - *y) * a);
//!         Ok(())
//!     }
//! }
//!
//! let spec = Smooth::spec();
//! assert_eq!(spec.summary, "A first-order low-pass filter: y += (u − y)·dt/(tau + dt).");
//! let tau = spec.param("tau").unwrap();
//! assert_eq!((tau.default, tau.unit, tau.range), (Some("0.1"), Some("s"), Some("≥ 0")));
//! let mut library = Registry::empty();
//! library.add::<Smooth>();
//! ```
//!
//! The attributes are documented on the derive itself (`ndds_derive::Component`, re-exported
//! here). The functions of [`support`] are what the generated factories call: each refusal
//! is a [`ModuleError::Param`] naming the key, so the loader points at file:line:column
//! exactly as it does for the built-in types.

use super::module::{Binder, ModuleError, SampleModule};
use super::registry::{ComponentSpec, Params};

/// A component type: a sample module with its spec and its factory.
pub trait Component: SampleModule + Sized {
    /// The type's name, summary and parameters (what description files are checked against and
    /// what the reference docs and the studio's palette show).
    fn spec() -> &'static ComponentSpec;

    /// Builds an instance from a description file's table (already checked against
    /// [`spec`](Self::spec) for unknown keys and kinds when it comes from the loader),
    /// declaring its CSMats through `binder`.
    fn build(binder: &mut Binder<'_>, params: &Params) -> Result<Self, ModuleError>;
}

pub mod support {
    //! What `#[derive(Component)]`'s generated code calls; usable by hand-written factories too.
    //! Every refusal names the parameter's key.

    use super::super::csmat::CsMat;
    use super::super::mat::Mat;
    use super::super::module::{Binder, ModuleError, Shape};
    use super::super::registry::{ParamValue, Params};
    use nalgebra::DMatrix;
    use std::path::PathBuf;

    /// A value a parameter of a component struct can hold, read from a description file's
    /// table.
    pub trait FromParam: Sized {
        /// Reads the parameter `key` (present) of `params`.
        fn from_param(params: &Params, key: &str) -> Result<Self, ModuleError>;
    }

    impl FromParam for f64 {
        fn from_param(params: &Params, key: &str) -> Result<Self, ModuleError> {
            finite(key, params.number(key)?)
        }
    }

    impl FromParam for Vec<f64> {
        fn from_param(params: &Params, key: &str) -> Result<Self, ModuleError> {
            let values = params.numbers(key)?;
            for x in &values {
                finite(key, *x)?;
            }
            Ok(values)
        }
    }

    impl FromParam for DMatrix<f64> {
        fn from_param(params: &Params, key: &str) -> Result<Self, ModuleError> {
            let m = params.matrix(key)?;
            for x in m.iter() {
                finite(key, *x)?;
            }
            Ok(m)
        }
    }

    impl FromParam for String {
        fn from_param(params: &Params, key: &str) -> Result<Self, ModuleError> {
            Ok(params.text(key)?.to_owned())
        }
    }

    impl FromParam for PathBuf {
        fn from_param(params: &Params, key: &str) -> Result<Self, ModuleError> {
            Ok(PathBuf::from(params.text(key)?))
        }
    }

    impl FromParam for bool {
        fn from_param(params: &Params, key: &str) -> Result<Self, ModuleError> {
            Ok(params.bool(key)?)
        }
    }

    impl FromParam for Params {
        fn from_param(params: &Params, key: &str) -> Result<Self, ModuleError> {
            Ok(params.table(key)?.clone())
        }
    }

    /// A number, list or matrix read without the finite check: `#[param(finite = false)]`, for
    /// a parameter where an infinity means something (an absent bound) and the component
    /// checks NaN itself.
    #[derive(Clone, Debug, PartialEq)]
    pub struct NonFinite<T>(pub T);

    impl FromParam for NonFinite<f64> {
        fn from_param(params: &Params, key: &str) -> Result<Self, ModuleError> {
            Ok(Self(params.number(key)?))
        }
    }

    impl FromParam for NonFinite<Vec<f64>> {
        fn from_param(params: &Params, key: &str) -> Result<Self, ModuleError> {
            Ok(Self(params.numbers(key)?))
        }
    }

    impl FromParam for NonFinite<DMatrix<f64>> {
        fn from_param(params: &Params, key: &str) -> Result<Self, ModuleError> {
            Ok(Self(params.matrix(key)?))
        }
    }

    macro_rules! whole {
        ($($t:ty),*) => {$(
            impl FromParam for $t {
                fn from_param(params: &Params, key: &str) -> Result<Self, ModuleError> {
                    let x = params.number(key)?;
                    // MIN is a power of two (or 0), exact as an f64; MAX + 1 is one too, and
                    // `MAX as f64` rounds to it for the 64-bit types, so the bound is `< MAX + 1`.
                    let (min, past) = (<$t>::MIN as f64, <$t>::MAX as f64 + 1.0);
                    if x.fract() == 0.0 && x >= min && x < past {
                        Ok(x as $t)
                    } else {
                        Err(ModuleError::param(
                            key,
                            format!(
                                "expected a whole number from {} to {}, got {x}",
                                <$t>::MIN,
                                <$t>::MAX
                            ),
                        ))
                    }
                }
            }
        )*};
    }
    whole!(u8, u16, u32, u64, usize, i8, i16, i32, i64, isize);

    /// The parameter `key`: `None` when absent.
    pub fn optional<T: FromParam>(params: &Params, key: &str) -> Result<Option<T>, ModuleError> {
        if params.has(key) {
            T::from_param(params, key).map(Some)
        } else {
            Ok(None)
        }
    }

    /// The required parameter `key`.
    pub fn required<T: FromParam>(params: &Params, key: &str) -> Result<T, ModuleError> {
        if params.has(key) {
            T::from_param(params, key)
        } else {
            Err(ModuleError::param(key, "missing"))
        }
    }

    /// `x`, unless it is not a finite number.
    pub fn finite(key: &str, x: f64) -> Result<f64, ModuleError> {
        if x.is_finite() {
            Ok(x)
        } else {
            Err(ModuleError::param(
                key,
                format!("{x} is not a finite number"),
            ))
        }
    }

    /// A number (or each number of a list or matrix) checked against a range.
    pub trait InRange {
        /// Whether it is an integer type (a refusal then says "a whole number").
        const WHOLE: bool = false;

        /// Each number the value holds.
        fn numbers(&self) -> Vec<f64>;
    }
    impl InRange for f64 {
        fn numbers(&self) -> Vec<f64> {
            vec![*self]
        }
    }
    impl InRange for Vec<f64> {
        fn numbers(&self) -> Vec<f64> {
            self.clone()
        }
    }
    impl InRange for DMatrix<f64> {
        fn numbers(&self) -> Vec<f64> {
            self.iter().copied().collect()
        }
    }
    macro_rules! in_range_int {
        ($($t:ty),*) => {$(
            impl InRange for $t {
                const WHOLE: bool = true;

                fn numbers(&self) -> Vec<f64> {
                    vec![*self as f64]
                }
            }
        )*};
    }
    in_range_int!(u8, u16, u32, u64, usize, i8, i16, i32, i64, isize);
    impl<T: InRange> InRange for Option<T> {
        const WHOLE: bool = T::WHOLE;

        fn numbers(&self) -> Vec<f64> {
            self.as_ref().map(InRange::numbers).unwrap_or_default()
        }
    }

    /// Bounds of a parameter: `min ≤ x`, `x ≤ max`, `x > above`, `x < below` for each given.
    #[derive(Clone, Copy, Debug, Default)]
    pub struct Range {
        /// Smallest accepted.
        pub min: Option<f64>,
        /// Largest accepted.
        pub max: Option<f64>,
        /// Every accepted value is above this.
        pub above: Option<f64>,
        /// Every accepted value is below this.
        pub below: Option<f64>,
    }

    impl Range {
        /// Refuses the first number of `value` outside the range, naming `key`: "−1 is
        /// negative: expected ≥ 0", "0 is not positive: expected > 0", "2 is out of range:
        /// expected ≥ 0 and ≤ 1"; for an integer type "expected a whole number from 1 to 10, got
        /// 0" (as its type's range is worded) or "expected a whole number ≥ 1, got 0".
        /// (NaN is refused by every bound.)
        pub fn check<T: InRange>(&self, key: &str, value: &T) -> Result<(), ModuleError> {
            for x in value.numbers() {
                if let Some(what) = self.refusal(x) {
                    let words = self.words();
                    let reason = match (T::WHOLE, self.min, self.max, self.above, self.below) {
                        (true, Some(min), Some(max), None, None) => {
                            format!("expected a whole number from {min} to {max}, got {x}")
                        }
                        (true, ..) => format!("expected a whole number {words}, got {x}"),
                        (false, ..) => format!("{x} is {what}: expected {words}"),
                    };
                    return Err(ModuleError::param(key, reason));
                }
            }
            Ok(())
        }

        /// What is wrong with `x`, if it is outside the range.
        fn refusal(&self, x: f64) -> Option<&'static str> {
            let nan = x.is_nan();
            let below_min = self.min.is_some_and(|m| nan || x < m);
            let not_above = self.above.is_some_and(|m| nan || x <= m);
            let refused = below_min
                || not_above
                || self.max.is_some_and(|m| nan || x > m)
                || self.below.is_some_and(|m| nan || x >= m);
            if !refused {
                None
            } else if below_min && self.min == Some(0.0) && x < 0.0 {
                Some("negative")
            } else if not_above && self.above == Some(0.0) && !nan {
                Some("not positive")
            } else {
                Some("out of range")
            }
        }

        /// The range in words, as the spec shows it (`≥ 0`, `> 0 and ≤ 1`).
        pub fn words(&self) -> String {
            let parts: Vec<String> = [
                self.min.map(|m| format!("≥ {m}")),
                self.above.map(|m| format!("> {m}")),
                self.max.map(|m| format!("≤ {m}")),
                self.below.map(|m| format!("< {m}")),
            ]
            .into_iter()
            .flatten()
            .collect();
            parts.join(" and ")
        }
    }

    /// The CSMat name the parameter `key` gives.
    pub fn mat_name(params: &Params, key: &str) -> Result<String, ModuleError> {
        required::<String>(params, key)
    }

    /// The CSMat names the list parameter `key` gives (a single name is a list of one; at
    /// least one).
    pub fn mat_names(params: &Params, key: &str) -> Result<Vec<String>, ModuleError> {
        let names = params.texts(key)?;
        if names.is_empty() {
            return Err(ModuleError::param(key, "expected at least one CSMat"));
        }
        Ok(names)
    }

    /// Refuses a CSMat that a module both reads and writes, or writes twice (it would hold both
    /// guards at once): `outputs` against each other and against `inputs`.
    pub fn distinct(inputs: &[&str], outputs: &[&str]) -> Result<(), ModuleError> {
        for (i, out) in outputs.iter().enumerate() {
            if outputs[i + 1..].contains(out) || inputs.contains(out) {
                return Err(ModuleError::Failed(format!(
                    "CSMat `{out}` is used twice by this module; inputs and outputs must differ"
                )));
            }
        }
        Ok(())
    }

    /// The shape of `mat` if it exists, else any shape (for an input that takes another's).
    pub fn shape_of(mat: &Mat) -> Shape {
        if mat.is_bound() {
            mat.shape().into()
        } else {
            Shape::Any
        }
    }

    /// Declares the inputs `names` of the list parameter `key`; with `same_shape`, the second
    /// and later are expected to have the first's shape (refused now when both exist).
    pub fn inputs(
        binder: &mut Binder<'_>,
        key: &str,
        names: &[String],
        same_shape: bool,
    ) -> Result<Vec<Mat>, ModuleError> {
        let mut mats: Vec<Mat> = Vec::with_capacity(names.len());
        for name in names {
            let shape = match mats.first() {
                Some(first) if same_shape => shape_of(first),
                _ => Shape::Any,
            };
            let mat = binder.input(name, shape);
            if let (Shape::Exact(rows, cols), true) = (shape, mat.is_bound())
                && mat.shape() != (rows, cols)
            {
                let (r, c) = mat.shape();
                return Err(ModuleError::param(
                    key,
                    format!(
                        "`{name}` is {r}x{c} but `{}` is {rows}x{cols}; all inputs must have \
                         one shape",
                        names[0]
                    ),
                ));
            }
            mats.push(mat);
        }
        Ok(mats)
    }

    /// The tunable 1 × 1 parameter CSMat `"{module}.{key}"`, created with `value` unless it
    /// exists (a value set before, or by another file, wins).
    pub fn tunable(binder: &mut Binder<'_>, key: &str, value: f64) -> Mat {
        let full = format!("{}.{key}", binder.module_name());
        let mat = CsMat::from_row_slice(&full, 1, 1, &[value])
            .unwrap_or_else(|_| CsMat::zeros(&full, 1, 1));
        binder.param_or(&full, mat)
    }

    /// The tunable column parameter CSMat `"{module}.{key}"` (one row per value).
    pub fn tunable_column(binder: &mut Binder<'_>, key: &str, values: &[f64]) -> Mat {
        let full = format!("{}.{key}", binder.module_name());
        let mat = CsMat::from_row_slice(&full, values.len(), 1, values)
            .unwrap_or_else(|_| CsMat::zeros(&full, values.len(), 1));
        binder.param_or(&full, mat)
    }

    /// A value given to a `Params` in a Rust constructor of a derived component.
    pub fn value(x: impl Into<ParamValue>) -> ParamValue {
        x.into()
    }
}

#[cfg(test)]
mod tests {
    use super::support::{NonFinite, Range, optional, required};
    use crate::module::ModuleError;
    use crate::registry::Params;

    /// The refusal's key and reason.
    fn refused(result: Result<(), ModuleError>) -> (String, String) {
        match result {
            Err(ModuleError::Param { name, reason }) => (name, reason),
            other => panic!("expected a parameter refusal, got {other:?}"),
        }
    }

    #[test]
    fn range_refusals_say_what_is_wrong_in_words() {
        let at_least_zero = Range {
            min: Some(0.0),
            ..Range::default()
        };
        assert_eq!(
            refused(at_least_zero.check("std_dev", &vec![1.0, -1.0])),
            ("std_dev".into(), "-1 is negative: expected ≥ 0".into())
        );
        let positive = Range {
            above: Some(0.0),
            ..Range::default()
        };
        assert_eq!(
            refused(positive.check("duration", &0.0)).1,
            "0 is not positive: expected > 0"
        );
        let unit = Range {
            min: Some(0.0),
            max: Some(1.0),
            ..Range::default()
        };
        assert_eq!(
            refused(unit.check("share", &2.0)).1,
            "2 is out of range: expected ≥ 0 and ≤ 1"
        );
        assert_eq!(
            refused(unit.check("share", &f64::NAN)).1,
            "NaN is out of range: expected ≥ 0 and ≤ 1",
            "NaN is refused by every bound"
        );
        assert!(unit.check("share", &Some(0.5)).is_ok());
        assert!(unit.check("share", &None::<f64>).is_ok());
    }

    #[test]
    fn integer_range_refusals_say_a_whole_number() {
        let rows = Range {
            min: Some(1.0),
            max: Some(65536.0),
            ..Range::default()
        };
        assert_eq!(
            refused(rows.check("rows", &0usize)).1,
            "expected a whole number from 1 to 65536, got 0"
        );
        let at_least_one = Range {
            min: Some(1.0),
            ..Range::default()
        };
        assert_eq!(
            refused(at_least_one.check("rows", &Some(0u32))).1,
            "expected a whole number ≥ 1, got 0"
        );
    }

    #[test]
    fn non_finite_reads_infinities_and_nan_that_the_plain_types_refuse() {
        let params = Params::new()
            .with("lower", f64::NEG_INFINITY)
            .with("bounds", vec![1.0, f64::NAN]);
        let lower: NonFinite<f64> = required(&params, "lower").unwrap();
        assert_eq!(lower.0, f64::NEG_INFINITY);
        let bounds: NonFinite<Vec<f64>> = required(&params, "bounds").unwrap();
        assert!(bounds.0[1].is_nan());
        let err = required::<f64>(&params, "lower").unwrap_err();
        assert_eq!(
            err.to_string(),
            "parameter `lower`: -inf is not a finite number"
        );
        let absent: Option<NonFinite<f64>> = optional(&params, "upper").unwrap();
        assert!(absent.is_none());
    }
}
