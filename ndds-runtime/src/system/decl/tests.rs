//! The key tables drive reading and unknown-key reports; the unknown-CSMat rule.

use std::path::Path;

use super::{Description, SECTION_KEYS, SECTIONS, describe};
use crate::system::source::{self, Diagnostic, Diagnostics};
use crate::{ComponentSpec, ParamKind, ParamSpec};

/// A documented type with one input and one output.
static GAIN: ComponentSpec = ComponentSpec {
    name: "gain",
    summary: "y = u",
    params: &[
        ParamSpec::required("input", ParamKind::Input, "u"),
        ParamSpec::required("output", ParamKind::Output, "y"),
    ],
};

fn check(text: &str) -> (Description, Vec<Diagnostic>) {
    let files = source::read_text("t.toml", text, Path::new(".")).expect("valid TOML");
    let spec = |name: &str| match name {
        "gain" => Ok(Some(&GAIN)),
        _ => Err(vec!["gain".to_owned()]),
    };
    let mut p = Diagnostics::default();
    let d = describe(&files, &spec, &Default::default(), &mut p);
    (d, p.0)
}

#[test]
fn a_misspelled_key_of_any_section_gets_a_did_you_mean() {
    for section in SECTION_KEYS.iter().filter(|s| !s.open) {
        for key in section.keys {
            let wrong = format!("{}{}", key.name, &key.name[key.name.len() - 1..]);
            let (_, found) = check(&format!("{}\n{wrong} = 1\n", section.title()));
            let message = format!("unknown key `{wrong}` in {}", section.title());
            let d = found
                .iter()
                .find(|d| d.message == message)
                .unwrap_or_else(|| panic!("no `{message}` in {found:#?}"));
            let expected = d.expected.as_deref().unwrap_or("");
            assert!(
                expected.ends_with(&format!("(did you mean `{}`?)", key.name)),
                "{d}"
            );
            assert_eq!(d.location.line, 2, "{d}");
        }
    }
}

#[test]
fn the_component_section_takes_its_types_parameters() {
    let component = SECTION_KEYS.iter().find(|s| s.name == "component").unwrap();
    assert!(component.open);
    let text = "[[component]]\nname = \"g\"\ntype = \"gain\"\nhabitat = \"h\"\n\
                input = \"u\"\noutput = \"y\"\ninptu = \"u\"\n";
    let (_, found) = check(text);
    let d = found
        .iter()
        .find(|d| d.message == "`gain` has no parameter `inptu`")
        .unwrap_or_else(|| panic!("{found:#?}"));
    let expected = d.expected.as_deref().unwrap();
    assert!(expected.contains("(did you mean `input`?)"), "{d}");
    assert!(
        expected.ends_with("`name`, `type`, `habitat` or `group`"),
        "{d}"
    );
}

#[test]
fn the_key_tables_are_well_formed() {
    let names: Vec<&str> = SECTION_KEYS.iter().map(|s| s.name).collect();
    assert_eq!(SECTIONS[0], "include");
    assert_eq!(&SECTIONS[1..], names.as_slice());
    for section in SECTION_KEYS {
        for (i, key) in section.keys.iter().enumerate() {
            assert!(!key.takes.is_empty(), "{}.{}", section.name, key.name);
            let again = section.keys[..i].iter().any(|k| k.name == key.name);
            assert!(!again, "{}.{} twice", section.name, key.name);
        }
    }
}

#[test]
fn a_missing_key_says_what_its_table_says_it_takes() {
    let (_, found) = check("[[habitat]]\nname = \"h\"\n");
    assert_eq!(found.len(), 1, "{found:#?}");
    assert_eq!(found[0].message, "[[habitat]] has no `rate`");
    assert_eq!(
        found[0].expected.as_deref(),
        Some("`rate = ` the sample rate in Hz")
    );
}

#[test]
fn an_unknown_section_gets_a_did_you_mean() {
    let (_, found) = check("[[habitats]]\nname = \"h\"\n");
    assert_eq!(found.len(), 1, "{found:#?}");
    assert_eq!(found[0].message, "unknown section `habitats`");
    let expected = found[0].expected.as_deref().unwrap();
    assert!(
        expected.ends_with("(did you mean `habitat`?)"),
        "{expected}"
    );
}

#[test]
fn unknown_csmats_are_the_loaders_parameter_csmats_are_verifys() {
    let text = "[system]\ndisplay = [\"g.k\", \"y\", \"nothing\"]\n\n\
                [[habitat]]\nname = \"h\"\nrate = 10\n\n\
                [[component]]\nname = \"g\"\ntype = \"gain\"\nhabitat = \"h\"\n\
                input = \"g.gain\"\noutput = \"y\"\n";
    let (d, found) = check(text);
    assert_eq!(found.len(), 1, "{found:#?}");
    assert!(
        found[0].message.starts_with("unknown CSMat `nothing`"),
        "{}",
        found[0]
    );
    assert_eq!(found[0].expected.as_deref(), Some("one of `y`"));
    // `g.gain` and `g.k` are left to verify(), which knows what `g` creates.
    assert_eq!(d.display.len(), 3);
}
