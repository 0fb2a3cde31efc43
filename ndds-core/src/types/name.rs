//! The name a [`TypeDescription`] is announced with: the one discovery carries and every
//! tool, log and error message shows, whichever module the type lives in.
//!
//! The name is decided once, where the description is made:
//!
//! | made by | its name |
//! |---|---|
//! | [`TypeDescription::of`], [`try_of`](TypeDescription::try_of), a [`Describer`](super::Describer) | the Rust type with every module path removed ([`stable_name`]): `Pose`, `Vec<Pose>`, `String`, `Option<f64>`, `(i32, String)`, `[f64; 3]` |
//! | [`TypeDescription::named`], [`with_name`](TypeDescription::with_name), [`opaque`](TypeDescription::opaque) | the name given, as given |
//!
//! Nothing shortens it later: tools print [`TypeDescription::name`] as it arrived.
//!
//! A traced type matches by its fingerprint, which never includes this name (its containers
//! are named by their serde names, also without paths), so a type moved to another module,
//! or given an explicit name, still matches its old self. An *opaque* type matches by this
//! name, so a derived one makes it independent of module paths too.
//!
//! The `ndds::` namespace is reserved for the types this workspace puts on the network; they
//! are listed in [`builtin`]. A derived name never contains `::`, so none collides with them.
//!
//! ```
//! use ndds_core::types::{TypeDescription, builtin};
//!
//! mod app { #[derive(serde::Serialize, serde::Deserialize)] pub struct Pose { pub x: f64 } }
//!
//! assert_eq!(TypeDescription::of::<Vec<app::Pose>>().name, "Vec<Pose>");
//! let named = TypeDescription::named::<app::Pose>("demo::Pose");
//! assert_eq!(named.name, "demo::Pose");
//! assert_eq!(named.fingerprint(), TypeDescription::of::<app::Pose>().fingerprint());
//! assert!(builtin::ALL.iter().all(|name| name.starts_with("ndds::")));
//! ```

use super::TypeDescription;

/// A Rust type path (as [`std::any::type_name`] spells it) without its module paths, in
/// generics, tuples and arrays too: `alloc::vec::Vec<my_crate::Pose>` → `Vec<Pose>`,
/// `(i32, alloc::string::String)` → `(i32, String)`.
///
/// ```
/// use ndds_core::types::stable_name;
///
/// assert_eq!(stable_name("alloc::vec::Vec<app::msg::Pose>"), "Vec<Pose>");
/// assert_eq!(stable_name("core::option::Option<f64>"), "Option<f64>");
/// assert_eq!(stable_name("[f64; 3]"), "[f64; 3]");
/// ```
pub fn stable_name(rust_path: &str) -> String {
    let mut out = String::with_capacity(rust_path.len());
    // Where the path being written started in `out`: a `::` cuts back to it.
    let mut segment_start = 0;
    let mut rest = rust_path;
    while let Some(c) = rest.chars().next() {
        if let Some(after) = rest.strip_prefix("::") {
            out.truncate(segment_start);
            rest = after;
            continue;
        }
        out.push(c);
        if !(c.is_alphanumeric() || c == '_') {
            segment_start = out.len();
        }
        rest = &rest[c.len_utf8()..];
    }
    out
}

/// The names of the types the workspace itself announces, all in the `ndds::` namespace.
/// Each crate describes its type with [`TypeDescription::named`] and the name here.
pub mod builtin {
    /// `ndds_runtime::CsMat`, on the topics a runtime publishes and subscribes to and from
    /// `ndds pub --type csmat`.
    pub const CSMAT: &str = "ndds::CsMat";
    /// `ndds_runtime::HabitatStats`, on a habitat's `cs/<runtime>/<habitat>/stats` topic.
    pub const HABITAT_STATS: &str = "ndds::HabitatStats";
    /// `ndds_runtime::fsm::Stimulus`, on a state machine's `fsm/<machine>/events` topic.
    pub const FSM_STIMULUS: &str = "ndds::fsm::Stimulus";
    /// `ndds_runtime::fsm::MachineState`, on a state machine's `fsm/<machine>/state` topic.
    pub const FSM_STATE: &str = "ndds::fsm::MachineState";
    /// `ndds_runtime::describe::SystemDescription`, on a runtime's `cs/<runtime>/description`.
    pub const SYSTEM_DESCRIPTION: &str = "ndds::SystemDescription";
    /// `ndds_client::ports::Request`, on `port/<port>/request`.
    pub const PORT_REQUEST: &str = "ndds::port::Request";
    /// `ndds_client::ports::Reply`, on `port/<port>/reply/<user>`.
    pub const PORT_REPLY: &str = "ndds::port::Reply";
    /// `ndds_client::ports::OwnerInfo`, on `port/<port>/owner`.
    pub const PORT_OWNER_INFO: &str = "ndds::port::OwnerInfo";
    /// `ndds_client::ports::UserInfo`, on `port/<port>/users`.
    pub const PORT_USER_INFO: &str = "ndds::port::UserInfo";
    /// `ndds_client::ports::Arrival`, a rendezvous arrival on a port's topics.
    pub const PORT_ARRIVAL: &str = "ndds::port::Arrival";
    /// `ndds_client::ports::Broadcast`, an owner's `sendall` message.
    pub const PORT_BROADCAST: &str = "ndds::port::Broadcast";
    /// `ndds_client::ports::BroadcastReply`, a user's answer to a `sendall`.
    pub const PORT_BROADCAST_REPLY: &str = "ndds::port::BroadcastReply";
    /// `ndds_client::ports::ModuleInfo`, a running module's declaration on `module/<name>`.
    pub const PORT_MODULE_INFO: &str = "ndds::port::ModuleInfo";
    /// The sample of `ndds perf`.
    pub const PERF_SAMPLE: &str = "ndds::PerfSample";

    /// Every name above.
    pub const ALL: &[&str] = &[
        CSMAT,
        HABITAT_STATS,
        FSM_STIMULUS,
        FSM_STATE,
        SYSTEM_DESCRIPTION,
        PORT_REQUEST,
        PORT_REPLY,
        PORT_OWNER_INFO,
        PORT_USER_INFO,
        PORT_ARRIVAL,
        PORT_BROADCAST,
        PORT_BROADCAST_REPLY,
        PORT_MODULE_INFO,
        PERF_SAMPLE,
    ];
}

impl TypeDescription {
    /// Describes `T` by tracing it (as [`of`](Self::of), opaque if it cannot be traced), to be
    /// announced as `name` instead of the name derived from its Rust path. For a traced type
    /// only what tools show changes, not what it matches.
    pub fn named<T: serde::Serialize + serde::de::DeserializeOwned>(name: &str) -> Self {
        Self::of::<T>().with_name(name)
    }

    /// The same description under another name, for one built otherwise (a
    /// [`Describer`](super::Describer)). A traced type keeps its fingerprint; an opaque one,
    /// which matches by name, gets the fingerprint of the new name.
    pub fn with_name(mut self, name: &str) -> Self {
        name.clone_into(&mut self.name);
        self
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use serde::{Deserialize, Serialize};

    use super::*;

    mod robot {
        pub mod msgs {
            #[derive(serde::Serialize, serde::Deserialize)]
            pub struct Pose {
                pub x: f64,
                pub y: f64,
            }

            #[derive(serde::Serialize, serde::Deserialize)]
            pub enum Shape {
                Dot,
                Circle(f64),
            }

            /// Untraceable on its own (an enum behind a `Vec`): opaque.
            #[derive(serde::Serialize, serde::Deserialize)]
            pub struct Scene {
                pub shapes: Vec<Shape>,
            }
        }
    }

    /// The same definitions in another module, as in another crate or after a move.
    mod moved {
        #[derive(serde::Serialize, serde::Deserialize)]
        pub struct Pose {
            pub x: f64,
            pub y: f64,
        }

        #[derive(serde::Serialize, serde::Deserialize)]
        pub enum Shape {
            Dot,
            Circle(f64),
        }

        #[derive(serde::Serialize, serde::Deserialize)]
        pub struct Scene {
            pub shapes: Vec<Shape>,
        }
    }

    #[test]
    fn stable_names_drop_module_paths_everywhere() {
        assert_eq!(stable_name("alloc::string::String"), "String");
        assert_eq!(stable_name("my_robot::msgs::Pose"), "Pose");
        assert_eq!(
            stable_name("alloc::vec::Vec<core::option::Option<a::B>>"),
            "Vec<Option<B>>"
        );
        assert_eq!(
            stable_name("(i32, alloc::string::String, [a::b::C; 4])"),
            "(i32, String, [C; 4])"
        );
        assert_eq!(
            stable_name("std::collections::HashMap<alloc::string::String, f64>"),
            "HashMap<String, f64>"
        );
        assert_eq!(stable_name("f64"), "f64");
        assert_eq!(stable_name("()"), "()");
    }

    #[test]
    fn descriptions_are_made_with_stable_names() {
        let name = |desc: TypeDescription| desc.name;
        assert_eq!(name(TypeDescription::of::<String>()), "String");
        assert_eq!(name(TypeDescription::of::<Option<f64>>()), "Option<f64>");
        assert_eq!(
            name(TypeDescription::of::<Vec<robot::msgs::Pose>>()),
            "Vec<Pose>"
        );
        assert_eq!(
            name(TypeDescription::of::<(i32, String, [u8; 4])>()),
            "(i32, String, [u8; 4])"
        );
        let described = TypeDescription::describer()
            .with::<robot::msgs::Shape>()
            .describe::<robot::msgs::Scene>()
            .unwrap();
        assert_eq!(described.name, "Scene");
        assert_eq!(
            name(TypeDescription::of::<robot::msgs::Scene>()),
            "Scene",
            "an opaque fallback too"
        );
    }

    #[test]
    fn types_differing_only_in_module_path_match_under_one_name() {
        let here = TypeDescription::of::<robot::msgs::Pose>();
        let there = TypeDescription::of::<moved::Pose>();
        assert_eq!(here.fingerprint(), there.fingerprint());
        assert_eq!(here.name, "Pose");
        assert_eq!(here, there, "the whole description is the same");

        let here = TypeDescription::of::<robot::msgs::Scene>();
        let there = TypeDescription::of::<moved::Scene>();
        assert!(
            here.layout.is_none() && there.layout.is_none(),
            "both opaque"
        );
        assert_eq!(here.fingerprint(), there.fingerprint());
        assert_eq!(here.canonical_text(), r#"opaque="Scene""#);
    }

    #[test]
    fn an_explicit_name_is_shown_but_never_matched() {
        let derived = TypeDescription::of::<robot::msgs::Pose>();
        let named = TypeDescription::named::<moved::Pose>("demo::Pose");
        assert_eq!(named.name, "demo::Pose");
        assert_eq!(named.fingerprint(), derived.fingerprint());
        assert_eq!(named.layout, derived.layout);

        // An opaque type matches by name: its explicit name is its identity.
        let opaque = TypeDescription::named::<moved::Scene>("demo::Scene");
        assert_eq!(opaque.canonical_text(), r#"opaque="demo::Scene""#);
        assert_ne!(
            opaque.fingerprint(),
            TypeDescription::of::<moved::Scene>().fingerprint()
        );
    }

    #[test]
    fn a_renamed_type_matches_only_when_its_serde_name_stays() {
        #[derive(Serialize, Deserialize)]
        #[serde(rename = "Pose")]
        struct PoseMsg {
            x: f64,
            y: f64,
        }

        #[derive(Serialize, Deserialize)]
        struct Pose2D {
            x: f64,
            y: f64,
        }

        let pose = TypeDescription::of::<robot::msgs::Pose>();
        let serde_renamed = TypeDescription::of::<PoseMsg>();
        assert_eq!(serde_renamed.fingerprint(), pose.fingerprint());
        assert_eq!(serde_renamed.name, "PoseMsg", "shown by its own name");

        let renamed = TypeDescription::of::<Pose2D>();
        assert_ne!(
            renamed.fingerprint(),
            pose.fingerprint(),
            "the container name is part of the layout"
        );
        assert_eq!(renamed.name, "Pose2D");
    }

    #[test]
    fn builtin_names_are_distinct_and_in_the_ndds_namespace() {
        let distinct: BTreeSet<&str> = builtin::ALL.iter().copied().collect();
        assert_eq!(distinct.len(), builtin::ALL.len());
        for name in builtin::ALL {
            assert!(name.starts_with("ndds::"), "{name}");
            assert_eq!(name.trim(), *name, "{name:?}");
        }
    }
}
