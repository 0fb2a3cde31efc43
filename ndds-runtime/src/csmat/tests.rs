//! Unit tests of [`CsMat`]: construction, access, slicing, arithmetic, units and the table.
//! The wire format is tested in `tests/wire.rs`.

mod wire;

use super::*;

fn gain() -> CsMat {
    CsMat::from_rows("K", &[&[1.0, 2.0], &[3.0, 4.0], &[5.0, 6.0]])
        .unwrap()
        .with_row_fields([("tau1", "N.m"), ("tau2", "N.m"), ("tau3", "N.m")])
        .unwrap()
        .with_col_fields([("q1", "rad"), ("q2", "rad")])
        .unwrap()
}

fn state(q1: f64, q2: f64) -> CsMat {
    CsMat::from_row_slice("x", 2, 1, &[q1, q2])
        .unwrap()
        .with_row_fields([("q1", "rad"), ("q2", "rad")])
        .unwrap()
}

/// A deterministic pseudo-random matrix.
fn random(rng: &mut fastrand::Rng, name: &str, rows: usize, cols: usize) -> CsMat {
    let data: Vec<f64> = (0..rows * cols).map(|_| rng.f64() * 10.0 - 5.0).collect();
    CsMat::from_row_slice(name, rows, cols, &data).unwrap()
}

fn close(a: &CsMat, b: &CsMat) -> bool {
    a.shape() == b.shape()
        && a.matrix()
            .iter()
            .zip(b.matrix().iter())
            .all(|(x, y)| (x - y).abs() < 1e-9)
}

#[test]
fn construction_checks_lengths_and_field_counts() {
    let m = CsMat::from_row_slice("m", 2, 3, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
    assert_eq!(m.shape(), (2, 3));
    assert_eq!(m.get(1, 0).unwrap(), 4.0, "row-major data");
    assert_eq!(
        CsMat::from_row_slice("m", 2, 3, &[1.0; 5]).unwrap_err(),
        MatError::DataLength {
            mat: "m".into(),
            rows: 2,
            cols: 3,
            got: 5
        }
    );
    assert!(CsMat::from_row_slice("huge", usize::MAX, 2, &[]).is_err());
    let err = CsMat::from_rows("r", &[&[1.0, 2.0], &[3.0]]).unwrap_err();
    assert_eq!(err.to_string(), "row 1 of `r` has 1 values but row 0 has 2");
    assert_eq!(CsMat::from_rows("e", &[]).unwrap().shape(), (0, 0));
    assert!(CsMat::zeros("z", 0, 4).is_empty());
    let flat = CsMat::zeros("flat", 0, usize::MAX / 2);
    assert!(flat.clone().with_col_fields([("a", "")]).is_err());
    assert_eq!(flat.to_string(), "(empty)");

    let err = m.clone().with_row_fields([("a", "")]).unwrap_err();
    assert_eq!(
        err.to_string(),
        "`m` has 2 rows but 1 row fields were given"
    );
    let err = m
        .clone()
        .with_col_fields([("a", ""), ("b", ""), ("c", ""), ("d", "")])
        .unwrap_err();
    assert!(matches!(
        err,
        MatError::FieldCount {
            got: 4,
            expected: 3,
            axis: Axis::Col,
            ..
        }
    ));
    let k = gain();
    assert_eq!(k.row_fields()[2], Field::new("tau3", "N.m"));
    assert_eq!(k.col_fields().len(), 2);
}

#[test]
fn access_by_index_and_by_name() {
    let mut k = gain();
    assert_eq!(k.get_named("tau2", "q2").unwrap(), 4.0);
    k.set_named("tau3", "q1", -1.0).unwrap();
    assert_eq!(k.get(2, 0).unwrap(), -1.0);
    k.set(0, 1, 9.0).unwrap();
    assert_eq!(k.matrix()[(0, 1)], 9.0);
    let err = k.get(3, 0).unwrap_err();
    assert_eq!(err.to_string(), "(3, 0) is outside `K`, which is 3x2");
    assert!(k.set(0, 2, 1.0).is_err());
    let err = k.get_named("tau9", "q1").unwrap_err();
    assert_eq!(err.to_string(), "`K` has no row field named `tau9`");
    assert!(matches!(
        k.col_index("q3"),
        Err(MatError::UnknownField {
            axis: Axis::Col,
            ..
        })
    ));
    // A column vector's only column answers to "".
    let x = state(0.5, 0.25);
    assert_eq!(x.get_named("q2", "").unwrap(), 0.25);
    assert!(gain().get_named("tau1", "").is_err());
    assert!(CsMat::zeros("z", 2, 2).row_index("").is_err());
}

#[test]
fn slicing_by_names_keeps_fields() {
    let k = gain();
    let rows = k.rows_named(&["tau3", "tau1"]).unwrap();
    assert_eq!(rows.name(), "K");
    assert_eq!(rows.matrix().as_slice(), &[5.0, 1.0, 6.0, 2.0]);
    assert_eq!(rows.row_fields()[0].name, "tau3");
    assert_eq!(rows.col_fields(), k.col_fields());
    let cols = k.cols_named(&["q2"]).unwrap();
    assert_eq!(cols.shape(), (3, 1));
    assert_eq!(cols.col_fields(), &[Field::new("q2", "rad")]);
    assert_eq!(cols.row_fields(), k.row_fields());
    assert!(k.rows_named(&["tau1", "nope"]).is_err());
    assert_eq!(k.rows_named(&[]).unwrap().shape(), (0, 2));
}

#[test]
fn in_place_updates() {
    let mut k = gain();
    k.fill(2.0);
    assert!(k.matrix().iter().all(|&v| v == 2.0));
    k.copy_from_slice(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
    assert_eq!(k, gain());
    assert!(matches!(
        k.copy_from_slice(&[1.0]),
        Err(MatError::DataLength { got: 1, .. })
    ));
    let mut other = CsMat::zeros("o", 3, 2);
    other.copy_from(&k).unwrap();
    assert_eq!(other.matrix(), k.matrix());
    assert!(other.row_fields().is_empty(), "values only");
    let err = other.copy_from(&state(1.0, 2.0)).unwrap_err();
    assert_eq!(
        err.to_string(),
        "copy_from: shapes do not fit: `o` is 3x2, `x` is 2x1"
    );

    other.set_fields_from(&k);
    assert_eq!(other.row_fields(), k.row_fields());
    assert_eq!(other.col_fields(), k.col_fields());
    other.resize(3, 2);
    assert!(other.matrix().iter().all(|&v| v == 0.0));
    assert!(other.row_fields().is_empty() && other.col_fields().is_empty());
    other.resize(2, 2);
    other.set_fields_from(&k);
    assert!(
        other.row_fields().is_empty(),
        "3 row fields do not fit 2 rows"
    );
    assert_eq!(other.col_fields(), k.col_fields());
    other.set_name("renamed");
    assert_eq!(other.name(), "renamed");
}

#[test]
fn arithmetic_values_names_and_fields() {
    let k = gain();
    let u = k.mul(&state(1.0, -1.0)).unwrap();
    assert_eq!(u.name(), "K*x");
    assert_eq!(u.matrix().as_slice(), &[-1.0, -1.0, -1.0]);
    assert_eq!(u.row_fields(), k.row_fields());
    assert!(u.col_fields().is_empty());

    let sum = k.add(&k.scale(2.0)).unwrap();
    assert_eq!(sum.name(), "K+2*K");
    assert_eq!(sum.get(2, 1).unwrap(), 18.0);
    assert_eq!(sum.row_fields(), k.row_fields());
    let bare = CsMat::zeros("z", 3, 2);
    assert_eq!(
        bare.add(&k).unwrap().col_fields(),
        k.col_fields(),
        "fields from the right"
    );
    let diff = k.sub(&k).unwrap();
    assert_eq!(diff.name(), "K-K");
    assert!(diff.matrix().iter().all(|&v| v == 0.0));

    let t = k.transpose();
    assert_eq!(t.name(), "K'");
    assert_eq!(t.shape(), (2, 3));
    assert_eq!(t.row_fields(), k.col_fields());
    assert_eq!(t.col_fields(), k.row_fields());
    assert_eq!(t.get(1, 2).unwrap(), 6.0);
}

#[test]
fn shape_and_unit_mismatches_name_the_matrices() {
    let k = gain();
    let err = k.add(&state(0.0, 0.0)).unwrap_err();
    assert_eq!(
        err.to_string(),
        "add: shapes do not fit: `K` is 3x2, `x` is 2x1"
    );
    let err = k.mul(&k).unwrap_err();
    assert!(matches!(err, MatError::ShapeMismatch { op: "mul", .. }));

    let mm = CsMat::from_row_slice("y", 2, 1, &[1.0, 2.0])
        .unwrap()
        .with_row_fields([("q1", "rad"), ("q2", "deg")])
        .unwrap();
    let err = k.mul(&mm).unwrap_err();
    assert_eq!(
        err.to_string(),
        "mul: column 1 of `K` is `q2` [rad] but row 1 of `y` is `q2` [deg]"
    );
    let mut other = k
        .clone()
        .with_col_fields([("q1", "rad"), ("v", "m")])
        .unwrap();
    other.set_name("L");
    let err = k.sub(&other).unwrap_err();
    assert_eq!(
        err,
        MatError::UnitMismatch(Box::new(UnitMismatch {
            op: "sub",
            axis: Axis::Col,
            index: 1,
            left: "K".into(),
            left_field: "q2".into(),
            left_unit: "rad".into(),
            right: "L".into(),
            right_field: "v".into(),
            right_unit: "m".into(),
        }))
    );
    assert!(
        err.to_string()
            .contains("column 1 of `K` is `q2` [rad] but column 1 of `L` is `v` [m]")
    );
    // Unitless operands fit anything.
    assert!(k.mul(&CsMat::zeros("z", 2, 4)).is_ok());
}

#[test]
fn to_versions_match_the_allocating_ones() {
    let mut rng = fastrand::Rng::with_seed(7);
    for _ in 0..200 {
        let (r, k, c) = (rng.usize(0..9), rng.usize(0..9), rng.usize(0..9));
        let a = random(&mut rng, "a", r, k);
        let b = random(&mut rng, "b", k, c);
        let mut out = CsMat::zeros("out", r, c);
        out.fill(f64::NAN); // never read
        a.mul_to(&b, &mut out).unwrap();
        assert!(close(&out, &a.mul(&b).unwrap()), "{r}x{k} * {k}x{c}");
        assert_eq!(out.name(), "out");

        let a2 = random(&mut rng, "a2", r, k);
        let mut sum = CsMat::zeros("sum", r, k);
        a.add_to(&a2, &mut sum).unwrap();
        assert!(close(&sum, &a.add(&a2).unwrap()));
        a.sub_to(&a2, &mut sum).unwrap();
        assert!(close(&sum, &a.sub(&a2).unwrap()));
    }
}

#[test]
fn to_versions_check_the_output_shape_and_units() {
    let k = gain();
    let x = state(1.0, 2.0);
    let mut wrong = CsMat::zeros("u", 2, 1);
    let err = k.mul_to(&x, &mut wrong).unwrap_err();
    assert_eq!(
        err.to_string(),
        "mul_to: shapes do not fit: `u` is 2x1, `K*x` is 3x1"
    );
    let err = k.add_to(&k, &mut wrong).unwrap_err();
    assert!(matches!(err, MatError::ShapeMismatch { op: "add_to", .. }));
    assert!(k.sub_to(&x, &mut wrong).is_err());
    let deg = x
        .clone()
        .with_row_fields([("q1", "deg"), ("q2", "rad")])
        .unwrap();
    let mut u = CsMat::zeros("u", 3, 1);
    assert!(matches!(
        k.mul_to(&deg, &mut u),
        Err(MatError::UnitMismatch(m)) if m.index == 0
    ));
    k.mul_to(&x, &mut u).unwrap();
    assert_eq!(u.matrix().as_slice(), &[5.0, 11.0, 17.0]);
}

#[test]
fn inverse_and_solve() {
    let a = CsMat::from_rows("A", &[&[4.0, 1.0], &[2.0, 3.0]])
        .unwrap()
        .with_row_fields([("f", "N"), ("g", "N")])
        .unwrap()
        .with_col_fields([("p", "m"), ("q", "m")])
        .unwrap();
    let inv = a.inverse().unwrap();
    assert_eq!(inv.name(), "inv(A)");
    assert_eq!(inv.row_fields(), a.col_fields());
    assert_eq!(inv.col_fields(), a.row_fields());
    let eye = a.mul(&inv).unwrap();
    assert!(close(
        &eye,
        &CsMat::from_rows("I", &[&[1.0, 0.0], &[0.0, 1.0]]).unwrap()
    ));
    assert!(inv.mul(&a).is_ok(), "the inverse's units chain with A's");

    let b = CsMat::from_row_slice("b", 2, 1, &[9.0, 13.0])
        .unwrap()
        .with_row_fields([("f", "N"), ("g", "N")])
        .unwrap();
    let x = a.solve(&b).unwrap();
    assert_eq!(x.name(), "A\\b");
    assert!(close(
        &x,
        &CsMat::from_row_slice("", 2, 1, &[1.4, 3.4]).unwrap()
    ));
    assert_eq!(x.row_fields(), a.col_fields());

    let singular = CsMat::from_rows("S", &[&[1.0, 2.0], &[2.0, 4.0]]).unwrap();
    assert_eq!(
        singular.inverse().unwrap_err().to_string(),
        "`S` is singular (no finite inverse)"
    );
    assert!(matches!(singular.solve(&b), Err(MatError::Singular { .. })));
    let err = gain().inverse().unwrap_err();
    assert_eq!(err.to_string(), "inverse: `K` is 3x2, not square");
    assert!(matches!(
        gain().solve(&b),
        Err(MatError::NotSquare { op: "solve", .. })
    ));
    assert!(matches!(
        a.solve(&gain()),
        Err(MatError::ShapeMismatch { op: "solve", .. })
    ));
    let kb = b
        .clone()
        .with_row_fields([("f", "kN"), ("g", "N")])
        .unwrap();
    assert!(matches!(
        a.solve(&kb),
        Err(MatError::UnitMismatch(m)) if m.op == "solve"
    ));
    let empty = CsMat::zeros("E", 0, 0);
    assert_eq!(empty.inverse().unwrap().shape(), (0, 0));
    assert_eq!(
        empty.solve(&CsMat::zeros("e", 0, 3)).unwrap().shape(),
        (0, 3)
    );
}

#[test]
fn non_finite_values_never_panic() {
    let mut a = CsMat::zeros("A", 3, 3);
    a.fill(f64::NAN);
    assert!(a.inverse().is_err());
    assert!(a.solve(&CsMat::zeros("b", 3, 1)).is_err());
    assert!(a.mul(&a).unwrap().matrix().iter().all(|v| v.is_nan()));
    a.fill(f64::INFINITY);
    assert!(a.inverse().is_err());
    let _ = a.to_string();
}

#[test]
fn display_is_a_labelled_table() {
    let k = gain();
    assert_eq!(
        k.to_string(),
        "            q1 [rad]  q2 [rad]\n\
         tau1 [N.m]         1         2\n\
         tau2 [N.m]         3         4\n\
         tau3 [N.m]         5         6"
    );
    assert_eq!(
        format!("{:.2}", state(0.5, -1.0)),
        "              0\nq1 [rad]   0.50\nq2 [rad]  -1.00"
    );
    let bare = CsMat::from_row_slice("b", 1, 3, &[1.0 / 3.0, 1e12, -2e-7]).unwrap();
    assert_eq!(
        bare.to_string(),
        "          0          1           2\n0  0.333333  1.0000e12  -2.0000e-7"
    );
    let nan = CsMat::from_row_slice("n", 1, 2, &[f64::NAN, f64::NEG_INFINITY]).unwrap();
    assert_eq!(nan.to_string(), "     0     1\n0  NaN  -inf");
    assert_eq!(CsMat::zeros("e", 0, 2).to_string(), "(empty)");
}
