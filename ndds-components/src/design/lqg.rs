//! The LQG design of a continuous plant at one sampling period: its weights, its result, and
//! the reference feedforward that makes the output settle at the reference.

use nalgebra::DMatrix;

use super::{discretize, dlqr, kalman_gain};

/// The feedforward `N` that makes `y = C·x` settle at `r` under `u = N·r − K·x`.
pub fn reference_gain(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    c: &DMatrix<f64>,
    k: &DMatrix<f64>,
) -> Option<DMatrix<f64>> {
    let n = a.nrows();
    let closed = DMatrix::identity(n, n) - a + b * k;
    let dc = c * closed.try_inverse()? * b;
    dc.try_inverse()
}

/// Everything an LQG controller for a continuous plant needs, discretised at one period.
#[derive(Clone, Debug, PartialEq)]
pub struct LqgDesign {
    /// Discrete state matrix.
    pub ad: DMatrix<f64>,
    /// Discrete input matrix.
    pub bd: DMatrix<f64>,
    /// Output matrix.
    pub c: DMatrix<f64>,
    /// State-feedback gain (`u = N·r − K·x̂`).
    pub k: DMatrix<f64>,
    /// Reference feedforward.
    pub n: DMatrix<f64>,
    /// Kalman gain.
    pub l: DMatrix<f64>,
}

/// Weights of an LQG design: state and input costs, process and measurement noise.
#[derive(Clone, Debug, PartialEq)]
pub struct LqgWeights {
    /// State cost (n × n).
    pub q: DMatrix<f64>,
    /// Input cost (m × m).
    pub r: DMatrix<f64>,
    /// Process noise covariance (n × n).
    pub process_noise: DMatrix<f64>,
    /// Measurement noise covariance (p × p).
    pub measurement_noise: DMatrix<f64>,
}

/// Designs an LQG controller for `ẋ = A·x + B·u`, `y = C·x` sampled every `dt` seconds, or
/// `None` if the plant is not stabilisable / detectable with these weights.
pub fn design_lqg(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    c: &DMatrix<f64>,
    dt: f64,
    weights: &LqgWeights,
) -> Option<LqgDesign> {
    let (ad, bd) = discretize(a, b, dt);
    let k = dlqr(&ad, &bd, &weights.q, &weights.r)?;
    let l = kalman_gain(&ad, c, &weights.process_noise, &weights.measurement_noise)?;
    let n = reference_gain(&ad, &bd, c, &k)?;
    Some(LqgDesign {
        ad,
        bd,
        c: c.clone(),
        k,
        n,
        l,
    })
}

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;

    use super::{LqgWeights, design_lqg, reference_gain};

    #[test]
    fn the_reference_gain_makes_the_output_settle_at_the_reference() {
        // x⁺ = 0.5·x + u, y = 2·x, u = N·r − 0.25·x: the steady state x = N·r/0.75 gives y = r.
        let one = |x: f64| DMatrix::from_element(1, 1, x);
        let n = reference_gain(&one(0.5), &one(1.0), &one(2.0), &one(0.25)).expect("a gain");
        assert!((n[0] - 0.375).abs() < 1e-12, "{n}");
    }

    #[test]
    fn a_mass_spring_damper_design_is_stable() {
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -4.0, -0.4]);
        let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
        let c = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
        let weights = LqgWeights {
            q: DMatrix::identity(2, 2),
            r: DMatrix::from_element(1, 1, 0.1),
            process_noise: DMatrix::identity(2, 2),
            measurement_noise: DMatrix::from_element(1, 1, 0.01),
        };
        let d = design_lqg(&a, &b, &c, 0.01, &weights).expect("a design");
        let control = crate::design::spectral_radius(&(&d.ad - &d.bd * &d.k));
        let estimator = crate::design::spectral_radius(&(&d.ad - &d.ad * &d.l * &d.c));
        assert!(control < 1.0 && estimator < 1.0, "{control}, {estimator}");
    }
}
