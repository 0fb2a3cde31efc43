//! The description-file reference, the component reference and the user guide against the
//! code: the section table and the sections' key tables are the loader's, the component
//! reference is generated from the components' own specs (`NDDS_BLESS=1 cargo test -p
//! ndds-docs --test systems` rewrites it), every `toml system` block loads and runs, and every
//! example file the docs name exists.

use std::path::Path;

use ndds_docs::markdown::{Doc, plain};
use ndds_docs::report::Problems;
use ndds_runtime::system::{LoadOptions, SECTION_KEYS, System};
use ndds_runtime::{ComponentSpec, ParamKind, Runtime};

/// The component reference's chapters, in order: every registered type must be in one.
const CHAPTERS: &[(&str, &[&str])] = &[
    ("Sources", &["constant", "step", "ramp", "sine", "noise"]),
    (
        "Arithmetic",
        &["gain", "sum", "product", "saturation", "dead_band"],
    ),
    (
        "Filters and dynamic systems",
        &["lowpass", "transfer_function", "state_space"],
    ),
    ("Controllers", &["pd", "pid", "lqg"]),
    ("Trajectories", &["trapezoidal", "quintic"]),
    ("Recording", &["recorder"]),
    ("Simulated plants", &["mass_spring_damper", "two_link_arm"]),
];

const BEGIN: &str = "<!-- generated from the component specs: do not edit by hand -->";
const END: &str = "<!-- end of generated reference -->";

fn kind(kind: ParamKind) -> &'static str {
    match kind {
        ParamKind::Input => "reads CSMat",
        ParamKind::Inputs => "reads CSMats",
        ParamKind::Output => "writes CSMat",
        ParamKind::Number => "number",
        ParamKind::Numbers => "numbers",
        ParamKind::Matrix => "matrix",
        ParamKind::Text => "string",
        ParamKind::File => "file name",
        ParamKind::Bool => "bool",
        ParamKind::Table => "table",
    }
}

fn render(spec: &ComponentSpec) -> String {
    let mut out = format!("### `{}`\n\n{}\n\n", spec.name, spec.summary);
    out.push_str("| parameter | kind | default | meaning |\n|---|---|---|---|\n");
    for p in spec.params {
        let meaning = p.meaning();
        out.push_str(&format!(
            "| `{}` | {} | {} | {} |\n",
            p.name,
            kind(p.kind),
            p.default.unwrap_or("required"),
            meaning.replace('|', "\\|")
        ));
    }
    out.push('\n');
    out
}

fn generated(rt: &Runtime) -> String {
    let mut out = String::new();
    for (chapter, types) in CHAPTERS {
        out.push_str(&format!("## {chapter}\n\n"));
        for name in *types {
            let spec = rt
                .component_spec(name)
                .unwrap_or_else(|| panic!("no documented component type `{name}`"));
            out.push_str(&render(spec));
        }
    }
    out
}

#[test]
fn component_reference_is_generated_from_the_specs() {
    let rt = Runtime::new("docs");
    ndds_components::register(&rt);
    let listed: Vec<&str> = CHAPTERS
        .iter()
        .flat_map(|(_, t)| t.iter().copied())
        .collect();
    let mut registered: Vec<String> = rt
        .component_specs()
        .iter()
        .map(|s| s.name.to_owned())
        .collect();
    registered.sort();
    let mut sorted: Vec<String> = listed.iter().map(|s| (*s).to_owned()).collect();
    sorted.sort();
    assert_eq!(
        sorted, registered,
        "every documented component type is in exactly one chapter of docs/components.md"
    );
    for spec in rt.component_specs() {
        assert!(
            !spec.summary.trim().is_empty(),
            "`{}` has no summary",
            spec.name
        );
        for p in spec.params {
            assert!(
                !p.doc.trim().is_empty(),
                "`{}.{}` is not documented",
                spec.name,
                p.name
            );
        }
    }

    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("components.md");
    let text = std::fs::read_to_string(&path).expect("docs/components.md");
    let (Some(begin), Some(end)) = (text.find(BEGIN), text.find(END)) else {
        panic!("docs/components.md lacks the generated-reference markers");
    };
    let now = &text[begin + BEGIN.len()..end];
    let wanted = format!("\n\n{}", generated(&rt));
    if now != wanted {
        if std::env::var_os("NDDS_BLESS").is_some() {
            let new = format!("{}{BEGIN}{wanted}{}", &text[..begin], &text[end..]);
            std::fs::write(&path, new).expect("rewrite docs/components.md");
        } else {
            panic!(
                "docs/components.md is not what the component specs say; regenerate it with \
                 NDDS_BLESS=1 cargo test -p ndds-docs --test systems"
            );
        }
    }
}

#[test]
fn section_table_is_the_loaders() {
    let doc = Doc::load("description-files.md");
    let mut problems = Problems::new();
    let table = doc.table(&["section", "keys"]).expect("the sections table");
    let mut listed = Vec::new();
    for row in &table.rows {
        let section = plain(&row.cells[0]);
        let section = section.trim_matches(['[', ']']).to_owned();
        let open = row.cells[1].contains("and the type's parameters");
        let keys: Vec<String> = row.cells[1]
            .split(',')
            .map(|k| plain(k).trim().to_owned())
            .filter(|k| !k.is_empty() && !k.starts_with("and the type"))
            .collect();
        match loader_keys(&section) {
            None => problems.at(
                &doc,
                row.line,
                format!("no section `{section}` in the loader"),
            ),
            Some((code, _)) if code != keys => problems.at(
                &doc,
                row.line,
                format!("`{section}` lists {keys:?}; the loader takes {code:?}"),
            ),
            Some((_, true)) if !open => problems.at(
                &doc,
                row.line,
                format!("`{section}` takes its type's parameters too: say so"),
            ),
            Some((_, false)) if open => problems.at(
                &doc,
                row.line,
                format!("`{section}` takes no keys but its own"),
            ),
            Some(_) => {}
        }
        listed.push(section);
    }
    let code: Vec<&str> = SECTION_KEYS.iter().map(|s| s.name).collect();
    if listed != code {
        problems.at(
            &doc,
            table.line,
            format!("sections {listed:?}; the loader has {code:?}"),
        );
    }
    problems.finish("docs/description-files.md");
}

/// The loader's keys of `section` and whether it takes others too (`None`: no such section).
fn loader_keys(section: &str) -> Option<(Vec<&'static str>, bool)> {
    let found = SECTION_KEYS.iter().find(|s| s.name == section)?;
    Some((found.key_names().collect(), found.open))
}

/// A section's own `| key | value |` table (under its `### [section]` heading) lists exactly
/// the loader's keys, in its order.
#[test]
fn key_tables_are_the_loaders() {
    let doc = Doc::load("description-files.md");
    let mut problems = Problems::new();
    let mut count = 0;
    for table in doc
        .tables()
        .iter()
        .filter(|t| t.starts_with(&["key", "value"]))
    {
        count += 1;
        let heading = table
            .heading
            .as_ref()
            .map(|h| plain(&h.text))
            .unwrap_or_default();
        let section = heading.trim_matches(['[', ']']);
        let keys: Vec<String> = table.rows.iter().map(|row| row.plain(0)).collect();
        match loader_keys(section) {
            None => problems.at(
                &doc,
                table.line,
                format!("no section `{heading}` in the loader"),
            ),
            Some((code, _)) if code != keys => problems.at(
                &doc,
                table.line,
                format!("`{heading}` lists {keys:?}; the loader takes {code:?}"),
            ),
            Some(_) => {}
        }
    }
    assert!(count >= 2, "the reference has key tables ({count})");
    problems.finish("docs/description-files.md");
}

/// Every `toml system` block of the guides loads, verifies and runs 2 s of simulated time.
#[test]
fn system_blocks_load_and_run() {
    let mut count = 0;
    let mut problems = Problems::new();
    for name in ["description-files.md", "user-guide.md", "components.md"] {
        let doc = Doc::load(name);
        for block in doc.blocks().into_iter().filter(|b| b.info == "toml system") {
            count += 1;
            let text: String = block.lines.iter().map(|(_, l)| format!("{l}\n")).collect();
            let dir = tempdir(&format!("block{count}"));
            let file = dir.join("system.toml");
            std::fs::write(&file, &text).unwrap();
            match System::load_with(
                &file,
                None,
                LoadOptions::simulated().with_library(ndds_components::library()),
            ) {
                Err(err) => problems.at(&doc, block.line, format!("does not load: {err}")),
                Ok(system) => {
                    system.start().unwrap();
                    match system.simulate(2.0) {
                        Ok(samples) if samples > 0 => {}
                        Ok(_) => problems.at(&doc, block.line, "ran no samples"),
                        Err(err) => problems.at(&doc, block.line, format!("does not run: {err}")),
                    }
                    let errors = system.status().module_errors();
                    if errors > 0 {
                        problems.at(&doc, block.line, format!("{errors} module errors"));
                    }
                }
            }
            let _ = std::fs::remove_dir_all(&dir);
        }
    }
    assert!(count >= 2, "the guides have runnable systems");
    problems.finish("system blocks");
}

/// Every `examples/....toml` the docs and README name exists.
#[test]
fn named_example_files_exist() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut problems = Problems::new();
    let mut count = 0;
    for name in [
        "description-files.md",
        "user-guide.md",
        "components.md",
        "cli.md",
        "../README.md",
    ] {
        let doc = Doc::load(name);
        for line in 1..=doc.len() {
            for word in doc
                .line(line)
                .split(|c: char| c.is_whitespace() || "`()[],'\"".contains(c))
            {
                if let Some(start) = word.find("examples/")
                    && word.ends_with(".toml")
                {
                    count += 1;
                    let path = &word[start..];
                    // As written from the repository's root (`ndds-client/examples/...`), or
                    // from `examples/`.
                    if !root.join(word).exists()
                        && !root.join(path).exists()
                        && !root.join("examples").join(path).exists()
                    {
                        problems.at(&doc, line, format!("`{path}` does not exist"));
                    }
                }
            }
        }
    }
    assert!(count >= 5, "the docs name the example files ({count})");
    problems.finish("example file names");
}

fn tempdir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("ndds-docs-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The guide's "make a mistake" example prints exactly what the loader says.
#[test]
fn the_guides_error_example_is_the_loaders() {
    let doc = Doc::load("user-guide.md");
    let blocks = doc.blocks();
    let first = blocks
        .iter()
        .find(|b| b.info == "toml system")
        .expect("the guide's first system");
    let text: String = first.lines.iter().map(|(_, l)| format!("{l}\n")).collect();
    let broken = text.replacen("input = \"wave\"", "input = \"wav\"", 1);
    assert_ne!(broken, text, "the first system reads `wave`");
    let shown = blocks
        .iter()
        .filter(|b| b.info == "text")
        .flat_map(|b| b.lines.iter())
        .find(|(_, l)| l.starts_with("first.toml:"))
        .expect("the guide shows the error");
    match System::from_str("first.toml", &broken, None, ndds_components::library()) {
        Err(ndds_runtime::system::SystemError::Invalid(d)) => {
            assert_eq!(d.0.len(), 1, "{d}");
            assert_eq!(
                d.0[0].to_string(),
                shown.1,
                "docs/user-guide.md:{} shows another message than the loader's",
                shown.0
            );
        }
        Ok(_) => panic!("the broken first system loaded"),
        Err(other) => panic!("{other}"),
    }
}
