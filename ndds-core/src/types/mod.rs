//! Type descriptions: what a topic's sample type looks like, so that producers and consumers
//! of different types never match and tools can decode any topic without its Rust type.
//!
//! A [`TypeDescription`] is a [name] plus an optional structural [`TypeLayout`] traced
//! from the type's serde implementation. Its [`fingerprint`](TypeDescription::fingerprint) is
//! derived from the [canonical text](canonical) of the layout. Types that serde-reflection
//! cannot trace are *opaque*: they still match by name, but tools show their bytes in hex.
//! The name never holds a module path (`Vec<Pose>`, not `alloc::vec::Vec<my_crate::Pose>`):
//! it is made stable where the description is made, and the workspace's own types carry
//! explicit `ndds::` names ([`builtin`]). Messages show it as it is, or the type's
//! [shape](display) (`Pose{x: f64, y: f64}`).

pub mod canonical;
pub mod describe;
pub mod display;
pub mod layout;
pub mod name;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

pub use describe::{DescribeError, Describer, from_registry};
pub use layout::{
    Container, ContainerShape, Field, Format, LayoutError, TypeLayout, Variant, VariantShape,
};
pub use name::{builtin, stable_name};
/// The serde-reflection crate [`from_registry`] takes its formats from, so that a binding
/// builds them with the same version.
pub use serde_reflection;

/// The description of a topic's sample type.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TypeDescription {
    /// The name tools and messages show: the Rust type without module paths (`Vec<Pose>`), or
    /// a name given explicitly (`ndds::CsMat`); see [`name`]. Not part of the fingerprint
    /// unless the type is opaque.
    pub name: String,
    /// Structural layout, or `None` for an opaque type.
    pub layout: Option<TypeLayout>,
}

impl TypeDescription {
    /// Describes `T` by tracing it, named by its [stable name](stable_name); an untraceable
    /// type becomes opaque (see the module docs).
    pub fn of<T: Serialize + DeserializeOwned>() -> Self {
        match describe::describe::<T>() {
            Ok(desc) => desc,
            Err(err) => {
                let name = stable_name(std::any::type_name::<T>());
                tracing::warn!(error = %err, r#type = name, "type is opaque: it still matches by name, but tools cannot decode it");
                Self::opaque(&name)
            }
        }
    }

    /// Describes `T` by tracing it, failing if it cannot be traced.
    pub fn try_of<T: Serialize + DeserializeOwned>() -> Result<Self, DescribeError> {
        describe::describe::<T>()
    }

    /// A [`Describer`], for types with enums nested in sequences, options or maps.
    pub fn describer() -> Describer {
        Describer::new()
    }

    /// A description carrying only a name, taken as given.
    pub fn opaque(name: &str) -> Self {
        TypeDescription {
            name: name.to_owned(),
            layout: None,
        }
    }

    /// The canonical text the fingerprint is computed from.
    pub fn canonical_text(&self) -> String {
        match &self.layout {
            Some(layout) => canonical::canonical_text(layout),
            None => canonical::opaque_text(&self.name),
        }
    }

    /// The type fingerprint: first 8 bytes of SHA-256 of the canonical text, big-endian.
    pub fn fingerprint(&self) -> u64 {
        canonical::fingerprint_of_text(&self.canonical_text())
    }

    /// Checks the layout's structural rules (see [`TypeLayout::validate`]).
    pub fn validate(&self) -> Result<(), LayoutError> {
        self.layout.as_ref().map_or(Ok(()), TypeLayout::validate)
    }
}

/// Formats a fingerprint the way every ndds tool prints it: 16 lowercase hex digits.
pub fn fingerprint_hex(fingerprint: u64) -> String {
    format!("{fingerprint:016x}")
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use serde::{Deserialize, Serialize};

    use super::*;

    #[derive(Serialize, Deserialize)]
    struct Pose {
        x: f64,
        y: f64,
        label: Option<String>,
    }

    #[derive(Serialize, Deserialize)]
    enum Mode {
        Idle,
        Move { speed: f32 },
        Hold(u8, u8),
    }

    #[derive(Serialize, Deserialize)]
    struct Tree {
        value: i32,
        children: Vec<Tree>,
        table: BTreeMap<String, [u16; 3]>,
        mode: Mode,
    }

    #[test]
    fn a_registry_built_by_hand_describes_like_the_traced_type() {
        use serde_reflection::{ContainerFormat, Format as Sr, Named, Registry};
        let mut registry = Registry::new();
        let field = |name: &str, value| Named {
            name: name.to_owned(),
            value,
        };
        registry.insert(
            "Pose".to_owned(),
            ContainerFormat::Struct(vec![
                field("x", Sr::F64),
                field("y", Sr::F64),
                field("label", Sr::Option(Box::new(Sr::Str))),
            ]),
        );
        let root = Sr::TypeName("Pose".to_owned());
        let declared = from_registry("Pose", &root, &registry).unwrap();
        let traced = TypeDescription::try_of::<Pose>().unwrap();
        assert_eq!(declared, traced);
        assert_eq!(declared.fingerprint(), traced.fingerprint());
        // A name the registry does not hold is refused, naming the type.
        let missing = Sr::TypeName("Twist".to_owned());
        let err = from_registry("Twist", &missing, &registry).unwrap_err();
        assert!(err.to_string().contains("Twist"), "{err}");
    }

    #[test]
    fn canonical_text_of_a_struct() {
        let desc = TypeDescription::try_of::<Pose>().unwrap();
        assert_eq!(
            desc.canonical_text(),
            r#"root="Pose";"Pose"=struct{"x":f64,"y":f64,"label":option<str>};"#
        );
        assert_eq!(desc.name, "Pose");
    }

    #[test]
    fn recursive_types_and_enums_are_described() {
        let desc = TypeDescription::try_of::<Tree>().unwrap();
        assert_eq!(
            desc.canonical_text(),
            concat!(
                r#"root="Tree";"#,
                r#""Mode"=enum{0:"Idle":unit,1:"Move":struct{"speed":f32},2:"Hold":tuple(u8,u8)};"#,
                r#""Tree"=struct{"value":i32,"children":seq<"Tree">,"#,
                r#""table":map<str,array<u16;3>>,"mode":"Mode"};"#
            )
        );
        desc.validate().unwrap();
    }

    #[derive(Serialize, Deserialize)]
    enum Shape {
        Empty,
        Circle(f64),
        Rect { w: f64, h: f64 },
    }

    #[derive(Serialize, Deserialize)]
    struct Scene {
        shapes: Vec<Shape>,
        focus: Option<Mode>,
    }

    #[test]
    fn enums_behind_sequences_are_reported_and_can_be_pre_traced() {
        let err = TypeDescription::try_of::<Scene>().unwrap_err();
        let text = err.to_string();
        assert!(text.contains("Shape") && text.contains("Mode"), "{text}");
        assert!(
            TypeDescription::of::<Scene>().layout.is_none(),
            "falls back to opaque"
        );
        let desc = TypeDescription::describer()
            .with::<Shape>()
            .with::<Mode>()
            .describe::<Scene>()
            .unwrap();
        assert_eq!(
            desc.canonical_text(),
            concat!(
                r#"root="Scene";"#,
                r#""Mode"=enum{0:"Idle":unit,1:"Move":struct{"speed":f32},2:"Hold":tuple(u8,u8)};"#,
                r#""Scene"=struct{"shapes":seq<"Shape">,"focus":option<"Mode">};"#,
                r#""Shape"=enum{0:"Empty":unit,1:"Circle":newtype(f64),2:"Rect":struct{"w":f64,"h":f64}};"#
            )
        );
    }

    #[test]
    fn fingerprint_is_stable_and_structural() {
        // The value is part of the protocol: changing how fingerprints are computed breaks
        // matching with every deployed node, so this constant must never change silently.
        let f64_desc = TypeDescription::try_of::<f64>().unwrap();
        assert_eq!(f64_desc.canonical_text(), "root=f64;");
        // sha256("root=f64;") = 68568ad56bcbc0f8...
        assert_eq!(fingerprint_hex(f64_desc.fingerprint()), "68568ad56bcbc0f8");
        assert_ne!(
            TypeDescription::try_of::<f32>().unwrap().fingerprint(),
            f64_desc.fingerprint()
        );
        assert_ne!(
            TypeDescription::opaque("f64").fingerprint(),
            f64_desc.fingerprint()
        );
    }
}
