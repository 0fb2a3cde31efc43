//! Broken description files: each gives the precise error (file, line, column, what is wrong,
//! what was expected), and nothing starts.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use ndds_runtime::system::{Diagnostic, System, SystemError};
use ndds_runtime::{Binder, ModuleError, Params, RoutineResult, Runtime, SampleContext};
use ndds_runtime::{SampleModule, Shape};

/// The line and column (from 1) where `needle` starts in `text`; `nth` for repeated needles.
fn at(text: &str, needle: &str, nth: usize) -> (usize, usize) {
    let offset = text
        .match_indices(needle)
        .nth(nth)
        .unwrap_or_else(|| panic!("`{needle}` #{nth} not in the text"))
        .0;
    let line = text[..offset].matches('\n').count() + 1;
    let column = offset - text[..offset].rfind('\n').map_or(0, |i| i + 1) + 1;
    (line, column)
}

fn problems(name: &str, text: &str) -> Vec<Diagnostic> {
    match System::from_str(name, text, None, ndds_components::library()) {
        Ok(_) => panic!("{name} loaded, but it is broken:\n{text}"),
        Err(SystemError::Invalid(d)) => d.0,
        Err(other) => panic!("{name}: expected diagnostics, got {other}"),
    }
}

/// The one problem of `text`, which must be at `needle` and say `says`.
fn expect_one(text: &str, needle: &str, says: &[&str]) -> Diagnostic {
    let found = problems("broken.toml", text);
    assert_eq!(found.len(), 1, "one problem expected, got: {found:#?}");
    let d = found.into_iter().next().unwrap();
    let (line, column) = at(text, needle, 0);
    assert_eq!(
        (d.location.line, d.location.column),
        (line, column),
        "problem reported at the wrong place: {d}"
    );
    assert_eq!(d.location.file.as_path(), Path::new("broken.toml"));
    for s in says {
        assert!(d.to_string().contains(s), "`{d}` should say `{s}`");
    }
    d
}

const HABITAT: &str = r#"
[[habitat]]
name = "h"
rate = 100.0
clock = "manual"

[[mat]]
name = "u"
value = [1.0]
"#;

#[test]
fn unknown_component_type_names_the_known_ones() {
    let text = format!(
        "{HABITAT}
[[component]]
name = \"g\"
type = \"gian\"
habitat = \"h\"
input = \"u\"
output = \"y\"
"
    );
    let d = expect_one(
        &text,
        "\"gian\"",
        &["unknown component type `gian`", "did you mean `gain`?"],
    );
    assert!(d.expected.as_deref().unwrap().contains("lowpass"), "{d}");
}

#[test]
fn unknown_csmat_is_reported_where_it_is_read() {
    let text = format!(
        "{HABITAT}
[[component]]
name = \"g\"
type = \"gain\"
habitat = \"h\"
input = \"uu\"
output = \"y\"
"
    );
    expect_one(
        &text,
        "\"uu\"",
        &[
            "unknown CSMat `uu`",
            "no [[mat]], component output",
            "did you mean `u`?",
        ],
    )
    .to_string();
}

#[test]
fn unknown_parameter_and_missing_parameter() {
    let text = format!(
        "{HABITAT}
[[component]]
name = \"f\"
type = \"lowpass\"
habitat = \"h\"
input = \"u\"
output = \"y\"
taw = 0.1
"
    );
    let found = problems("broken.toml", &text);
    // The unknown one is reported; the missing `tau` is not reported on top of it (one
    // mistake, one message).
    assert_eq!(found.len(), 1, "{found:#?}");
    assert_eq!(found[0].location.line, at(&text, "taw", 0).0);
    assert!(found[0].to_string().contains("no parameter `taw`"));
    assert!(
        found[0].to_string().contains("did you mean `tau`?"),
        "{}",
        found[0]
    );

    let text = text.replace("taw = 0.1\n", "");
    expect_one(&text, "\"f\"", &["has no `tau`", "`tau = ` a number"]);
}

#[test]
fn bad_values_say_what_was_expected() {
    let text = format!(
        "{HABITAT}
[[component]]
name = \"f\"
type = \"lowpass\"
habitat = \"h\"
input = \"u\"
output = \"y\"
tau = \"fast\"
"
    );
    expect_one(
        &text,
        "\"fast\"",
        &["parameter `tau` is a string", "expected a number"],
    );

    // One mistake, one message: the component in the broken habitat is not reported too.
    let text = "[[habitat]]\nname = \"h\"\nrate = -5\n\n[[mat]]\nname = \"u\"\nvalue = 1\n\n\
                [[component]]\nname = \"g\"\ntype = \"gain\"\nhabitat = \"h\"\n\
                input = \"u\"\noutput = \"y\"\n";
    expect_one(text, "-5", &["`rate` is -5 Hz", "expected a rate from"]);

    let text = "[[habitat]]\nname = \"h\"\nrate = 99999999999999999999\n";
    expect_one(text, "9999", &["`rate` is 100000000000000000000 Hz"]);

    let text = "[[habitat]]\nname = \"h\"\nrate = 10\nclock = \"sundial\"\n";
    expect_one(text, "\"sundial\"", &["unknown clock `sundial`"]);

    let text = "[[mat]]\nname = \"m\"\nvalue = [[1, 2], [3]]\n";
    expect_one(text, "[3]", &["has 1 numbers", "2, like the first row"]);
}

#[test]
fn a_value_the_component_refuses_is_reported_at_that_parameter() {
    let text = format!(
        "{HABITAT}
[[component]]
name = \"plant\"
type = \"mass_spring_damper\"
habitat = \"h\"
force = \"u\"
position = \"p\"
angle = \"a\"
mass = -1.0
"
    );
    // The component's own check (mass must be positive) runs when it is built.
    expect_one(
        &text,
        "\"plant\"",
        &["module `plant` could not be built", "mass"],
    );
}

#[test]
fn shape_mismatch_is_reported_where_the_csmat_is_used() {
    let text = format!(
        "{HABITAT}
[[mat]]
name = \"reference\"
value = [0.1, 0.2]

[[component]]
name = \"pd\"
type = \"pd\"
habitat = \"h\"
measured = \"u\"
reference = \"reference\"
output = \"force\"
kp = 1
kd = 0
"
    );
    expect_one(
        &text,
        "\"reference\"\noutput",
        &[
            "shape mismatch",
            "module `pd` expects CSMat `reference` to be 1x1, it is 2x1",
        ],
    );
}

#[test]
fn a_feedthrough_cycle_names_its_modules() {
    let text = format!(
        "{HABITAT}
[[component]]
name = \"a\"
type = \"gain\"
habitat = \"h\"
input = \"y\"
output = \"x\"

[[component]]
name = \"b\"
type = \"gain\"
habitat = \"h\"
input = \"x\"
output = \"y\"
"
    );
    let d = expect_one(&text, "\"b\"", &["algebraic loop"]);
    let s = d.to_string();
    assert!(s.contains("`a`") && s.contains("`b`"), "{s}");
}

#[test]
fn duplicate_names_point_at_the_first_declaration() {
    let text = format!(
        "{HABITAT}
[[component]]
name = \"g\"
type = \"gain\"
habitat = \"h\"
input = \"u\"
output = \"y\"

[[component]]
name = \"g\"
type = \"gain\"
habitat = \"h\"
input = \"u\"
output = \"z\"
"
    );
    let (line, column) = at(&text, "\"g\"", 0);
    let found = problems("broken.toml", &text);
    assert_eq!(found.len(), 1, "{found:#?}");
    let (l2, c2) = at(&text, "\"g\"", 1);
    assert_eq!((found[0].location.line, found[0].location.column), (l2, c2));
    assert!(
        found[0].to_string().contains(&format!(
            "duplicate component `g` (first declared at broken.toml:{line}:{column})"
        )),
        "{}",
        found[0]
    );
}

#[test]
fn unknown_sections_keys_habitats_groups_and_configurations() {
    let text = format!(
        "{HABITAT}
[[componet]]
name = \"x\"

[[habitat]]
name = \"h2\"
rate = 10
rte = 5

[[component]]
name = \"g\"
type = \"gain\"
habitat = \"hh\"
group = \"ctl/A\"
input = \"u\"
output = \"y\"

[[configuration]]
name = \"C\"
groups = [\"ctl/B\"]

[system]
configuration = \"D\"
"
    );
    let found = problems("broken.toml", &text);
    let says = |needle: &str, nth: usize, what: &str| {
        let (line, column) = at(&text, needle, nth);
        assert!(
            found.iter().any(|d| d.location.line == line
                && d.location.column == column
                && d.to_string().contains(what)),
            "no `{what}` at {line}:{column} in {found:#?}"
        );
    };
    says("componet", 0, "unknown section `componet`");
    says("rte", 0, "unknown key `rte` in [[habitat]]");
    says("\"hh\"", 0, "unknown habitat `hh`");
    says("\"ctl/B\"", 0, "group `ctl/B`, which no component is in");
    says("\"D\"", 0, "unknown configuration `D`");
    assert_eq!(found.len(), 5, "{found:#?}");
    // In file order.
    let lines: Vec<usize> = found.iter().map(|d| d.location.line).collect();
    let mut sorted = lines.clone();
    sorted.sort();
    assert_eq!(lines, sorted);
}

#[test]
fn syntax_errors_and_bad_includes() {
    let text = "[[habitat]]\nname = \"h\"\nrate = [1, 2\n";
    let found = problems("broken.toml", text);
    assert_eq!(found.len(), 1);
    assert!(
        found[0].message.starts_with("not valid TOML"),
        "{}",
        found[0]
    );
    assert!(found[0].location.line >= 3, "{}", found[0]);

    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.toml");
    let b = dir.path().join("b.toml");
    std::fs::write(&a, "include = [\"b.toml\"]\n").unwrap();
    std::fs::write(&b, "\ninclude = [\"a.toml\", \"missing.toml\"]\n").unwrap();
    let err = match System::load(&a, None, ndds_components::library()) {
        Err(SystemError::Invalid(d)) => d,
        Ok(_) => panic!("an include cycle loaded"),
        Err(other) => panic!("{other}"),
    };
    assert_eq!(err.0.len(), 2, "{err}");
    assert!(err.0[0].to_string().contains("include cycle"), "{err}");
    assert_eq!(err.0[0].location.line, 2, "{err}");
    assert!(err.0[0].location.file.ends_with("b.toml"), "{err}");
    assert!(err.0[1].to_string().contains("cannot read"), "{err}");
    assert!(err.0[1].to_string().contains("missing.toml"), "{err}");
}

#[test]
fn includes_are_relative_read_once_and_top_file_settings_win() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("parts")).unwrap();
    std::fs::write(
        dir.path().join("parts/habitat.toml"),
        "[system]\nname = \"inner\"\n\n[[habitat]]\nname = \"h\"\nrate = 100\nclock = \"manual\"\n",
    )
    .unwrap();
    std::fs::write(
        dir.path().join("parts/source.toml"),
        "include = \"habitat.toml\"\n\n[[mat]]\nname = \"u\"\nvalue = 2.0\n",
    )
    .unwrap();
    let top = dir.path().join("top.toml");
    std::fs::write(
        &top,
        "include = [\"parts/source.toml\", \"parts/habitat.toml\"]\n[system]\nname = \"outer\"\n\n\
         [[component]]\nname = \"g\"\ntype = \"gain\"\nhabitat = \"h\"\ninput = \"u\"\n\
         output = \"y\"\nk = 3\n",
    )
    .unwrap();
    let system = System::load(&top, None, ndds_components::library()).expect("loads");
    assert_eq!(system.name(), "outer");
    assert_eq!(system.files().len(), 3, "{:?}", system.files());
    system.start().unwrap();
    system.runtime().habitat("h").step().unwrap();
    assert_eq!(system.runtime().mat("y").value(0, 0), 6.0);
}

#[test]
fn an_overlay_stands_in_for_files_on_disk_and_files_that_do_not_exist_yet() {
    use ndds_runtime::system::{LoadOptions, Overlay, overlay_key};
    let dir = tempfile::tempdir().unwrap();
    let top = dir.path().join("top.toml");
    std::fs::write(
        &top,
        "include = [\"parts/gain.toml\"]\n[[habitat]]\nname = \"h\"\nrate = 100\nclock = \"manual\"\n\n\
         [[mat]]\nname = \"u\"\nvalue = 2.0\n",
    )
    .unwrap();
    std::fs::create_dir(dir.path().join("parts")).unwrap();
    let gain = "[[component]]\nname = \"g\"\ntype = \"gain\"\nhabitat = \"h\"\ninput = \"u\"\n\
                output = \"y\"\nk = 3\n";
    std::fs::write(dir.path().join("parts/gain.toml"), gain).unwrap();
    let on_disk = System::load(&top, None, ndds_components::library()).expect("loads");
    on_disk.start().unwrap();
    on_disk.runtime().habitat("h").step().unwrap();
    assert_eq!(on_disk.runtime().mat("y").value(0, 0), 6.0);
    drop(on_disk);

    // The included file as an editor holds it (named through `..`), and a state machine file
    // that exists only in the overlay.
    let mut overlay = Overlay::new();
    overlay.insert(
        overlay_key(&dir.path().join("parts/../parts/gain.toml")),
        format!(
            "{}\n[[state_machine]]\nfile = \"m.toml\"\n",
            gain.replace("k = 3", "k = 5")
        ),
    );
    overlay.insert(
        overlay_key(&dir.path().join("parts/m.toml")),
        "main = \"m\"\n[stimuli]\nGo = \"transient\"\n[[machine]]\nname = \"m\"\nstart = \"A\"\n\
         states = [\"A\", \"B\"]\n[[machine.transition]]\nfrom = \"A\"\nwhen = \"Go\"\nnext = { 0 = \"B\" }\n"
            .to_owned(),
    );
    let options = LoadOptions {
        overlay: Arc::new(overlay.clone()),
        ..LoadOptions::default().with_library(ndds_components::library())
    };
    let edited = System::load_with(&top, None, options.clone()).expect("the overlay loads");
    assert_eq!(edited.machine_names(), ["m"]);
    edited.start().unwrap();
    edited.runtime().habitat("h").step().unwrap();
    assert_eq!(edited.runtime().mat("y").value(0, 0), 10.0);
    drop(edited);
    assert!(
        !dir.path().join("parts/m.toml").exists(),
        "nothing was written"
    );

    // A mistake in a text of the overlay is reported where it is in that text.
    overlay.insert(
        overlay_key(&dir.path().join("parts/gain.toml")),
        gain.replace("k = 3", "k = \"three\""),
    );
    let options = LoadOptions {
        overlay: Arc::new(overlay),
        ..options
    };
    match System::load_with(&top, None, options) {
        Err(SystemError::Invalid(d)) => {
            assert_eq!(d.0.len(), 1, "{d}");
            assert!(d.0[0].location.file.ends_with("parts/gain.toml"), "{d}");
            assert_eq!(d.0[0].location.line, 7, "{d}");
            assert!(d.0[0].message.contains("`k`"), "{d}");
        }
        Ok(_) => panic!("a text gain loaded"),
        Err(other) => panic!("{other}"),
    }
}

/// A component type that counts its startups: proves nothing started.
#[derive(Clone, Default)]
struct Counter(Arc<AtomicUsize>);

struct Counted {
    count: Arc<AtomicUsize>,
}

impl SampleModule for Counted {
    fn startup(&mut self, _: &SampleContext) -> RoutineResult {
        self.count.fetch_add(1, Ordering::SeqCst);
        Ok(())
    }
}

fn counting_runtime(counter: &Counter) -> Runtime {
    let rt = Runtime::new("counted");
    ndds_components::register(&rt);
    let count = Arc::clone(&counter.0);
    rt.register_component(
        "counted",
        "counts startups",
        move |b: &mut Binder<'_>, p: &Params| -> Result<Counted, ModuleError> {
            b.output(p.text("output")?, Shape::Exact(1, 1));
            Ok(Counted {
                count: Arc::clone(&count),
            })
        },
    );
    rt
}

#[test]
fn nothing_starts_when_a_file_is_broken_and_custom_types_load() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.toml");
    let body = "[[habitat]]\nname = \"h\"\nrate = 100\nclock = \"manual\"\n\n\
                [[component]]\nname = \"c\"\ntype = \"counted\"\nhabitat = \"h\"\noutput = \"x\"\n";
    std::fs::write(&good, body).unwrap();
    let broken = dir.path().join("broken.toml");
    std::fs::write(
        &broken,
        format!(
            "{body}\n[[component]]\nname = \"g\"\ntype = \"gain\"\nhabitat = \"h\"\n\
             input = \"nothing\"\noutput = \"y\"\n"
        ),
    )
    .unwrap();

    let counter = Counter::default();
    let err = System::load_into(counting_runtime(&counter), &broken);
    assert!(matches!(err, Err(SystemError::Invalid(_))));
    assert_eq!(counter.0.load(Ordering::SeqCst), 0, "a module started");

    let system = System::load_into(counting_runtime(&counter), &good).expect("loads");
    assert_eq!(
        counter.0.load(Ordering::SeqCst),
        0,
        "started before start()"
    );
    system.start().unwrap();
    assert_eq!(counter.0.load(Ordering::SeqCst), 1);
    assert!(matches!(
        system.start(),
        Err(SystemError::AlreadyStarted(_))
    ));
}

#[test]
fn network_sections_need_a_participant() {
    let text = "[[habitat]]\nname = \"h\"\nrate = 10\n\n[[subscribe]]\nmat = \"u\"\n\
                topic = \"t/u\"\nhabitat = \"h\"\nshape = [1, 1]\n";
    let needs = match System::from_str("broken.toml", text, None, ndds_components::library()) {
        Err(SystemError::NeedsParticipant(d)) => d.0,
        Ok(_) => panic!("loaded without a participant"),
        Err(other) => panic!("expected NeedsParticipant, got {other}"),
    };
    assert_eq!(needs.len(), 1, "{needs:#?}");
    let (line, column) = at(text, "[[subscribe]]", 0);
    assert_eq!(
        (needs[0].location.line, needs[0].location.column),
        (line, column)
    );
    let d = needs[0].to_string();
    assert!(
        d.contains("`t/u`") && d.contains("connection to a daemon"),
        "{d}"
    );
}

#[test]
fn a_description_with_problems_reports_them_before_the_network_it_needs() {
    let text = "[[habitat]]\nname = \"h\"\nrate = 10\n\n[[subscribe]]\nmat = \"u\"\n\
                topic = \"t/u\"\nhabitat = \"nowhere\"\nshape = [1, 1]\n";
    let found = problems("broken.toml", text);
    assert!(
        found
            .iter()
            .any(|d| d.message.contains("unknown habitat `nowhere`")),
        "{found:#?}"
    );
    assert!(
        found.iter().all(|d| !d.message.contains("daemon")),
        "only the description's own problems: {found:#?}"
    );
}

#[test]
fn an_oversized_subscription_shape_is_refused_at_load() {
    let text = "[[habitat]]\nname = \"h\"\nrate = 10\n\n[[subscribe]]\nmat = \"image\"\n\
                topic = \"cam/image\"\nhabitat = \"h\"\nshape = [65536, 65536]\n";
    let found = problems("broken.toml", text);
    let (line, column) = at(text, "[65536", 0);
    assert!(
        found
            .iter()
            .any(|d| (d.location.line, d.location.column) == (line, column)
                && d.to_string().contains("at most 4194304 elements")),
        "{found:#?}"
    );
}

#[test]
fn a_components_refusal_points_at_the_parameter_it_names() {
    let text = format!(
        "{HABITAT}
[[component]]
name = \"c\"
type = \"step\"
habitat = \"h\"
final = [1.0, 2.0, 3.0]
initial = [0.0, 0.0]
output = \"y\"
"
    );
    expect_one(&text, "[0.0, 0.0]", &["parameter `initial`"]);
}

#[test]
fn parameter_csmats_groups_in_order_and_names() {
    // `<component>.<parameter>` CSMats may be displayed, read and set; the first group
    // declared in a category is the active one.
    let text = format!(
        "{HABITAT}
[system]
display = [\"g.k\"]

[[component]]
name = \"g\"
type = \"gain\"
habitat = \"h\"
group = \"ctl/Zeta\"
input = \"u\"
output = \"y\"

[[component]]
name = \"g2\"
type = \"gain\"
habitat = \"h\"
group = \"ctl/Alpha\"
input = \"u\"
output = \"y\"
"
    );
    let system =
        System::from_str("ok.toml", &text, None, ndds_components::library()).expect("loads");
    assert_eq!(system.runtime().active_groups()["ctl"], "Zeta");
    assert_eq!(system.status().display[0].1.get(0, 0).unwrap(), 1.0);

    let text = "[system]\nname = \"bad/name\"\n";
    expect_one(text, "\"bad/name\"", &["bad system name `bad/name`"]);

    let text = format!(
        "{HABITAT}
[[trigger]]
habitat = \"h\"
input = \"u\"
above = 2.0
below = 1.0
machine = \"m\"
stimulus = \"S\"
"
    );
    let found = problems("broken.toml", &text);
    assert!(
        found
            .iter()
            .any(|d| d.to_string().contains("could never fire")),
        "{found:#?}"
    );
}

#[test]
fn special_files_are_not_read_and_many_problems_are_capped() {
    let text = "include = \"/dev/zero\"\n";
    let found = problems("broken.toml", text);
    assert_eq!(found.len(), 1, "{found:#?}");
    assert!(
        found[0].to_string().contains("not a regular file"),
        "{}",
        found[0]
    );

    let mut text = String::from(HABITAT);
    for i in 0..150 {
        text.push_str(&format!(
            "\n[[component]]\nname = \"g{i}\"\ntype = \"gain\"\nhabitat = \"h\"\n\
             input = \"missing{i}\"\noutput = \"y{i}\"\n"
        ));
    }
    let found = problems("broken.toml", &text);
    assert_eq!(found.len(), 101, "100 problems and a count of the rest");
    assert_eq!(found[100].message, "... and 50 more problems");
    // Lists of known names are capped too.
    assert!(found[0].to_string().contains("more)"), "{}", found[0]);
}

#[test]
fn outputs_of_types_without_a_spec_count_as_provided() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("custom.toml");
    std::fs::write(
        &file,
        "[[habitat]]\nname = \"h\"\nrate = 100\nclock = \"manual\"\n\n\
         [[component]]\nname = \"c\"\ntype = \"counted\"\nhabitat = \"h\"\noutput = \"x\"\n\n\
         [[component]]\nname = \"g\"\ntype = \"gain\"\nhabitat = \"h\"\ninput = \"x\"\n\
         output = \"y\"\n",
    )
    .unwrap();
    let system = System::load_into(counting_runtime(&Counter::default()), &file);
    assert!(system.is_ok(), "{:?}", system.err().map(|e| e.to_string()));
}
