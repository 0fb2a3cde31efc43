//! A controller's steady state with CSMats allocates nothing: decoding samples of an unchanged
//! shape, name and fields into an existing matrix, and the `_to` arithmetic. A counting global
//! allocator counts the allocations of the test's own thread while it is tracked.

#[path = "../../ndds-client/tests/counting/mod.rs"]
mod counting;

use counting::{allocations_during, turn};
use ndds_runtime::CsMat;

fn labelled(name: &str, rows: usize, cols: usize, seed: f64) -> CsMat {
    let data: Vec<f64> = (0..rows * cols).map(|i| seed + i as f64 * 0.25).collect();
    let row_names: Vec<String> = (0..rows).map(|i| format!("out{i}")).collect();
    let col_names: Vec<String> = (0..cols).map(|j| format!("in{j}")).collect();
    CsMat::from_row_slice(name, rows, cols, &data)
        .unwrap()
        .with_row_fields(row_names.iter().map(|n| (n.as_str(), "N.m")))
        .unwrap()
        .with_col_fields(col_names.iter().map(|n| (n.as_str(), "rad")))
        .unwrap()
}

#[test]
fn decoding_same_shape_samples_allocates_nothing() {
    let _turn = turn();
    let samples: Vec<Vec<u8>> = (0..4)
        .map(|k| postcard::to_allocvec(&labelled("gain", 6, 8, f64::from(k))).unwrap())
        .collect();
    let mut target = CsMat::zeros("placeholder", 1, 1);
    target.decode_into(&samples[0]).unwrap(); // the first sample shapes and names it
    let mut ok = true;
    let allocations = allocations_during(|| {
        for i in 0..1000 {
            ok &= target.decode_into(&samples[i % samples.len()]).is_ok();
        }
    });
    assert!(ok, "every sample decodes");
    assert_eq!(
        target,
        labelled("gain", 6, 8, 3.0),
        "the last sample was decoded"
    );
    assert_eq!(
        allocations, 0,
        "allocations in 1000 same-shape decode_into calls"
    );
}

#[test]
fn the_to_arithmetic_allocates_nothing() {
    let _turn = turn();
    // 8x8 * 8x6 is above the size where nalgebra's gemm switches to matrixmultiply.
    let k = labelled("K", 8, 8, 1.0);
    let x = labelled("x", 8, 6, -2.0)
        .with_row_fields((0..8).map(|_| ("q", "rad")))
        .unwrap();
    let small = labelled("k", 3, 3, 0.5);
    let v = CsMat::from_row_slice("v", 3, 1, &[1.0, 2.0, 3.0]).unwrap();
    let mut u = CsMat::zeros("u", 8, 6);
    let mut w = CsMat::zeros("w", 3, 1);
    let mut sum = CsMat::zeros("sum", 8, 8);
    let mut ok = true;
    let allocations = allocations_during(|| {
        for _ in 0..1000 {
            ok &= k.mul_to(&x, &mut u).is_ok();
            ok &= small.mul_to(&v, &mut w).is_ok();
        }
    });
    assert!(ok, "every product fits");
    assert_eq!(allocations, 0, "allocations in 1000 mul_to calls");
    assert_eq!(u.matrix(), k.mul(&x).unwrap().matrix());
    assert_eq!(w.matrix(), small.mul(&v).unwrap().matrix());

    let allocations = allocations_during(|| {
        for _ in 0..1000 {
            ok &= k.add_to(&k, &mut sum).is_ok();
            ok &= k.sub_to(&k, &mut sum).is_ok();
        }
    });
    assert!(ok, "every sum fits");
    assert_eq!(allocations, 0, "allocations in 1000 add_to + sub_to calls");
}
