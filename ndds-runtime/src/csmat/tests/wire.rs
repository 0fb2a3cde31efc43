//! The CSMat wire format: layout, postcard round trips (random shapes and fields), validation of
//! inconsistent samples, and decoding in place.

use ndds_core::types::TypeDescription;
use serde::Serialize;

use super::super::wire::CsMatWire;
use super::super::*;

/// Any wire content, consistent or not.
#[derive(Serialize, Clone)]
#[serde(rename = "CsMat")]
struct RawWire {
    name: String,
    rows: u32,
    cols: u32,
    data: Vec<f64>,
    row_fields: Vec<Field>,
    col_fields: Vec<Field>,
}

fn raw(rows: u32, cols: u32, data: usize, row_fields: usize, col_fields: usize) -> Vec<u8> {
    postcard::to_allocvec(&RawWire {
        name: "m".into(),
        rows,
        cols,
        data: vec![1.5; data],
        row_fields: vec![Field::new("r", "u"); row_fields],
        col_fields: vec![Field::new("c", "v"); col_fields],
    })
    .unwrap()
}

fn random_text(rng: &mut fastrand::Rng) -> String {
    let alphabet = ['q', '1', ' ', '[', 'é', 'µ', '/', '_'];
    (0..rng.usize(0..6))
        .map(|_| alphabet[rng.usize(0..alphabet.len())])
        .collect()
}

fn random_mat(rng: &mut fastrand::Rng) -> CsMat {
    let (rows, cols) = (rng.usize(0..=8), rng.usize(0..=8));
    let data: Vec<f64> = (0..rows * cols)
        .map(|_| match rng.u8(0..20) {
            0 => f64::NAN,
            1 => f64::NEG_INFINITY,
            2 => -0.0,
            _ => rng.f64() * 2e6 - 1e6,
        })
        .collect();
    let mut m = CsMat::from_row_slice(random_text(rng), rows, cols, &data).unwrap();
    let fields = |rng: &mut fastrand::Rng, n| -> Vec<Field> {
        (0..n)
            .map(|_| Field {
                name: random_text(rng),
                unit: random_text(rng),
            })
            .collect()
    };
    if rng.bool() {
        m.row_fields = fields(rng, rows);
    }
    if rng.bool() {
        m.col_fields = fields(rng, cols);
    }
    m
}

/// Equality that treats NaN as equal to NaN and keeps the sign of zero.
fn same(a: &CsMat, b: &CsMat) -> bool {
    a.name == b.name
        && a.shape() == b.shape()
        && a.row_fields == b.row_fields
        && a.col_fields == b.col_fields
        && a.m
            .iter()
            .zip(b.m.iter())
            .all(|(x, y)| x.to_bits() == y.to_bits())
}

#[test]
fn the_type_has_a_structural_layout() {
    let desc = TypeDescription::try_of::<CsMat>().expect("CsMat traces");
    assert!(desc.layout.is_some());
    let text = desc.canonical_text();
    let order = ["name", "rows", "cols", "data", "row_fields", "col_fields"];
    let positions: Vec<usize> = order
        .iter()
        .map(|f| text.find(&format!("\"{f}\"")).unwrap())
        .collect();
    assert!(positions.is_sorted(), "fields in wire order: {text}");
    assert!(text.contains("CsMatField"), "{text}");
    assert_eq!(
        TypeDescription::of::<CsMat>().fingerprint(),
        desc.fingerprint()
    );
}

#[test]
fn the_encoding_is_the_documented_struct() {
    let m = CsMat::from_rows("K", &[&[1.0, 2.0], &[3.0, 4.0]])
        .unwrap()
        .with_col_fields([("a", "m"), ("b", "")])
        .unwrap();
    let expected = RawWire {
        name: "K".into(),
        rows: 2,
        cols: 2,
        data: vec![1.0, 2.0, 3.0, 4.0],
        row_fields: vec![],
        col_fields: vec![Field::new("a", "m"), Field::new("b", "")],
    };
    assert_eq!(
        postcard::to_allocvec(&m).unwrap(),
        postcard::to_allocvec(&expected).unwrap()
    );
}

#[test]
fn random_matrices_round_trip() {
    let mut rng = fastrand::Rng::with_seed(0x5eed);
    let mut reused = CsMat::zeros("", 0, 0);
    for case in 0..2000 {
        let m = random_mat(&mut rng);
        let bytes = postcard::to_allocvec(&m).unwrap();
        let back: CsMat = postcard::from_bytes(&bytes).unwrap();
        assert!(same(&back, &m), "case {case}: {m:?} became {back:?}");
        reused.decode_into(&bytes).unwrap();
        assert!(
            same(&reused, &m),
            "case {case} in place: {m:?} became {reused:?}"
        );
    }
}

#[test]
fn inconsistent_samples_are_refused() {
    let cases = [
        (raw(2, 2, 3, 0, 0), "`m` is 2x2 but 3 values were given"),
        (raw(2, 2, 5, 0, 0), "`m` is 2x2 but 5 values were given"),
        (raw(0, 3, 1, 0, 0), "`m` is 0x3 but 1 values were given"),
        (
            raw(2, 1, 2, 1, 0),
            "`m` has 2 rows but 1 row fields were given",
        ),
        (
            raw(2, 1, 2, 2, 3),
            "`m` has 1 columns but 3 column fields were given",
        ),
        (raw(u32::MAX, u32::MAX, 0, 0, 0), "at most 16777216 values"),
        (raw(1 << 13, 1 << 13, 0, 0, 0), "at most 16777216 values"),
    ];
    for (bytes, message) in cases {
        let mut m = CsMat::zeros("prev", 2, 2);
        let err = m.decode_into(&bytes).unwrap_err();
        assert!(err.to_string().contains(message), "{err} vs {message}");
        assert!(m.row_fields.is_empty() || m.row_fields.len() == m.rows());
        assert!(m.col_fields.is_empty() || m.col_fields.len() == m.cols());
        assert!(postcard::from_bytes::<CsMat>(&bytes).is_err(), "{message}");
    }
    // A sample claiming more values than its bytes can hold is refused without allocating
    // for them.
    let mut m = CsMat::zeros("", 0, 0);
    let err = m.decode_into(&raw(4000, 4000, 0, 0, 0)).unwrap_err();
    assert!(matches!(err, MatError::DataLength { got: 0, .. }), "{err}");
    assert_eq!(m.shape(), (0, 0));
    // The validation behind `Deserialize` explains itself (formats that keep custom messages,
    // such as JSON, show it).
    let wire = CsMatWire {
        name: "x".into(),
        rows: 2,
        cols: 1,
        data: vec![1.0],
        row_fields: vec![],
        col_fields: vec![],
    };
    let err = CsMat::try_from(wire).unwrap_err();
    assert_eq!(err.to_string(), "`x` is 2x1 but 1 values were given");
}

#[test]
fn truncated_and_random_bytes_are_errors() {
    let mut rng = fastrand::Rng::with_seed(99);
    for _ in 0..200 {
        let m = random_mat(&mut rng);
        let bytes = postcard::to_allocvec(&m).unwrap();
        let mut target = random_mat(&mut rng);
        for cut in 0..bytes.len() {
            let prefix = &bytes[..cut];
            assert!(postcard::from_bytes::<CsMat>(prefix).is_err());
            assert!(target.decode_into(prefix).is_err(), "prefix of {cut} bytes");
            assert!(target.row_fields.is_empty() || target.row_fields.len() == target.rows());
            assert!(target.col_fields.is_empty() || target.col_fields.len() == target.cols());
        }
        let noise: Vec<u8> = (0..rng.usize(0..64)).map(|_| rng.u8(..)).collect();
        let _ = postcard::from_bytes::<CsMat>(&noise);
        let _ = target.decode_into(&noise);
    }
}

#[test]
fn decode_into_reuses_or_resizes() {
    let k = CsMat::from_rows("K", &[&[1.0, 2.0], &[3.0, 4.0]])
        .unwrap()
        .with_row_fields([("a", "m"), ("b", "m")])
        .unwrap();
    let bytes = postcard::to_allocvec(&k).unwrap();
    let mut m = CsMat::zeros("placeholder", 3, 5)
        .with_col_fields([("c", ""); 5])
        .unwrap();
    m.decode_into(&bytes).unwrap();
    assert_eq!(m, k);
    let mut bigger = k.clone().with_col_fields([("x", "s"), ("y", "s")]).unwrap();
    bigger.set(1, 1, 7.0).unwrap();
    m.decode_into(&postcard::to_allocvec(&bigger).unwrap())
        .unwrap();
    assert_eq!(m, bigger);
    m.decode_into(&bytes).unwrap();
    assert_eq!(m, k, "fields dropped again when the sample has none");
}

#[test]
fn oversized_matrices_do_not_serialize() {
    let wide = CsMat::zeros("w", 0, usize::try_from(u64::from(u32::MAX) + 1).unwrap());
    assert!(postcard::to_allocvec(&wide).is_err());
}
