//! The dynamic codec against real Rust types: their layouts come from
//! [`TypeDescription::try_of`], their payloads from `postcard::to_allocvec`.

use std::collections::BTreeMap;

use proptest::prelude::*;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize, Serializer};
use serde_json::{Value, json};

use super::*;
use crate::types::{Container, ContainerShape, Format, TypeDescription};

#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
struct Pose {
    x: f64,
    y: f64,
    label: Option<String>,
}

#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
enum Shape {
    Empty,
    Circle(f64),
    Segment(i16, i16),
    Rect { w: u32, h: u32 },
}

#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
struct Meters(f64);

#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
struct Pair(i32, char);

#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
struct Marker;

#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
struct Tree {
    value: i32,
    children: Vec<Tree>,
}

#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
struct Holder {
    pose: Pose,
    grid: [u8; 3],
}

#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
struct Scene {
    name: String,
    // A direct enum field first: describe.rs traces an enum reached only through a `Vec` or
    // `Option` as a single bogus variant.
    shape: Shape,
    pose: Pose,
    shapes: Vec<Shape>,
    tags: BTreeMap<String, i64>,
    ids: BTreeMap<u32, String>,
    triple: (u8, i16, ()),
    grid: [u16; 3],
    distance: Meters,
    pair: Pair,
    marker: Marker,
    big: u128,
    small: i128,
    ratio: f32,
    flag: bool,
    maybe: Option<Box<Shape>>,
}

/// A byte string written with `serialize_bytes` (serde_bytes is not a dependency).
struct Raw(Vec<u8>);

impl Serialize for Raw {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(&self.0)
    }
}

fn layout_of<T: Serialize + DeserializeOwned>() -> TypeLayout {
    let layout = TypeDescription::try_of::<T>().unwrap().layout.unwrap();
    layout.validate().unwrap();
    layout
}

fn hand_layout(formats: Vec<Format>, containers: Vec<Container>) -> TypeLayout {
    let root = formats.len() as u32 - 1;
    let layout = TypeLayout {
        formats,
        root,
        containers,
    };
    layout.validate().unwrap();
    layout
}

/// Decodes `value`'s payload, checks that encoding the JSON gives the payload back byte for
/// byte, and returns the JSON.
fn round_trip<T: Serialize + DeserializeOwned>(value: &T) -> Value {
    let layout = layout_of::<T>();
    let payload = postcard::to_allocvec(value).unwrap();
    let json = decode_json(&layout, &payload).unwrap();
    assert_eq!(encode_json(&layout, &json).unwrap(), payload, "{json}");
    json
}

/// [`round_trip`], and checks the JSON is what `serde_json::to_value` makes of `value`.
fn agrees_with_serde_json<T: Serialize + DeserializeOwned>(value: &T) {
    assert_eq!(round_trip(value), serde_json::to_value(value).unwrap());
}

fn scene() -> Scene {
    Scene {
        name: "lab".to_owned(),
        shape: Shape::Circle(0.5),
        pose: Pose {
            x: 1.5,
            y: -0.25,
            label: Some("arm".to_owned()),
        },
        shapes: vec![Shape::Empty, Shape::Circle(2.0), Shape::Rect { w: 3, h: 4 }],
        tags: BTreeMap::from([("a".to_owned(), -1), ("b".to_owned(), i64::MAX)]),
        ids: BTreeMap::from([(7, "seven".to_owned()), (300, "many".to_owned())]),
        triple: (255, -300, ()),
        grid: [1, 2, 65535],
        distance: Meters(0.5),
        pair: Pair(-7, 'é'),
        marker: Marker,
        big: u128::MAX,
        small: -5,
        ratio: 0.1,
        flag: true,
        maybe: Some(Box::new(Shape::Segment(-1, 1))),
    }
}

#[test]
fn structs_options_newtypes_and_units_agree_with_serde_json() {
    agrees_with_serde_json(&Pose {
        x: 1.0,
        y: -2.5,
        label: Some("tip".to_owned()),
    });
    agrees_with_serde_json(&Pose {
        x: 0.0,
        y: 1e300,
        label: None,
    });
    agrees_with_serde_json(&Meters(3.25));
    agrees_with_serde_json(&Pair(-40, 'ß'));
    agrees_with_serde_json(&Marker);
    agrees_with_serde_json(&());
    agrees_with_serde_json(&(u64::MAX, i64::MIN, true, 'x'));
}

#[test]
fn every_variant_shape_agrees_with_serde_json() {
    assert_eq!(round_trip(&Shape::Empty), json!("Empty"));
    assert_eq!(round_trip(&Shape::Circle(1.5)), json!({"Circle": 1.5}));
    assert_eq!(
        round_trip(&Shape::Segment(-3, 4)),
        json!({"Segment": [-3, 4]})
    );
    let rect = Shape::Rect { w: 1, h: 2 };
    assert_eq!(round_trip(&rect), json!({"Rect": {"w": 1, "h": 2}}));
    for shape in [
        Shape::Empty,
        Shape::Circle(-0.5),
        Shape::Segment(1, 2),
        rect,
    ] {
        agrees_with_serde_json(&shape);
    }
}

#[test]
fn sequences_tuples_arrays_and_string_maps_agree_with_serde_json() {
    agrees_with_serde_json(&vec![Meters(1.0), Meters(2.0)]);
    agrees_with_serde_json(&Vec::<Pose>::new());
    agrees_with_serde_json(&(7u8, "seven".to_owned(), Some(false)));
    agrees_with_serde_json(&[-1i8, 0, 1, 127]);
    let map = BTreeMap::from([("one".to_owned(), vec![1u8]), ("none".to_owned(), vec![])]);
    agrees_with_serde_json(&map);
    agrees_with_serde_json(&Some(Some(3u16)));
}

#[test]
fn recursive_types_round_trip() {
    let leaf = |value| Tree {
        value,
        children: vec![],
    };
    let tree = Tree {
        value: 1,
        children: vec![
            leaf(2),
            Tree {
                value: 3,
                children: vec![leaf(4), leaf(5)],
            },
        ],
    };
    agrees_with_serde_json(&tree);
    assert_eq!(round_trip(&tree)["children"][1]["children"][0]["value"], 4);
}

#[test]
fn where_the_mapping_differs_from_serde_json() {
    // Non-string keys: pairs here, stringified keys in serde_json.
    let ids = BTreeMap::from([(7u32, "a".to_owned()), (9, "b".to_owned())]);
    assert_eq!(round_trip(&ids), json!([[7, "a"], [9, "b"]]));
    // 128-bit integers beyond 64 bits: strings here, an error in serde_json.
    assert_eq!(round_trip(&u128::MAX), json!(u128::MAX.to_string()));
    assert_eq!(round_trip(&i128::MIN), json!(i128::MIN.to_string()));
    assert_eq!(round_trip(&(u64::MAX as i128)), json!(u64::MAX));
    assert_eq!(round_trip(&-5i128), json!(-5));
    // f32: the shortest decimal here, the exact widening in serde_json.
    assert_eq!(round_trip(&0.1f32), json!(0.1));
    assert_eq!(
        serde_json::to_value(0.1f32).unwrap(),
        json!(0.10000000149011612)
    );
    // Non-finite floats: named here, null in serde_json.
    assert_eq!(round_trip(&f32::NAN), json!("NaN"));
    assert_eq!(round_trip(&f64::INFINITY), json!("inf"));
    assert_eq!(round_trip(&f32::NEG_INFINITY), json!("-inf"));
}

#[test]
fn a_compound_value_round_trips() {
    let json = round_trip(&scene());
    assert_eq!(json["pose"], json!({"x": 1.5, "y": -0.25, "label": "arm"}));
    assert_eq!(json["ids"], json!([[7, "seven"], [300, "many"]]));
    assert_eq!(json["triple"], json!([255, -300, null]));
    assert_eq!(json["pair"], json!([-7, "é"]));
    assert_eq!(json["marker"], Value::Null);
    assert_eq!(json["distance"], json!(0.5));
    assert_eq!(json["maybe"], json!({"Segment": [-1, 1]}));
}

#[test]
fn bytes_are_arrays_of_numbers() {
    let layout = hand_layout(vec![Format::Bytes], vec![]);
    let payload = postcard::to_allocvec(&Raw(vec![1, 2, 255])).unwrap();
    assert_eq!(payload, [3, 1, 2, 255]);
    let json = decode_json(&layout, &payload).unwrap();
    assert_eq!(json, json!([1, 2, 255]));
    assert_eq!(encode_json(&layout, &json).unwrap(), payload);
    let err = encode_json(&layout, &json!([1, 256])).unwrap_err();
    assert_eq!(
        err.to_string(),
        "at /: expected bytes (an array of numbers 0-255), found array of 2 elements"
    );
}

#[test]
fn convenient_json_is_accepted() {
    let layout = layout_of::<Scene>();
    let mut json = round_trip(&scene());
    json["big"] = json!("340282366920938463463374607431768211455");
    json["small"] = json!("-5");
    json["ids"] = json!({"300": "many", "7": "seven"});
    json["shapes"][0] = json!({"Empty": null});
    json["pose"].as_object_mut().unwrap().remove("label");
    let mut expected = scene();
    expected.pose.label = None;
    let payload = postcard::to_allocvec(&expected).unwrap();
    // Object members come in key order ("300" < "7"), so the map bytes differ in order only.
    let decoded: Scene = postcard::from_bytes(&encode_json(&layout, &json).unwrap()).unwrap();
    assert_eq!(decoded, expected);
    assert_eq!(encode_json(&layout, &json).unwrap().len(), payload.len());
}

fn encode_err<T: Serialize + DeserializeOwned>(json: Value) -> String {
    encode_json(&layout_of::<T>(), &json)
        .unwrap_err()
        .to_string()
}

#[test]
fn encode_errors_say_where_and_what() {
    let pose = json!({"x": "far", "y": 0.0});
    let err = encode_json(
        &layout_of::<Holder>(),
        &json!({"pose": pose, "grid": [1, 2, 3]}),
    );
    assert_eq!(
        err.unwrap_err(),
        DynamicError::Encode {
            path: "/pose/x".to_owned(),
            expected: "f64".to_owned(),
            found: "string \"far\"".to_owned(),
        }
    );
    let pose = json!({"x": 1.0, "y": 2.0});
    assert_eq!(
        encode_err::<Holder>(json!({"pose": pose, "grid": [1, 300, 3]})),
        "at /grid/1: expected u8, found number 300"
    );
    assert_eq!(
        encode_err::<Holder>(json!({"pose": pose, "grid": [1, 2]})),
        "at /grid: expected array of 3 elements, found array of 2 elements"
    );
    assert_eq!(
        encode_err::<Pose>(json!({"x": 1.0})),
        "at /y: expected f64, found nothing (the field is missing)"
    );
    assert_eq!(
        encode_err::<Pose>(json!({"x": 1.0, "y": 2.0, "z": 3.0})),
        "at /: expected a field of Pose (x, y, label), found field \"z\""
    );
    assert_eq!(
        encode_err::<Pose>(json!([1.0, 2.0, null])),
        "at /: expected object (struct Pose), found array of 3 elements"
    );
}

#[test]
fn encode_errors_in_enums_maps_and_scalars() {
    assert_eq!(
        encode_err::<Shape>(json!("Triangle")),
        "at /: expected a variant of Shape (Empty, Circle, Segment, Rect), found string \"Triangle\""
    );
    assert_eq!(
        encode_err::<Shape>(json!({"Segment": [1]})),
        "at /Segment: expected array of 2 elements, found array of 1 element"
    );
    assert_eq!(
        encode_err::<Shape>(json!("Circle")),
        "at /: expected {\"Circle\": value}, found string \"Circle\""
    );
    assert_eq!(
        encode_err::<Shape>(json!({"Rect": {"w": 1, "h": -1}})),
        "at /Rect/h: expected u32, found number -1"
    );
    assert_eq!(
        encode_err::<BTreeMap<u32, bool>>(json!([[1, true], [2]])),
        "at /1: expected a [key, value] pair, found array of 1 element"
    );
    assert_eq!(
        encode_err::<BTreeMap<u32, bool>>(json!({"x": true})),
        "at /x: expected u32, found string \"x\""
    );
    assert_eq!(
        encode_err::<char>(json!("ab")),
        "at /: expected char (a one-character string), found string \"ab\""
    );
    assert_eq!(
        encode_err::<f32>(json!(1e39)),
        "at /: expected f32, found number 1e+39"
    );
    assert_eq!(
        encode_err::<Marker>(json!(0)),
        "at /: expected null (unit struct Marker), found number 0"
    );
}

#[test]
fn decode_errors_say_where_and_what() {
    let layout = layout_of::<Holder>();
    let holder = Holder {
        pose: Pose {
            x: 1.0,
            y: 2.0,
            label: Some("ok".to_owned()),
        },
        grid: [1, 2, 3],
    };
    let payload = postcard::to_allocvec(&holder).unwrap();
    let err = decode_json(&layout, &payload[..12]).unwrap_err();
    assert!(
        matches!(&err, DynamicError::Decode { path, .. } if path == "/pose/y"),
        "{err}"
    );
    // Invalid UTF-8 in the label ("ok" starts at byte 18, after its tag and length).
    let mut bad = payload.clone();
    bad[18] = 0xFF;
    let err = decode_json(&layout, &bad).unwrap_err();
    assert!(
        matches!(&err, DynamicError::Decode { path, .. } if path == "/pose/label"),
        "{err}"
    );
    let mut long = payload.clone();
    long.extend([0, 0]);
    assert_eq!(decode_json(&layout, &long), Err(DynamicError::Trailing(2)));
    assert_eq!(
        decode_json(&layout_of::<Shape>(), &[9])
            .unwrap_err()
            .to_string(),
        "at /: enum Shape has no variant with index 9"
    );
}

#[test]
fn a_huge_claimed_length_of_units_fails_quickly() {
    let layout = hand_layout(vec![Format::Unit, Format::Seq(0)], vec![]);
    // Varint length 0xFFFF_FFFF.
    let payload = [0xFF, 0xFF, 0xFF, 0xFF, 0x0F];
    let err = decode_json(&layout, &payload).unwrap_err();
    assert!(
        matches!(err, DynamicError::TooManyElements { limit, .. } if limit == value_limit(5)),
        "{err}"
    );
    // Honest unit sequences within the budget decode.
    let units = postcard::to_allocvec(&vec![(); 1000]).unwrap();
    assert_eq!(
        decode_json(&layout, &units)
            .unwrap()
            .as_array()
            .unwrap()
            .len(),
        1000
    );
}

#[test]
fn a_layout_multiplying_zero_sized_values_fails_quickly() {
    // tuple<tuple<...<unit × 100>...> × 100>, ten levels: 100^10 units in zero bytes.
    // `validate` refuses it; the decoder must still fail fast if handed it unvalidated.
    let mut formats = vec![Format::Unit];
    for level in 0..10 {
        formats.push(Format::Tuple(vec![level; 100]));
    }
    let layout = TypeLayout {
        root: formats.len() as u32 - 1,
        formats,
        containers: vec![],
    };
    assert!(matches!(
        layout.validate(),
        Err(crate::types::LayoutError::TooLarge(_))
    ));
    let err = decode_json(&layout, &[]).unwrap_err();
    assert!(matches!(err, DynamicError::TooManyElements { .. }), "{err}");
}

fn nested_tree(levels: usize) -> Tree {
    let mut tree = Tree {
        value: 0,
        children: vec![],
    };
    for value in 1..levels as i32 {
        tree = Tree {
            value,
            children: vec![tree],
        };
    }
    tree
}

#[test]
fn nesting_is_bounded() {
    // A tree level is two values deep (the struct and its `children` sequence).
    let layout = layout_of::<Tree>();
    round_trip(&nested_tree(30));
    let deep = nested_tree(40);
    let payload = postcard::to_allocvec(&deep).unwrap();
    let err = decode_json(&layout, &payload).unwrap_err();
    assert!(
        matches!(
            err,
            DynamicError::TooDeep {
                limit: MAX_DEPTH,
                ..
            }
        ),
        "{err}"
    );
    let json = serde_json::to_value(&deep).unwrap();
    let err = encode_json(&layout, &json).unwrap_err();
    assert!(
        matches!(
            err,
            DynamicError::TooDeep {
                limit: MAX_DEPTH,
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn a_newtype_containing_itself_is_bounded() {
    // struct Loop(Loop): never consumes a byte, recurses through its container forever.
    let container = Container {
        name: "Loop".to_owned(),
        shape: ContainerShape::NewType(0),
    };
    let layout = hand_layout(vec![Format::Named(0)], vec![container]);
    let err = decode_json(&layout, &[]).unwrap_err();
    assert!(matches!(err, DynamicError::TooDeep { .. }), "{err}");
    let err = encode_json(&layout, &Value::Null).unwrap_err();
    assert!(matches!(err, DynamicError::TooDeep { .. }), "{err}");
}

#[test]
fn an_unvalidated_layout_is_an_error_not_a_panic() {
    let layout = TypeLayout {
        formats: vec![Format::Option(5), Format::Named(3)],
        root: 0,
        containers: vec![],
    };
    let err = decode_json(&layout, &[1]).unwrap_err();
    assert!(
        matches!(err, DynamicError::BadLayout { index: 5, .. }),
        "{err}"
    );
    assert!(matches!(
        encode_json(&layout, &json!(1)),
        Err(DynamicError::BadLayout { index: 5, .. })
    ));
    let named = TypeLayout { root: 1, ..layout };
    assert!(matches!(
        decode_json(&named, &[]),
        Err(DynamicError::BadLayout {
            what: "container",
            ..
        })
    ));
    let nowhere = TypeLayout { root: 9, ..named };
    assert!(decode_json(&nowhere, &[]).is_err());
    assert!(encode_json(&nowhere, &json!(null)).is_err());
}

/// Layouts whose decoders the byte-level property tests attack.
fn attacked_layouts() -> Vec<TypeLayout> {
    // 8^5 units: as large as `validate` allows (MAX_EXPANDED_FORMATS).
    let dag = (0..5).map(|level| Format::Tuple(vec![level; 8]));
    vec![
        layout_of::<Scene>(),
        layout_of::<Tree>(),
        layout_of::<Shape>(),
        layout_of::<BTreeMap<u32, (f32, char, Option<()>)>>(),
        layout_of::<Vec<Option<Option<i128>>>>(),
        hand_layout(vec![Format::Unit, Format::Seq(0)], vec![]),
        hand_layout(vec![Format::Bytes], vec![]),
        hand_layout(std::iter::once(Format::Unit).chain(dag).collect(), vec![]),
    ]
}

/// Decodes `bytes` with `layout`; when that works, the JSON must encode, and decode back to
/// itself (the bytes may differ: non-canonical input, duplicate keys, NaN payloads).
fn check_bytes(layout: &TypeLayout, bytes: &[u8]) -> Result<(), TestCaseError> {
    let Ok(json) = decode_json(layout, bytes) else {
        return Ok(());
    };
    let again = encode_json(layout, &json).map_err(|e| TestCaseError::fail(e.to_string()))?;
    match decode_json(layout, &again) {
        // A shorter re-encoding has a smaller value budget.
        Err(DynamicError::TooManyElements { .. }) => Ok(()),
        redecoded => {
            prop_assert_eq!(redecoded, Ok(json));
            Ok(())
        }
    }
}

fn finite_or_canonical_nan_f64() -> impl Strategy<Value = f64> {
    any::<f64>().prop_map(|f| if f.is_nan() { f64::NAN } else { f })
}

fn finite_or_canonical_nan_f32() -> impl Strategy<Value = f32> {
    any::<f32>().prop_map(|f| if f.is_nan() { f32::NAN } else { f })
}

fn arb_pose() -> impl Strategy<Value = Pose> {
    let floats = finite_or_canonical_nan_f64;
    (floats(), floats(), proptest::option::of(".{0,8}")).prop_map(|(x, y, label)| Pose {
        x,
        y,
        label,
    })
}

fn arb_shape() -> impl Strategy<Value = Shape> {
    prop_oneof![
        Just(Shape::Empty),
        finite_or_canonical_nan_f64().prop_map(Shape::Circle),
        any::<(i16, i16)>().prop_map(|(a, b)| Shape::Segment(a, b)),
        any::<(u32, u32)>().prop_map(|(w, h)| Shape::Rect { w, h }),
    ]
}

fn arb_scene() -> impl Strategy<Value = Scene> {
    let first = (
        (".{0,12}", arb_shape()),
        arb_pose(),
        proptest::collection::vec(arb_shape(), 0..4),
        proptest::collection::btree_map(".{0,6}", any::<i64>(), 0..4),
        proptest::collection::btree_map(any::<u32>(), ".{0,6}", 0..4),
        any::<(u8, i16)>(),
        any::<[u16; 3]>(),
    );
    let second = (
        finite_or_canonical_nan_f64(),
        any::<(i32, char)>(),
        any::<(u128, i128)>(),
        finite_or_canonical_nan_f32(),
        any::<bool>(),
        proptest::option::of(arb_shape()),
    );
    (first, second).prop_map(|(first, second)| {
        let ((name, shape), pose, shapes, tags, ids, (a, b), grid) = first;
        let (distance, (p, c), (big, small), ratio, flag, maybe) = second;
        Scene {
            name,
            shape,
            pose,
            shapes,
            tags,
            ids,
            triple: (a, b, ()),
            grid,
            distance: Meters(distance),
            pair: Pair(p, c),
            marker: Marker,
            big,
            small,
            ratio,
            flag,
            maybe: maybe.map(Box::new),
        }
    })
}

fn arb_tree() -> impl Strategy<Value = Tree> {
    let leaf = any::<i32>().prop_map(|value| Tree {
        value,
        children: vec![],
    });
    leaf.prop_recursive(5, 32, 4, |inner| {
        (any::<i32>(), proptest::collection::vec(inner, 0..4))
            .prop_map(|(value, children)| Tree { value, children })
    })
}

proptest! {
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..96)) {
        for layout in attacked_layouts() {
            check_bytes(&layout, &bytes)?;
        }
    }

    #[test]
    fn corrupted_payloads_never_panic(
        scene in arb_scene(),
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..4),
        cut in any::<prop::sample::Index>(),
    ) {
        let layout = layout_of::<Scene>();
        let mut bytes = postcard::to_allocvec(&scene).unwrap();
        for (at, byte) in edits {
            let index = at.index(bytes.len());
            bytes[index] = byte;
        }
        check_bytes(&layout, &bytes)?;
        check_bytes(&layout, &bytes[..cut.index(bytes.len() + 1)])?;
    }

    #[test]
    fn compound_values_round_trip(scene in arb_scene()) {
        let json = round_trip(&scene);
        prop_assert_eq!(&json["name"], &json!(scene.name));
        prop_assert_eq!(&json["pose"]["label"], &json!(scene.pose.label));
    }

    #[test]
    fn recursive_values_round_trip(tree in arb_tree()) {
        prop_assert_eq!(round_trip(&tree), serde_json::to_value(&tree).unwrap());
    }

    #[test]
    fn every_f32_round_trips(bits in any::<u32>()) {
        let value = f32::from_bits(bits);
        if !value.is_nan() {
            prop_assert_eq!(round_trip(&value).is_number(), value.is_finite());
        }
    }
}

/// Whether `value` satisfies `schema`, for the draft-07 keywords [`json_schema`] writes (a
/// small checker for these tests; Python's `jsonschema` checks recordings in the interop
/// tests). `root` resolves `$ref`s.
fn satisfies(schema: &Value, value: &Value, root: &Value) -> bool {
    let Some(schema) = schema.as_object() else {
        return true;
    };
    if let Some(reference) = schema.get("$ref").and_then(Value::as_str) {
        let name = reference.trim_start_matches("#/definitions/");
        return satisfies(&root["definitions"][name], value, root);
    }
    let any_of = schema.get("anyOf").and_then(Value::as_array);
    if any_of.is_some_and(|any| !any.iter().any(|s| satisfies(s, value, root)))
        || schema.get("const").is_some_and(|c| c != value)
        || (schema.get("enum").and_then(Value::as_array)).is_some_and(|e| !e.contains(value))
    {
        return false;
    }
    let number = |key: &str| schema.get(key).and_then(Value::as_f64);
    let count = |key: &str| schema.get(key).and_then(Value::as_u64);
    match schema.get("type").and_then(Value::as_str) {
        None => true,
        Some("null") => value.is_null(),
        Some("boolean") => value.is_boolean(),
        Some("number") => value.is_number(),
        Some("integer") => {
            let Some(v) = value.as_f64().filter(|_| value.is_i64() || value.is_u64()) else {
                return false;
            };
            number("minimum").is_none_or(|m| v >= m) && number("maximum").is_none_or(|m| v <= m)
        }
        Some("string") => value.as_str().is_some_and(|s| {
            let n = s.chars().count() as u64;
            count("minLength").is_none_or(|m| n >= m) && count("maxLength").is_none_or(|m| n <= m)
        }),
        Some("array") => value.as_array().is_some_and(|items| {
            let n = items.len() as u64;
            let sized = count("minItems").is_none_or(|m| n >= m)
                && count("maxItems").is_none_or(|m| n <= m);
            let each = match schema.get("items") {
                Some(Value::Array(positional)) => items
                    .iter()
                    .zip(positional)
                    .all(|(v, s)| satisfies(s, v, root)),
                Some(one) => items.iter().all(|v| satisfies(one, v, root)),
                None => true,
            };
            sized && each
        }),
        Some("object") => value.as_object().is_some_and(|members| {
            let properties = schema.get("properties").and_then(Value::as_object);
            let required = schema
                .get("required")
                .and_then(Value::as_array)
                .is_none_or(|r| {
                    r.iter()
                        .all(|k| k.as_str().is_some_and(|k| members.contains_key(k)))
                });
            required
                && members.iter().all(|(k, v)| {
                    match (
                        properties.and_then(|p| p.get(k)),
                        schema.get("additionalProperties"),
                    ) {
                        (Some(s), _) => satisfies(s, v, root),
                        (None, Some(Value::Bool(false))) => false,
                        (None, Some(other)) => satisfies(other, v, root),
                        (None, None) => true,
                    }
                })
        }),
        Some(_) => false,
    }
}

fn schema_of<T: Serialize + DeserializeOwned>() -> Value {
    json_schema(&layout_of::<T>(), "test").unwrap()
}

#[test]
fn the_json_schema_describes_decoded_samples_and_refuses_others() {
    let schema = schema_of::<Scene>();
    let json = round_trip(&scene());
    assert!(satisfies(&schema, &json, &schema), "{schema:#}\n{json:#}");
    assert_eq!(schema["title"], "Scene");
    assert_eq!(
        schema["properties"]["pose"]["properties"]["x"]["anyOf"][0]["type"],
        "number"
    );
    // A missing field, a wrong type, an unknown field, a bad variant: each refused.
    for broken in [
        {
            let mut j = json.clone();
            j.as_object_mut().unwrap().remove("name");
            j
        },
        {
            let mut j = json.clone();
            j["flag"] = json!(3);
            j
        },
        {
            let mut j = json.clone();
            j["extra"] = json!(1);
            j
        },
        {
            let mut j = json.clone();
            j["shape"] = json!("Hexagon");
            j
        },
        {
            let mut j = json.clone();
            j["grid"] = json!([1, 2]);
            j
        },
    ] {
        assert!(!satisfies(&schema, &broken, &schema), "{broken}");
    }
    // A recursive type refers to its own definition.
    let tree = schema_of::<Tree>();
    let value = Tree {
        value: 1,
        children: vec![Tree {
            value: 2,
            children: vec![],
        }],
    };
    assert!(satisfies(&tree, &round_trip(&value), &tree), "{tree:#}");
    assert!(
        tree["definitions"]
            .as_object()
            .is_some_and(|d| d.len() == 1),
        "{tree:#}"
    );
    assert!(!satisfies(
        &tree,
        &json!({"value": 1, "children": [{"value": "x", "children": []}]}),
        &tree
    ));
}

proptest! {
    #[test]
    fn every_decoded_scene_satisfies_the_schema(scene in arb_scene()) {
        let schema = schema_of::<Scene>();
        prop_assert!(satisfies(&schema, &round_trip(&scene), &schema));
    }
}
