//! `#[derive(Component)]` for `ndds-runtime`: ControlShell's Component Editor as a derive.
//! A component's inputs, outputs and parameters are declared once, on its struct's fields; the
//! derive generates its `ComponentSpec` (what description files are checked against and the
//! reference docs and the studio's palette show), its factory from a description file's table
//! (with the built-ins' diagnostics: unknown key, wrong type, out of range, each at the key's
//! file:line:column) and its binding to CSMats. The author writes only the routines
//! (`impl SampleModule`).
//!
//! Use it through `ndds_runtime::Component` (re-exported there); the generated code names
//! `::ndds_runtime`.
//!
//! # Layout
//! - `model.rs`: the struct as the derive understands it (the component, its fields' roles),
//!   and the checks across fields;
//! - `fields.rs`: one field's role attribute and options, checked against its type;
//! - `types.rs`: what a field's Rust type is (`Mat`, `Option<Mat>`, `Vec<Mat>`, a parameter
//!   type), and doc comments as text. Every compile error the derive gives is made in these
//!   three and names the field;
//! - `expand.rs`: the generated `impl ndds_runtime::Component`.

use proc_macro::TokenStream;

mod expand;
mod fields;
mod model;
mod types;

/// Derives `ndds_runtime::Component`: the component's spec and factory from its fields.
///
/// On the struct:
///
/// | attribute | meaning |
/// |---|---|
/// | `#[component(name = "NAME")]` | the type name description files give (`type = "NAME"`); required |
/// | `#[component(summary = "...")]` | the spec's summary; default: the doc comment's first paragraph |
/// | `#[component(finish = PATH)]` | `fn(&mut Self, &mut Binder<'_>) -> Result<(), ModuleError>`, called once the struct is built (checks across parameters and CSMats, CSMats of its own) |
///
/// On each field (its doc comment is the parameter's line in the docs; required on every
/// field that is a key of the table):
///
/// | attribute | field type | description file gives | kind |
/// |---|---|---|---|
/// | `#[input]` | `Mat` (`Option<Mat>`: optional) | the name of a CSMat it reads in `execute` | reads CSMat |
/// | `#[input(state)]` | as above | a CSMat read only in `state_update` (closes loops) | reads CSMat |
/// | `#[input(state = EXPR)]` | as above | read in `state_update` when `EXPR` is true, else in `execute` (feedthrough that depends on parameters) | reads CSMat |
/// | `#[inputs]` | `Vec<Mat>` | a list of CSMat names (at least one) | reads CSMats |
/// | `#[output]` | `Mat` (`Option<Mat>`: optional) | the name of a CSMat it writes | writes CSMat |
/// | `#[param]` | `f64`, an integer type, `Vec<f64>`, `DMatrix<f64>`, `String`, `PathBuf`, `bool`, `Params`; `Option<_>` of one | a value | number, numbers, matrix, string, file name, bool, table |
/// | `#[param(tunable)]` | `Mat` | a number (a list when the default is one, or with `column`) | the 1 × 1 (n × 1) parameter CSMat `<module>.<key>`, changed while it runs |
/// | `#[state]` or none | anything with `Default` | nothing: the module's own state | — |
///
/// Options:
/// - inputs and outputs: `shape = (ROWS, COLS)` (an expression), `same_as = FIELD` (an
///   earlier CSMat's shape, or the first CSMat's of an `#[inputs]` field; an output then
///   follows its input's shape once known); outputs: `like = TEMPLATE` (a `CsMat` with field
///   names and units, created unless it exists; its name is the output's once bound);
///   `#[inputs(same_shape)]`: all of the first's shape;
/// - parameters: `default = EXPR` (absent means required, unless `Option`; an integer
///   parameter's default is typed by the field), `default_doc = "..."` (how docs show it),
///   `unit = "s"`, `min`, `max` (inclusive), `above`, `below` (exclusive) as number literals,
///   checked on every number of the value; `finite = false`: infinities and NaN accepted (the
///   component checks them, e.g. an infinite bound); `column` with `tunable`: given as a list
///   (one row per value) even without a default;
/// - any described field: `key = "..."` (the table's key, when it is not the field's name:
///   `final` is a Rust keyword). Without it the key is the field's name without `r#` or a
///   leading `_`: `_rows` is the key `rows`, for a parameter that only the factory reads
///   (no routine does, so Rust would call the field dead);
/// - `#[state(init = EXPR)]`: the state's first value.
///
/// The factory reads every parameter first, in field order (so a `default` may name an
/// earlier parameter), then declares the CSMats and initialises the state fields, in field
/// order again: a `shape`, `like`, `state = EXPR` or `init` expression may name every
/// parameter and every earlier CSMat or state field (a tunable parameter is its `Mat`, once
/// declared), and may use `?` on a `Result<_, ModuleError>`. A state field placed before the CSMats can so hold what their
/// shapes come from (a model, columns of one length); it is not in the spec, so its place
/// changes no parameter's order.
///
/// Numbers are refused when not finite (unless `finite = false`); integers when not whole or
/// out of their type's range; a CSMat both read and written by the module is refused. Every
/// refusal is `ModuleError::Param` naming the key (or, for the CSMat used twice,
/// `ModuleError::Failed`): "−1 is negative: expected ≥ 0", "0 is not positive: expected > 0",
/// "2 is out of range: expected ≤ 1", "expected a whole number from 1 to 10, got 0".
///
/// A field of a type the role does not take is a compile error naming the field (the
/// `trybuild` cases in `ndds-runtime/tests/ui/` hold each error's exact text):
///
/// ```text
/// error: field `table`: #[param] does not take `HashMap<String,f64>`; it takes f64, an
///        integer type, Vec<f64>, DMatrix<f64>, String, PathBuf, bool, Params (a table), or
///        Mat with `tunable`; or Option of one of these
/// ```
#[proc_macro_derive(Component, attributes(component, input, inputs, output, param, state))]
pub fn derive_component(input: TokenStream) -> TokenStream {
    let input = syn::parse_macro_input!(input as syn::DeriveInput);
    match model::Component::parse(&input) {
        Ok(component) => expand::expand(&component).into(),
        Err(err) => err.to_compile_error().into(),
    }
}
