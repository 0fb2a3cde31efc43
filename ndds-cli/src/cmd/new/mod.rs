//! `ndds new component NAME` and `ndds new system NAME`: a new directory NAME with a crate
//! holding a component type of the user's own (the derive, its routines, a known-answer test,
//! a program that runs description files with it, a description file using it, a README), or
//! with a description file of built-in components.
//!
//! The component crate depends on this ndds checkout by path: the one this `ndds` was built
//! from when it still exists, else `--ndds PATH`. The checkout's `Cargo.lock` is copied in, so
//! the crate builds with the dependency versions ndds was tested with.

mod templates;

use std::path::{Path, PathBuf};

use anyhow::Context as _;

use crate::outln;

/// Options of `ndds new`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(Debug, clap::Subcommand)]
enum What {
    /// A crate with a component type of your own and a program that runs systems with it.
    Component {
        /// The component type's name in description files, and the crate's (`my_filter`).
        name: String,
        /// The directory to create (default: NAME in the current directory).
        #[arg(long)]
        dir: Option<PathBuf>,
        /// The ndds checkout the crate depends on (default: the one this `ndds` was built
        /// from).
        #[arg(long, value_name = "PATH")]
        ndds: Option<PathBuf>,
    },
    /// A directory with a description file of built-in components, for `ndds run`.
    System {
        /// The system's name.
        name: String,
        /// The directory to create (default: NAME in the current directory).
        #[arg(long)]
        dir: Option<PathBuf>,
    },
}

/// Runs `ndds new`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    match &args.what {
        What::Component { name, dir, ndds } => {
            let dir = dir.clone().unwrap_or_else(|| PathBuf::from(name));
            let ndds = checkout(ndds.as_deref())?;
            component(name, &dir, &ndds)?;
            outln!("created component `{name}` in {}:", dir.display())?;
            outln!(
                "  cd {} && cargo test && cargo run -- system.toml",
                dir.display()
            )?;
        }
        What::System { name, dir } => {
            let dir = dir.clone().unwrap_or_else(|| PathBuf::from(name));
            system(name, &dir)?;
            outln!("created system `{name}` in {}:", dir.display())?;
            outln!("  ndds run {}", dir.join("system.toml").display())?;
        }
    }
    Ok(())
}

/// Refuses a name that cannot be a crate's and a component type's.
fn check_name(name: &str) -> anyhow::Result<()> {
    let first_ok = name.chars().next().is_some_and(|c| c.is_ascii_lowercase());
    let rest_ok = name
        .chars()
        .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_' || c == '-');
    anyhow::ensure!(
        first_ok && rest_ok && name.len() <= 64,
        "`{name}` cannot name a component: use lowercase letters, digits, `_` and `-`, \
         beginning with a letter (e.g. `my_filter`)"
    );
    Ok(())
}

/// Words a component's crate cannot be named: Rust's keywords (the crate's name is a path in
/// the generated `main.rs`) and the crates it links.
const RESERVED_CRATES: &[&str] = &[
    "abstract",
    "alloc",
    "as",
    "async",
    "await",
    "become",
    "box",
    "break",
    "const",
    "continue",
    "core",
    "crate",
    "do",
    "dyn",
    "else",
    "enum",
    "extern",
    "false",
    "final",
    "fn",
    "for",
    "gen",
    "if",
    "impl",
    "in",
    "let",
    "loop",
    "macro",
    "match",
    "mod",
    "move",
    "mut",
    "override",
    "priv",
    "proc_macro",
    "pub",
    "ref",
    "return",
    "self",
    "static",
    "std",
    "struct",
    "super",
    "test",
    "trait",
    "true",
    "try",
    "type",
    "typeof",
    "unsafe",
    "unsized",
    "use",
    "virtual",
    "where",
    "while",
    "yield",
];

/// Names the generated `lib.rs` imports: a struct of the same name would clash.
const IMPORTED_TYPES: &[&str] = &[
    "Clock",
    "Component",
    "CsMat",
    "DMatrix",
    "HabitatOptions",
    "Mat",
    "Params",
    "Registry",
    "RoutineResult",
    "Runtime",
    "SampleContext",
    "SampleModule",
];

/// Refuses a component name whose crate would not build or whose type would hide another.
fn check_component_name(name: &str) -> anyhow::Result<()> {
    check_name(name)?;
    let ident = name.replace('-', "_");
    anyhow::ensure!(
        !RESERVED_CRATES.contains(&ident.as_str()) && !ident.starts_with("ndds"),
        "`{name}` cannot name a component crate: it is a Rust keyword or the name of a crate \
         it links; choose another (e.g. `my_{ident}`)"
    );
    let rust_type = type_ident(name);
    anyhow::ensure!(
        !IMPORTED_TYPES.contains(&rust_type.as_str()),
        "`{name}` would make the struct `{rust_type}`, a name the component's code imports \
         from ndds_runtime; choose another (e.g. `my_{ident}`)"
    );
    let library = ndds_components::library();
    anyhow::ensure!(
        library.spec(name).is_none(),
        "`{name}` is a built-in component type (docs/components.md): a type of your own of that \
         name would replace it for every description file the program runs; choose another \
         (e.g. `my_{ident}`)"
    );
    Ok(())
}

/// `my_filter` → `MyFilter`.
fn type_ident(name: &str) -> String {
    name.split(['_', '-'])
        .filter(|part| !part.is_empty())
        .map(|part| {
            let mut chars = part.chars();
            chars
                .next()
                .map(|c| c.to_ascii_uppercase().to_string() + chars.as_str())
                .unwrap_or_default()
        })
        .collect()
}

/// The ndds checkout a new crate depends on.
fn checkout(asked: Option<&Path>) -> anyhow::Result<PathBuf> {
    let built_from = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let dir = asked.map_or(built_from, Path::to_path_buf);
    let dir = dir.canonicalize().with_context(|| {
        format!(
            "the ndds checkout {} does not exist; name one with --ndds PATH",
            dir.display()
        )
    })?;
    anyhow::ensure!(
        dir.join("ndds-runtime/Cargo.toml").is_file() && dir.join("ndds-cli/Cargo.toml").is_file(),
        "{} is not an ndds checkout (it has no ndds-runtime and ndds-cli); name one with --ndds \
         PATH",
        dir.display()
    );
    Ok(dir)
}

fn fill(template: &str, name: &str, ndds: &Path) -> String {
    let ndds = ndds
        .display()
        .to_string()
        .replace('\\', "\\\\")
        .replace('"', "\\\"");
    template
        .replace("{crate_ident}", &name.replace('-', "_"))
        .replace("{crate}", name)
        .replace("{type}", name)
        .replace("{Type}", &type_ident(name))
        .replace("{ndds}", &ndds)
}

/// Creates `dir` (which must not exist yet) with `files`.
fn write_all(dir: &Path, files: &[(&str, String)]) -> anyhow::Result<()> {
    anyhow::ensure!(
        !dir.exists(),
        "{} exists already; choose another name or --dir",
        dir.display()
    );
    for (path, text) in files {
        let path = dir.join(path);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("creating {}", parent.display()))?;
        }
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

fn component(name: &str, dir: &Path, ndds: &Path) -> anyhow::Result<()> {
    check_component_name(name)?;
    let f = |t: &str| fill(t, name, ndds);
    let mut files = vec![
        ("Cargo.toml", f(templates::CARGO_TOML)),
        ("src/lib.rs", f(templates::LIB_RS)),
        ("src/main.rs", f(templates::MAIN_RS)),
        ("system.toml", f(templates::COMPONENT_SYSTEM)),
        ("README.md", f(templates::COMPONENT_README)),
        (".gitignore", "/target\n".to_owned()),
    ];
    // The versions ndds was tested with (cargo adds what the new crate needs besides).
    if let Ok(lock) = std::fs::read_to_string(ndds.join("Cargo.lock")) {
        files.push(("Cargo.lock", lock));
    }
    write_all(dir, &files)
}

fn system(name: &str, dir: &Path) -> anyhow::Result<()> {
    check_name(name)?;
    let f = |t: &str| fill(t, name, Path::new(""));
    write_all(
        dir,
        &[
            ("system.toml", f(templates::SYSTEM)),
            ("README.md", f(templates::SYSTEM_README)),
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_become_rust_types_and_bad_names_are_refused() {
        assert_eq!(type_ident("my_filter"), "MyFilter");
        assert_eq!(type_ident("lead-lag2"), "LeadLag2");
        for bad in ["", "MyFilter", "1st", "a b", "x/y"] {
            let err = check_name(bad).unwrap_err().to_string();
            assert!(err.contains("lowercase letters"), "{bad}: {err}");
        }
        check_name("my_filter").unwrap();
        for (bad, says) in [
            ("fn", "Rust keyword"),
            ("ndds-cli", "crate it links"),
            ("std", "crate it links"),
            ("sample_module", "imports from ndds_runtime"),
            ("runtime", "imports from ndds_runtime"),
            ("sine", "built-in component type"),
        ] {
            let err = check_component_name(bad).unwrap_err().to_string();
            assert!(err.contains(says), "{bad}: {err}");
        }
        check_component_name("lead_lag").unwrap();
    }

    #[test]
    fn templates_are_filled_everywhere() {
        let ndds = Path::new("/src/nd\"ds");
        for t in [
            templates::CARGO_TOML,
            templates::LIB_RS,
            templates::MAIN_RS,
            templates::COMPONENT_SYSTEM,
            templates::COMPONENT_README,
        ] {
            let text = fill(t, "lead-lag", ndds);
            for placeholder in ["{crate}", "{type}", "{Type}", "{ndds}", "{crate_ident}"] {
                assert!(!text.contains(placeholder), "{placeholder} left in {text}");
            }
        }
        let manifest = fill(templates::CARGO_TOML, "x", ndds);
        assert!(
            manifest.contains(r#"path = "/src/nd\"ds/ndds-cli""#),
            "{manifest}"
        );
        assert!(fill(templates::MAIN_RS, "lead-lag", ndds).contains("lead_lag::LeadLag"));
    }

    #[test]
    fn an_existing_directory_is_left_alone() {
        let dir = tempfile::tempdir().unwrap();
        let err = system("plant", dir.path()).unwrap_err().to_string();
        assert!(err.contains("exists already"), "{err}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }
}
