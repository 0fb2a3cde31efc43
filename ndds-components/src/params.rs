//! Checks of parameter values shared by the component files, and the one way the library
//! words a failure that is not about a parameter.
//!
//! A refused parameter is a [`ModuleError::Param`] naming it as a description file does, so
//! that the loader can point at it: `rows`, or dotted for a key of a table parameter
//! (`plant.stiffness`, see [`in_table`]). Its message reads "parameter `NAME`: REASON".
//! Anything else (a shape met while sampling, a design without a solution) is [`failed`].

use nalgebra::DMatrix;

use ndds_runtime::{ModuleError, ParamError};

/// A failure that is not about one parameter, in the module's words.
pub(crate) fn failed(text: impl Into<String>) -> ModuleError {
    ModuleError::Failed(text.into())
}

/// `err`, about the key `err.name` of the table parameter `table`, as the refusal of the
/// parameter `table.name`.
pub(crate) fn in_table(table: &str, err: ParamError) -> ModuleError {
    ModuleError::param(format!("{table}.{}", err.name), err.problem)
}

/// `x`, unless it is not a finite number.
pub(crate) fn finite(name: &str, x: f64) -> Result<f64, ModuleError> {
    if x.is_finite() {
        Ok(x)
    } else {
        Err(ModuleError::param(
            name,
            format!("{x} is not a finite number"),
        ))
    }
}

/// Fails on the first of `values` that is not a finite number.
pub(crate) fn all_finite(name: &str, values: &[f64]) -> Result<(), ModuleError> {
    values.iter().try_for_each(|x| finite(name, *x).map(drop))
}

/// The length the lists `(name, values)` agree on: each has one value or the longest one's
/// count. Every value must be finite.
pub(crate) fn common_length(lists: &[(&str, &[f64])]) -> Result<usize, ModuleError> {
    let n = lists.iter().map(|(_, v)| v.len()).max().unwrap_or(1);
    for (name, values) in lists {
        if values.is_empty() {
            return Err(ModuleError::param(*name, "expected at least one value"));
        }
        if values.len() != 1 && values.len() != n {
            let longest = lists.iter().find(|(_, v)| v.len() == n).map_or("", |l| l.0);
            return Err(ModuleError::param(
                *name,
                format!(
                    "has {} values but `{longest}` has {n}; give one value or {n}",
                    values.len()
                ),
            ));
        }
        all_finite(name, values)?;
    }
    Ok(n)
}

/// `values` as `n` values: a single value is repeated; otherwise there must be `n`.
pub(crate) fn broadcast(name: &str, values: &[f64], n: usize) -> Result<Vec<f64>, ModuleError> {
    match values.len() {
        1 => Ok(vec![values[0]; n]),
        len if len == n => Ok(values.to_vec()),
        len => Err(ModuleError::param(
            name,
            format!("has {len} values; expected one value or {n}"),
        )),
    }
}

/// The lists `(name, values)` as columns of one length `n`: the longest list's, every other
/// list having one value (repeated) or as many.
pub(crate) fn columns<const N: usize>(
    lists: [(&str, &[f64]); N],
) -> Result<[DMatrix<f64>; N], ModuleError> {
    let n = common_length(&lists)?;
    // Each list has one value or n (checked above): `i % len` repeats a single value.
    Ok(lists.map(|(_, values)| DMatrix::from_fn(n, 1, |i, _| values[i % values.len()])))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The parameter `err` refuses, and why.
    fn refused(err: ModuleError) -> (String, String) {
        match err {
            ModuleError::Param { name, reason } => (name, reason),
            other => panic!("expected a parameter error, got {other:?}"),
        }
    }

    #[test]
    fn refusals_name_the_parameter() {
        let (name, reason) = refused(all_finite("x0", &[1.0, f64::NAN]).unwrap_err());
        assert_eq!(
            (name.as_str(), reason.as_str()),
            ("x0", "NaN is not a finite number")
        );
        let err = common_length(&[("initial", &[0.0, 0.0]), ("final", &[1.0; 3])]).unwrap_err();
        assert_eq!(
            err.to_string(),
            "parameter `initial`: has 2 values but `final` has 3; give one value or 3"
        );
        let (name, _) = refused(broadcast("value", &[1.0, 2.0], 3).unwrap_err());
        assert_eq!(name, "value");
        let inner = ParamError {
            name: "stiffness".into(),
            problem: "expected a number".into(),
        };
        let (name, reason) = refused(in_table("plant", inner));
        assert_eq!(
            (name.as_str(), reason.as_str()),
            ("plant.stiffness", "expected a number")
        );
    }

    #[test]
    fn columns_repeat_single_values() {
        let [a, b] = columns([("a", &[1.0][..]), ("b", &[2.0, 3.0][..])]).unwrap();
        assert_eq!(a.as_slice(), [1.0, 1.0]);
        assert_eq!(b.as_slice(), [2.0, 3.0]);
        assert!(matches!(failed("x"), ModuleError::Failed(text) if text == "x"));
    }
}
