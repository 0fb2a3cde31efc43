//! Built-in sample types that `ndds pub --type` can publish without discovery.

use ndds_client::TypeDescription;

/// Names accepted by `--type`, with the Rust type each stands for.
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
        _ => return None,
    })
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
        for (name, _) in NAMES {
            let desc = describe(name).unwrap();
            assert!(desc.layout.is_some(), "{name} has a layout");
        }
        assert!(describe("quaternion").is_none());
    }
}
