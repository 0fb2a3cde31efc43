//! Built-in sample types that `ndds pub --type` can publish without discovery, and the
//! recognition of the CSMat type, which `ndds echo` prints as a table and `ndds pub` validates.

use std::sync::OnceLock;

use ndds_client::TypeDescription;
use ndds_core::types::builtin;
use ndds_runtime::CsMat;

/// Names accepted by `--type`, with the name each type is announced under.
pub const NAMES: &[(&str, &str)] = &[
    ("bool", "bool"),
    ("i8", "i8"),
    ("i16", "i16"),
    ("i32", "i32"),
    ("i64", "i64"),
    ("u8", "u8"),
    ("u16", "u16"),
    ("u32", "u32"),
    ("u64", "u64"),
    ("f32", "f32"),
    ("f64", "f64"),
    ("string", "String"),
    ("bytes", "Vec<u8>"),
    ("csmat", builtin::CSMAT),
];

/// The description of a built-in type, or `None` for an unknown name.
pub fn describe(name: &str) -> Option<TypeDescription> {
    Some(match name {
        "bool" => TypeDescription::of::<bool>(),
        "i8" => TypeDescription::of::<i8>(),
        "i16" => TypeDescription::of::<i16>(),
        "i32" => TypeDescription::of::<i32>(),
        "i64" => TypeDescription::of::<i64>(),
        "u8" => TypeDescription::of::<u8>(),
        "u16" => TypeDescription::of::<u16>(),
        "u32" => TypeDescription::of::<u32>(),
        "u64" => TypeDescription::of::<u64>(),
        "f32" => TypeDescription::of::<f32>(),
        "f64" => TypeDescription::of::<f64>(),
        "string" => TypeDescription::of::<String>(),
        "bytes" => TypeDescription::of::<Vec<u8>>(),
        "csmat" => TypeDescription::named::<CsMat>(builtin::CSMAT),
        _ => return None,
    })
}

/// True when `desc` is the CSMat named matrix (same fingerprint as [`CsMat`]'s description).
pub fn is_csmat(desc: &TypeDescription) -> bool {
    static CSMAT: OnceLock<u64> = OnceLock::new();
    let csmat = *CSMAT.get_or_init(|| TypeDescription::of::<CsMat>().fingerprint());
    desc.layout.is_some() && desc.fingerprint() == csmat
}

/// Checks an encoded CSMat sample the way its consumers will decode it: data length
/// `rows * cols`, one field per row (column) or none.
pub fn check_csmat(payload: &[u8]) -> anyhow::Result<()> {
    let mut mat = CsMat::zeros("", 0, 0);
    mat.decode_into(payload)
        .map_err(|err| anyhow::anyhow!("the value is not a consistent CSMat: {err}"))
}

/// `bool, i8, ...` for error messages.
pub fn list() -> String {
    NAMES
        .iter()
        .map(|(name, _)| *name)
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_name_is_described() {
        for (name, announced) in NAMES {
            let desc = describe(name).unwrap();
            assert!(desc.layout.is_some(), "{name} has a layout");
            assert_eq!(desc.name, *announced, "{name} is announced as listed");
        }
        assert!(describe("quaternion").is_none());
    }

    #[test]
    fn csmat_is_recognised_and_checked() {
        let csmat = describe("csmat").unwrap();
        assert!(is_csmat(&csmat));
        assert!(!is_csmat(&describe("f64").unwrap()));
        assert!(!is_csmat(&TypeDescription::opaque(builtin::CSMAT)));
        let good = CsMat::from_row_slice("x", 2, 1, &[1.0, 2.0]).unwrap();
        check_csmat(&postcard::to_allocvec(&good).unwrap()).unwrap();
        let err = check_csmat(&[1, b'x', 2, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]).unwrap_err();
        assert_eq!(
            err.to_string(),
            "the value is not a consistent CSMat: `x` is 2x1 but 1 values were given"
        );
    }
}
