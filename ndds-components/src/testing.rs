//! What the components' tests share: a runtime with the library and a manual habitat, runs
//! that record CSMats, the refusal a bad parameter meets, and the scalar Riccati closed form.

use nalgebra::DMatrix;

use ndds_runtime::{Clock, CsMat, HabitatOptions, ModuleError, Params, Runtime, RuntimeError};

pub(crate) type TestResult = Result<(), Box<dyn std::error::Error>>;
pub(crate) type Outcome<T> = Result<T, Box<dyn std::error::Error>>;

/// A runtime with the library, a manual habitat `h` at `rate` Hz and the column CSMats `mats`.
pub(crate) fn runtime(rate: f64, mats: &[(&str, &[f64])]) -> Outcome<Runtime> {
    let rt = Runtime::new("t");
    crate::register(&rt);
    rt.create_habitat("h", HabitatOptions::rate(rate).clock(Clock::Manual))?;
    for (name, values) in mats {
        rt.create_mat(CsMat::from_row_slice(*name, values.len(), 1, values)?)?;
    }
    Ok(rt)
}

/// Starts `h` and records element 0 of each of `mats` after each of `samples` samples:
/// `out[mat][sample]`. No module may fail.
pub(crate) fn trace(rt: &Runtime, mats: &[&str], samples: usize) -> Outcome<Vec<Vec<f64>>> {
    let h = rt.habitat("h");
    h.start()?;
    let mut out = vec![Vec::new(); mats.len()];
    for _ in 0..samples {
        h.step()?;
        for (values, name) in out.iter_mut().zip(mats) {
            values.push(rt.mat(name).value(0, 0));
        }
    }
    assert_eq!(h.stats().module_errors, 0);
    Ok(out)
}

/// Why installing `m` of `type_name` with `params` into `rt` fails (it must).
pub(crate) fn refusal(rt: &Runtime, type_name: &str, params: &Params) -> ModuleError {
    match rt.install_component("h", "m", type_name, params) {
        Ok(()) => panic!("{type_name} with bad parameters was installed"),
        Err(RuntimeError::Build { source, .. }) => source,
        Err(other) => panic!("{type_name}: expected a refusal by the component, got {other}"),
    }
}

/// Asserts that `err` refuses the parameter `name` with a message saying each of `says`.
pub(crate) fn assert_refuses(err: &ModuleError, name: &str, says: &[&str]) {
    match err {
        ModuleError::Param { name: refused, .. } => {
            assert_eq!(refused, name, "refused the wrong parameter: {err}");
        }
        other => panic!("expected parameter `{name}` to be refused, got {other:?}"),
    }
    let text = err.to_string();
    assert!(text.starts_with(&format!("parameter `{name}`: ")), "{text}");
    for s in says {
        assert!(text.contains(s), "`{text}` should say `{s}`");
    }
}

/// The positive root of the scalar discrete Riccati equation
/// `P = q + a²P − (abP)²/(r + b²P)`, i.e. `b²P² + ((1 − a²)r − qb²)P − qr = 0`.
pub(crate) fn scalar_riccati(a: f64, b: f64, q: f64, r: f64) -> f64 {
    let linear = (1.0 - a * a) * r - q * b * b;
    (-linear + (linear * linear + 4.0 * b * b * q * r).sqrt()) / (2.0 * b * b)
}

/// The scalar discrete LQR gain `abP/(r + b²P)` at that root.
pub(crate) fn scalar_gain(a: f64, b: f64, q: f64, r: f64) -> f64 {
    let p = scalar_riccati(a, b, q, r);
    a * b * p / (r + b * b * p)
}

/// The 1 × 1 matrix `[x]`.
pub(crate) fn one(x: f64) -> DMatrix<f64> {
    DMatrix::from_element(1, 1, x)
}
