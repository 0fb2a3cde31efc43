//! `#[derive(Component)]` end to end: the spec a struct's fields give, instances built through
//! a runtime and through a description file, and every refusal the generated factory makes,
//! reported at the parameter it names (file:line:column for a description file).

use std::path::{Path, PathBuf};

use nalgebra::DMatrix;

use ndds_runtime::system::{Diagnostic, System, SystemError};
use ndds_runtime::{Binder, Clock, Component, ComponentSpec, CsMat, HabitatOptions, Mat};
use ndds_runtime::{ModuleError, ParamKind, ParamSpec, Params, Registry, RoutineResult};
use ndds_runtime::{Runtime, RuntimeError, SampleContext, SampleModule};

/// y = weight·u + (1 − weight)·w, element by element; w is optional (0 when absent).
///
/// This paragraph is not in the summary.
#[derive(Component)]
#[component(name = "blend", finish = Self::finish)]
struct Blend {
    /// u, any shape
    #[input]
    input: Mat,
    /// w, the shape of u
    #[input(same_as = input)]
    other: Option<Mat>,
    /// y, the shape of u
    #[output(same_as = input)]
    output: Mat,
    /// the weight of u
    #[param(default = 0.5, min = 0, max = 1)]
    weight: f64,
    /// samples between two updates of y
    #[param(default = 1, min = 1, max = 100)]
    every: u32,
    /// how long the blend lasts
    #[param(unit = "s", above = 0)]
    _lasts: Option<f64>,
    /// `1 − weight`, set by `finish`.
    complement: f64,
    samples: u64,
}

impl Blend {
    /// Derived state, and a check across a parameter and an optional input.
    fn finish(&mut self, _: &mut Binder<'_>) -> Result<(), ModuleError> {
        if self.weight == 1.0 && self.other.is_some() {
            return Err(ModuleError::param(
                "weight",
                "1 ignores `other`: leave `other` out",
            ));
        }
        self.complement = 1.0 - self.weight;
        Ok(())
    }
}

impl SampleModule for Blend {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        self.samples += 1;
        if !(self.samples - 1).is_multiple_of(u64::from(self.every)) {
            return Ok(());
        }
        let u = self.input.snapshot();
        let w = match &self.other {
            Some(other) => other.snapshot(),
            None => CsMat::zeros("w", u.rows(), u.cols()),
        };
        let mut y = self.output.write();
        for r in 0..u.rows() {
            for c in 0..u.cols() {
                let value = self.weight * u.get(r, c)? + self.complement * w.get(r, c)?;
                y.set(r, c, value)?;
            }
        }
        Ok(())
    }
}

/// Every other kind of parameter: a matrix, a table, a string, a file name, a flag.
#[derive(Component)]
#[component(name = "holder", summary = "Holds what it is given.")]
struct Holder {
    /// one row per row of `gain`
    #[output(shape = (gain.nrows(), 1))]
    output: Mat,
    /// the gain
    #[param]
    gain: DMatrix<f64>,
    /// options, any keys
    #[param]
    options: Option<Params>,
    /// a label
    #[param(default = "plain")]
    label: String,
    /// where to write
    #[param]
    file: Option<PathBuf>,
    /// whether to say more
    #[param(default = false)]
    verbose: bool,
    /// the value of `final`, a Rust keyword
    #[param(default = vec![1.0, 2.0], default_doc = "[1, 2]")]
    r#final: Vec<f64>,
}

impl SampleModule for Holder {
    fn execute(&mut self, _: &SampleContext) -> RoutineResult {
        let mut y = self.output.write();
        for r in 0..self.gain.nrows() {
            y.set(r, 0, self.gain[(r, 0)])?;
        }
        Ok(())
    }
}

/// Optional CSMats whose shape and reading name a parameter called `n` (the generated code's
/// own names never shadow a field's).
#[derive(Component)]
#[component(name = "counted", summary = "n rows, optionally read and written.")]
#[allow(dead_code)] // built, never run
struct Counted {
    /// how many rows
    #[param(default = 3)]
    n: usize,
    /// a big count
    #[param(default = 0)]
    big: u64,
    /// read in state_update when n > 2
    #[input(state = n > 2, shape = (n, 1))]
    source: Option<Mat>,
    /// n × 1
    #[output(shape = (n, 1))]
    sink: Option<Mat>,
}

impl SampleModule for Counted {}

fn p(
    name: &'static str,
    kind: ParamKind,
    default: Option<&'static str>,
    doc: &'static str,
) -> ParamSpec {
    ParamSpec {
        name,
        kind,
        default,
        doc,
        unit: None,
        range: None,
    }
}

const BLEND: ComponentSpec = ComponentSpec {
    name: "blend",
    summary: "y = weight·u + (1 − weight)·w, element by element; w is optional (0 when absent).",
    params: &[
        ParamSpec::required("input", ParamKind::Input, "u, any shape"),
        ParamSpec::optional("other", ParamKind::Input, "none", "w, the shape of u"),
        ParamSpec::required("output", ParamKind::Output, "y, the shape of u"),
        ParamSpec::optional("weight", ParamKind::Number, "0.5", "the weight of u")
            .range("≥ 0 and ≤ 1"),
        ParamSpec::optional(
            "every",
            ParamKind::Number,
            "1",
            "samples between two updates of y",
        )
        .range("≥ 1 and ≤ 100"),
        ParamSpec::optional(
            "lasts",
            ParamKind::Number,
            "none",
            "how long the blend lasts",
        )
        .unit("s")
        .range("> 0"),
    ],
};

#[test]
fn the_spec_is_the_fields_in_order_with_their_docs_kinds_defaults_units_and_ranges() {
    assert_eq!(Blend::spec(), &BLEND);
    let holder = Holder::spec();
    assert_eq!(
        (holder.name, holder.summary),
        ("holder", "Holds what it is given.")
    );
    let expected = [
        p(
            "output",
            ParamKind::Output,
            None,
            "one row per row of `gain`",
        ),
        p("gain", ParamKind::Matrix, None, "the gain"),
        p(
            "options",
            ParamKind::Table,
            Some("none"),
            "options, any keys",
        ),
        p("label", ParamKind::Text, Some("plain"), "a label"),
        p("file", ParamKind::File, Some("none"), "where to write"),
        p(
            "verbose",
            ParamKind::Bool,
            Some("false"),
            "whether to say more",
        ),
        p(
            "final",
            ParamKind::Numbers,
            Some("[1, 2]"),
            "the value of `final`, a Rust keyword",
        ),
    ];
    assert_eq!(holder.params, expected);
}

fn library() -> Registry {
    let mut registry = Registry::empty();
    registry.add::<Blend>().add::<Holder>().add::<Counted>();
    registry
}

/// A runtime with the test library, a manual habitat `h` and the 2 × 1 CSMats `u` and `w`.
fn runtime() -> Runtime {
    let rt = Runtime::new("derive");
    rt.add_library(library());
    rt.create_habitat("h", HabitatOptions::rate(100.0).clock(Clock::Manual))
        .unwrap();
    rt.create_mat(CsMat::from_row_slice("u", 2, 1, &[1.0, 2.0]).unwrap())
        .unwrap();
    rt.create_mat(CsMat::from_row_slice("w", 2, 1, &[10.0, 20.0]).unwrap())
        .unwrap();
    rt
}

/// Why `type_name` with `params` is not installed (it must not be).
fn refusal(rt: &Runtime, type_name: &str, params: &Params) -> ModuleError {
    match rt.install_component("h", "m", type_name, params) {
        Ok(()) => panic!("{type_name} with {params:?} was installed"),
        Err(RuntimeError::Build { source, .. }) => source,
        Err(other) => panic!("expected the component's refusal, got {other}"),
    }
}

/// The parameter `err` refuses, and why.
fn refused(err: ModuleError) -> (String, String) {
    match err {
        ModuleError::Param { name, reason } => (name, reason),
        other => panic!("expected a parameter refusal, got {other:?}"),
    }
}

#[test]
fn an_optional_input_present_and_absent_and_the_finish_hook() {
    let rt = runtime();
    let with = Params::new()
        .with("input", "u")
        .with("other", "w")
        .with("output", "with")
        .with("weight", 0.25);
    rt.install_component("h", "with", "blend", &with).unwrap();
    let without = Params::new().with("input", "u").with("output", "without");
    rt.install_component("h", "without", "blend", &without)
        .unwrap();
    // The outputs follow the input's shape: created at install, 2 × 1.
    assert_eq!(rt.mat("with").shape(), (2, 1));
    let h = rt.habitat("h");
    h.start().unwrap();
    h.step().unwrap();
    // 0.25·u + 0.75·w (finish set the complement); 0.5·u + 0.5·0 without `other`.
    assert_eq!(rt.mat("with").read().matrix().as_slice(), [7.75, 15.5]);
    assert_eq!(rt.mat("without").read().matrix().as_slice(), [0.5, 1.0]);
    assert_eq!(h.stats().module_errors, 0);

    // The finish hook's refusal, naming the parameter.
    let err = refusal(&rt, "blend", &with.clone().with("weight", 1.0));
    assert_eq!(refused(err).0, "weight");
    // Without `other`, weight 1 is fine.
    let alone = without.with("weight", 1.0).with("output", "alone");
    rt.install_component("h", "alone", "blend", &alone).unwrap();
}

#[test]
fn a_csmat_used_as_both_input_and_output_is_refused() {
    let rt = runtime();
    let params = Params::new().with("input", "u").with("output", "u");
    let err = refusal(&rt, "blend", &params);
    assert!(
        matches!(&err, ModuleError::Failed(text) if text.contains("`u`") && text.contains("twice")),
        "{err:?}"
    );
    let params = Params::new()
        .with("input", "u")
        .with("other", "y")
        .with("output", "y");
    assert!(matches!(
        refusal(&rt, "blend", &params),
        ModuleError::Failed(_)
    ));
    // Nothing of the refused instances is left behind.
    rt.install_component(
        "h",
        "m",
        "blend",
        &Params::new().with("input", "u").with("output", "y"),
    )
    .unwrap();
}

#[test]
fn optional_csmats_may_name_a_parameter_called_n() {
    let rt = runtime();
    rt.install_component(
        "h",
        "c",
        "counted",
        &Params::new().with("sink", "s").with("n", 4.0),
    )
    .unwrap();
    assert_eq!(rt.mat("s").shape(), (4, 1));
    // 2^64 is one past u64::MAX: refused, with the maximum written exactly.
    let (name, reason) = refused(refusal(
        &rt,
        "counted",
        &Params::new().with("big", 18446744073709551616.0),
    ));
    assert_eq!(name, "big");
    assert!(
        reason.contains("from 0 to 18446744073709551615"),
        "{reason}"
    );
}

#[test]
fn integer_parameters_take_whole_numbers_in_range() {
    let rt = runtime();
    let base = Params::new().with("input", "u").with("output", "y");
    for (every, says) in [
        (2.5, "expected a whole number from 0 to 4294967295, got 2.5"),
        (-1.0, "expected a whole number from 0 to 4294967295, got -1"),
        (1e10, "got 10000000000"),
        (0.0, "expected a whole number from 1 to 100, got 0"),
        (101.0, "expected a whole number from 1 to 100, got 101"),
    ] {
        let (name, reason) = refused(refusal(&rt, "blend", &base.clone().with("every", every)));
        assert_eq!(name, "every");
        assert!(reason.contains(says), "every = {every}: {reason}");
    }
    let (name, reason) = refused(refusal(&rt, "blend", &base.clone().with("lasts", 0.0)));
    assert_eq!(
        (name.as_str(), reason.as_str()),
        ("lasts", "0 is not positive: expected > 0")
    );
    let (name, reason) = refused(refusal(
        &rt,
        "blend",
        &base.clone().with("weight", f64::NAN),
    ));
    assert_eq!(
        (name.as_str(), reason.as_str()),
        ("weight", "NaN is not a finite number")
    );
    rt.install_component("h", "m", "blend", &base.with("every", 3.0))
        .unwrap();
}

#[test]
fn every_kind_of_parameter_is_read() {
    let rt = runtime();
    let params = Params::new()
        .with("output", "y")
        .with("gain", DMatrix::from_row_slice(3, 1, &[1.0, 2.0, 3.0]))
        .with("options", Params::new().with("anything", 1.0))
        .with("file", "out.csv")
        .with("verbose", true)
        .with("final", 4.0);
    rt.install_component("h", "m", "holder", &params).unwrap();
    assert_eq!(rt.mat("y").shape(), (3, 1));
    let h = rt.habitat("h");
    h.start().unwrap();
    h.step().unwrap();
    assert_eq!(rt.mat("y").read().matrix().as_slice(), [1.0, 2.0, 3.0]);

    // Built directly, the fields hold the values (and the defaults).
    let mut mats = std::collections::BTreeMap::new();
    let mut lookup = |name: &str| {
        mats.entry(name.to_owned())
            .or_insert_with(|| Mat::placeholder(name))
            .clone()
    };
    let mut binder = Binder::detached("m", &mut lookup);
    let holder = Holder::build(&mut binder, &params.with("label", "fancy")).unwrap();
    assert_eq!(holder.label, "fancy");
    assert_eq!(holder.file.as_deref(), Some(Path::new("out.csv")));
    assert!(holder.verbose);
    assert_eq!(holder.r#final, [4.0]);
    assert!(holder.options.is_some_and(|o| o.has("anything")));
    let wrong = Params::new().with("output", "y").with("gain", "big");
    let (name, _) = refused(Holder::build(&mut binder, &wrong).err().unwrap());
    assert_eq!(name, "gain");
    let missing = Params::new().with("output", "y");
    let (name, reason) = refused(Holder::build(&mut binder, &missing).err().unwrap());
    assert_eq!((name.as_str(), reason.as_str()), ("gain", "missing"));
}

// ---- description files ----

const HABITAT: &str = r#"
[[habitat]]
name = "h"
rate = 100.0
clock = "manual"

[[mat]]
name = "u"
value = [1.0, 2.0]

[[mat]]
name = "w"
value = [10.0, 20.0]
"#;

/// The line and column (from 1) where `needle` last starts in `text` (the component is last).
fn at(text: &str, needle: &str) -> (usize, usize) {
    let offset = text
        .rfind(needle)
        .unwrap_or_else(|| panic!("`{needle}` not in the text"));
    let line = text[..offset].matches('\n').count() + 1;
    let column = offset - text[..offset].rfind('\n').map_or(0, |i| i + 1) + 1;
    (line, column)
}

/// The one problem of the description `text`, which must be at `needle` and say `says`.
fn problem(text: &str, needle: &str, says: &[&str]) -> Diagnostic {
    let found = match System::from_str("blend.toml", text, None, library()) {
        Ok(_) => panic!("loaded, but it is broken:\n{text}"),
        Err(SystemError::Invalid(d)) => d.0,
        Err(other) => panic!("expected diagnostics, got {other}"),
    };
    assert_eq!(found.len(), 1, "one problem expected: {found:#?}");
    let d = found.into_iter().next().unwrap();
    assert_eq!(d.location.file.as_path(), Path::new("blend.toml"));
    assert_eq!(
        (d.location.line, d.location.column),
        at(text, needle),
        "reported at the wrong place: {d}"
    );
    for s in says {
        assert!(d.to_string().contains(s), "`{d}` should say `{s}`");
    }
    d
}

fn blend_with(extra: &str) -> String {
    format!(
        "{HABITAT}
[[component]]
name = \"b\"
type = \"blend\"
habitat = \"h\"
input = \"u\"
output = \"y\"
{extra}
"
    )
}

#[test]
fn a_description_file_builds_it_with_and_without_the_optional_input() {
    let text = format!(
        "{HABITAT}
[[component]]
name = \"with\"
type = \"blend\"
habitat = \"h\"
input = \"u\"
other = \"w\"
output = \"y1\"
weight = 0.25

[[component]]
name = \"without\"
type = \"blend\"
habitat = \"h\"
input = \"u\"
output = \"y2\"
every = 2
"
    );
    let system = System::from_str("blend.toml", &text, None, library()).unwrap();
    let rt = system.runtime();
    let h = rt.habitat("h");
    h.start().unwrap();
    h.step().unwrap();
    assert_eq!(rt.mat("y1").read().matrix().as_slice(), [7.75, 15.5]);
    assert_eq!(rt.mat("y2").read().matrix().as_slice(), [0.5, 1.0]);
    assert_eq!(h.stats().module_errors, 0);
}

#[test]
fn an_unknown_key_is_reported_where_it_is_written() {
    let text = blend_with("wieght = 0.3");
    problem(
        &text,
        "wieght",
        &["no parameter `wieght`", "did you mean `weight`?"],
    );
}

#[test]
fn a_value_of_the_wrong_type_is_reported_where_it_is_written() {
    let text = blend_with("weight = \"half\"");
    problem(
        &text,
        "\"half\"",
        &["parameter `weight` is a string", "expected a number"],
    );
}

#[test]
fn a_value_out_of_range_is_reported_where_it_is_written() {
    let text = blend_with("weight = 1.5");
    problem(
        &text,
        "1.5",
        &[
            "parameter `weight`",
            "1.5 is out of range: expected ≥ 0 and ≤ 1",
        ],
    );
    let text = blend_with("every = 2.5");
    problem(
        &text,
        "2.5",
        &["parameter `every`", "expected a whole number"],
    );
    // A refusal by the finish hook points at the parameter it names too.
    let text = blend_with("other = \"w\"\nweight = 1.0");
    problem(&text, "1.0", &["parameter `weight`", "leave `other` out"]);
}
