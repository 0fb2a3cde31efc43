//! A component struct as the derive understands it: every field's role (input, inputs,
//! output, parameter, state) with its options, checked, so that code generation
//! (`expand.rs`) never meets a malformed declaration. A field's attributes are read in
//! `fields.rs`, its type recognised in `types.rs`.

use proc_macro2::Span;
use syn::spanned::Spanned as _;
use syn::{Data, DeriveInput, Expr, Fields, Ident, LitStr, Type};

use crate::types::first_paragraph;

/// The whole component.
pub struct Component {
    /// The struct.
    pub ident: Ident,
    /// The type name description files use.
    pub name: String,
    /// The spec's summary.
    pub summary: String,
    /// `#[component(finish = path)]`: called with the built struct and the binder.
    pub finish: Option<Expr>,
    /// Every field, in declaration order (the spec lists parameters in this order).
    pub fields: Vec<Field>,
}

/// One field.
pub struct Field {
    /// Its name in Rust.
    pub ident: Ident,
    /// Its key in a description file (the field's name unless `key = "..."`).
    pub key: String,
    /// Its doc comment, joined into one line.
    pub doc: String,
    /// What it is.
    pub role: Role,
    /// Its Rust type.
    pub ty: Type,
    /// Where it is declared (for errors).
    pub span: Span,
}

/// What a field is.
pub enum Role {
    /// `#[input]`: a CSMat it reads (`Mat`, or `Option<Mat>` for an optional one).
    Input {
        optional: bool,
        state: Reading,
        shape: Shape,
    },
    /// `#[inputs]`: CSMats it reads (`Vec<Mat>`), at least one.
    Inputs { same_shape: bool },
    /// `#[output]`: a CSMat it writes (`Mat`, or `Option<Mat>` for an optional one).
    Output { optional: bool, shape: Shape },
    /// `#[param]`: a value from the description file.
    Param(Param),
    /// Anything unmarked or `#[state]`: the module's own state, `Default::default()` unless
    /// `#[state(init = EXPR)]`.
    State { init: Option<Expr> },
}

/// When an input is read.
pub enum Reading {
    /// In `execute` (direct feedthrough): `#[input]`.
    Execute,
    /// Only in `state_update` (closes loops): `#[input(state)]`.
    State,
    /// In `state_update` when the expression is true, else in `execute`:
    /// `#[input(state = EXPR)]` (a system whose feedthrough depends on its parameters).
    StateIf(Expr),
}

/// The shape a CSMat is declared with.
pub enum Shape {
    /// Whatever it is.
    Any,
    /// `shape = EXPR` (a `(rows, cols)`; may name parameters and earlier CSMats).
    Expr(Expr),
    /// `same_as = FIELD`: the shape of an earlier CSMat field (`first`: of an `#[inputs]`
    /// field, its first CSMat's; set by the checks once the field is known).
    SameAs { field: Ident, first: bool },
    /// `like = EXPR`: an output created from a template CSMat (field names and units).
    Like(Expr),
}

/// A parameter field.
pub struct Param {
    /// The value type.
    pub ty: ParamType,
    /// `Option<T>`: optional without a default.
    pub optional: bool,
    /// `default = EXPR`.
    pub default: Option<Expr>,
    /// How the spec shows the default.
    pub default_doc: Option<String>,
    /// `unit = "..."`.
    pub unit: Option<String>,
    /// `min`, `max`, `above`, `below`.
    pub range: Range,
    /// `finite = false`: infinities and NaN are accepted (the component checks them).
    pub any_number: bool,
}

/// Bounds, as literals.
#[derive(Default)]
pub struct Range {
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub above: Option<f64>,
    pub below: Option<f64>,
}

impl Range {
    pub(crate) fn is_empty(&self) -> bool {
        self.min.is_none() && self.max.is_none() && self.above.is_none() && self.below.is_none()
    }

    /// The range in words (the same text as `support::Range::words` gives at run time).
    pub fn words(&self) -> Option<String> {
        if self.is_empty() {
            return None;
        }
        let parts: Vec<String> = [
            self.min.map(|m| format!("≥ {m}")),
            self.above.map(|m| format!("> {m}")),
            self.max.map(|m| format!("≤ {m}")),
            self.below.map(|m| format!("< {m}")),
        ]
        .into_iter()
        .flatten()
        .collect();
        Some(parts.join(" and "))
    }
}

/// The types a parameter field may have.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamType {
    /// `f64`.
    Number,
    /// An integer type: a whole number in its range.
    Whole,
    /// `Vec<f64>`.
    Numbers,
    /// `DMatrix<f64>`.
    Matrix,
    /// `String`.
    Text,
    /// `PathBuf`.
    File,
    /// `bool`.
    Bool,
    /// `Params`: a table of sub-parameters.
    Table,
    /// `Mat` with `tunable`: a 1 × 1 parameter CSMat `<module>.<key>` set from a number.
    Tunable,
    /// `Mat` with `tunable`, given as a list: a column parameter CSMat.
    TunableColumn,
}

impl ParamType {
    /// The runtime's `ParamKind` variant.
    pub fn kind(self) -> &'static str {
        match self {
            ParamType::Number | ParamType::Whole | ParamType::Tunable => "Number",
            ParamType::Numbers | ParamType::TunableColumn => "Numbers",
            ParamType::Matrix => "Matrix",
            ParamType::Text => "Text",
            ParamType::File => "File",
            ParamType::Bool => "Bool",
            ParamType::Table => "Table",
        }
    }

    /// Whether a range applies to it.
    pub fn numeric(self) -> bool {
        !matches!(
            self,
            ParamType::Text | ParamType::File | ParamType::Bool | ParamType::Table
        )
    }
}

pub(crate) const PARAM_TYPES: &str = "f64, an integer type, Vec<f64>, DMatrix<f64>, String, PathBuf, \
                           bool, Params (a table), or Mat with `tunable`; or Option of one of \
                           these";

impl Component {
    /// Reads a struct deriving `Component`.
    pub fn parse(input: &DeriveInput) -> syn::Result<Self> {
        if !input.generics.params.is_empty() {
            return Err(syn::Error::new(
                input.generics.span(),
                "#[derive(Component)] does not take generic structs: a description file names \
                 one concrete type; register each instance type of its own",
            ));
        }
        let Data::Struct(data) = &input.data else {
            return Err(syn::Error::new(
                input.ident.span(),
                "#[derive(Component)] takes a struct with named fields",
            ));
        };
        let Fields::Named(named) = &data.fields else {
            return Err(syn::Error::new(
                input.ident.span(),
                "#[derive(Component)] takes a struct with named fields",
            ));
        };
        let mut name = None;
        let mut summary = None;
        let mut finish = None;
        for attr in input
            .attrs
            .iter()
            .filter(|a| a.path().is_ident("component"))
        {
            attr.parse_nested_meta(|meta| {
                let key = meta.path.get_ident().map(Ident::to_string);
                match key.as_deref() {
                    Some("name") => name = Some(meta.value()?.parse::<LitStr>()?.value()),
                    Some("summary") => summary = Some(meta.value()?.parse::<LitStr>()?.value()),
                    Some("finish") => finish = Some(meta.value()?.parse::<Expr>()?),
                    _ => {
                        return Err(meta.error(
                            "unknown #[component] option; it takes `name = \"...\"`, \
                             `summary = \"...\"` and `finish = path`",
                        ));
                    }
                }
                Ok(())
            })?;
        }
        let Some(name) = name else {
            return Err(syn::Error::new(
                input.ident.span(),
                "#[derive(Component)] needs the type's name for description files: \
                 #[component(name = \"my_filter\")]",
            ));
        };
        check_type_name(&name, input.ident.span())?;
        let summary = summary.unwrap_or_else(|| first_paragraph(&input.attrs));
        if summary.is_empty() {
            return Err(syn::Error::new(
                input.ident.span(),
                "a component needs a summary: a doc comment on the struct, or \
                 #[component(summary = \"...\")]",
            ));
        }
        let mut fields = Vec::new();
        for field in &named.named {
            fields.push(Field::parse(field)?);
        }
        check_references(&mut fields)?;
        Ok(Self {
            ident: input.ident.clone(),
            name,
            summary,
            finish,
            fields,
        })
    }
}

fn check_type_name(name: &str, span: Span) -> syn::Result<()> {
    let ok = !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if ok {
        Ok(())
    } else {
        Err(syn::Error::new(
            span,
            format!(
                "component name `{name}`: use letters, digits, `_` and `-` (it is written in \
                 description files as type = \"{name}\")"
            ),
        ))
    }
}

/// `same_as` must name an earlier CSMat field (marking the first of an `#[inputs]` field);
/// keys must be unique.
fn check_references(fields: &mut [Field]) -> syn::Result<()> {
    for i in 0..fields.len() {
        let (earlier, rest) = fields.split_at_mut(i);
        let (field, later) = rest.split_first_mut().expect("i < fields.len()");
        if field.is_described()
            && earlier
                .iter()
                .any(|f| f.is_described() && f.key == field.key)
        {
            return Err(syn::Error::new(
                field.span,
                format!("two fields have the key `{}`", field.key),
            ));
        }
        let (same_as, first) = match &mut field.role {
            Role::Input {
                shape: Shape::SameAs { field, first },
                ..
            }
            | Role::Output {
                shape: Shape::SameAs { field, first },
                ..
            } => (field, first),
            _ => continue,
        };
        let problem = match earlier
            .iter()
            .find(|f| f.ident == *same_as)
            .map(|f| &f.role)
        {
            Some(Role::Input {
                optional: false, ..
            })
            | Some(Role::Output {
                optional: false, ..
            }) => continue,
            Some(Role::Inputs { .. }) => {
                *first = true;
                continue;
            }
            Some(_) => "names a field that is not a CSMat it always has",
            None if later.iter().any(|f| f.ident == *same_as) => {
                "names a field declared after it (CSMats are declared in field order: move it \
                 above)"
            }
            None => "names no field of this struct",
        };
        return Err(syn::Error::new(
            same_as.span(),
            format!(
                "field `{}`: `same_as = {same_as}` {problem}; it takes an earlier #[input] or \
                 #[output] field of type Mat, or #[inputs] (its first CSMat)",
                field.ident
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(code: &str) -> syn::Result<Component> {
        Component::parse(&syn::parse_str(code).expect("valid Rust"))
    }

    fn error(code: &str) -> String {
        match parse(code) {
            Ok(_) => panic!("expected an error for {code}"),
            Err(err) => err.to_string(),
        }
    }

    #[test]
    fn fields_get_their_roles_keys_docs_and_types() {
        let c = parse(
            r#"
            /// Sums things.
            ///
            /// More words, not in the summary.
            #[component(name = "adder")]
            struct Adder {
                /// the terms
                #[inputs(same_shape)] terms: Vec<Mat>,
                /// the sum
                #[output(same_as = terms_first)] out: Mat,
                /// a gain
                #[param(tunable, default = 2.0, unit = "1/s", min = 0.0)] k: Mat,
                /// the count
                #[param(key = "n")] count: Option<u32>,
                scratch: Vec<f64>,
            }"#,
        );
        // `same_as` must name an earlier CSMat field: `terms_first` is none.
        assert!(c.is_err());
        let c = parse(
            r#"
            /// Sums things.
            ///
            /// More words, not in the summary.
            #[component(name = "adder")]
            struct Adder {
                /// the first
                #[input] first: Mat,
                /// the sum
                #[output(same_as = first)] out: Mat,
                /// a gain
                #[param(tunable, default = 2.0, unit = "1/s", min = 0.0)] k: Mat,
                /// the count
                #[param(key = "n")] count: Option<u32>,
                scratch: Vec<f64>,
            }"#,
        )
        .unwrap();
        assert_eq!(
            (c.name.as_str(), c.summary.as_str()),
            ("adder", "Sums things.")
        );
        let keys: Vec<&str> = c.fields.iter().map(|f| f.key.as_str()).collect();
        assert_eq!(keys, ["first", "out", "k", "n", "scratch"]);
        let Role::Param(k) = &c.fields[2].role else {
            panic!("k is a parameter")
        };
        assert_eq!(k.ty, ParamType::Tunable);
        assert_eq!(k.range.words().as_deref(), Some("≥ 0"));
        assert_eq!(k.unit.as_deref(), Some("1/s"));
        let Role::Param(n) = &c.fields[3].role else {
            panic!("n is a parameter")
        };
        assert!(n.optional && n.ty == ParamType::Whole);
        assert!(matches!(c.fields[4].role, Role::State { init: None }));
    }

    #[test]
    fn optional_outputs_conditional_state_inputs_columns_and_underscored_keys() {
        let c = parse(
            r#"
            /// x
            #[component(name = "x")]
            struct X {
                /// terms
                #[inputs] terms: Vec<Mat>,
                /// u
                #[input(state = !feedthrough, same_as = terms)] u: Mat,
                /// y
                #[output(same_as = terms)] y: Mat,
                /// v
                #[output(shape = (2, 1))] v: Option<Mat>,
                /// bounds
                #[param(tunable, column, finite = false)] lower: Mat,
                /// rows
                #[param(min = 1)] _rows: Option<usize>,
                /// the value from then on
                #[param] r#final: Vec<f64>,
            }"#,
        )
        .unwrap();
        let keys: Vec<&str> = c.fields.iter().map(|f| f.key.as_str()).collect();
        assert_eq!(keys, ["terms", "u", "y", "v", "lower", "rows", "final"]);
        assert!(matches!(
            &c.fields[1].role,
            Role::Input {
                state: Reading::StateIf(_),
                shape: Shape::SameAs { first: true, .. },
                ..
            }
        ));
        assert!(matches!(
            &c.fields[2].role,
            Role::Output {
                optional: false,
                shape: Shape::SameAs { first: true, .. }
            }
        ));
        assert!(matches!(
            &c.fields[3].role,
            Role::Output { optional: true, .. }
        ));
        let Role::Param(lower) = &c.fields[4].role else {
            panic!("lower is a parameter")
        };
        assert_eq!(lower.ty, ParamType::TunableColumn);
        assert!(lower.any_number);
    }

    #[test]
    fn options_that_do_not_fit_the_type_are_refused() {
        let cases = [
            (
                "/// x\n#[component(name = \"x\")] struct X { /// k\n #[param(column)] k: Vec<f64> }",
                "`column` is for a `tunable` Mat",
            ),
            (
                "/// x\n#[component(name = \"x\")] struct X { /// n\n #[param(finite = false)] n: u32 }",
                "`finite = false` applies to f64",
            ),
            (
                "/// x\n#[component(name = \"x\")] struct X { /// s\n #[param(finite = false)] s: String }",
                "`finite = false` applies to f64",
            ),
            (
                "/// x\n#[component(name = \"x\")] struct X { /// v\n #[output] v: Option<Mat>, /// w\n #[output(same_as = v)] w: Mat }",
                "`same_as = v` names a field that is not a CSMat it always has",
            ),
            (
                "/// x\n#[component(name = \"x\")] struct X { /// w\n #[output(same_as = u)] w: Mat, /// u\n #[input] u: Mat }",
                "`same_as = u` names a field declared after it",
            ),
            (
                "/// x\n#[component(name = \"x\")] struct X { /// w\n #[output(same_as = q)] w: Mat }",
                "`same_as = q` names no field of this struct",
            ),
            (
                "/// x\n#[component(name = \"x\")] struct X { /// v\n #[output] v: Vec<Mat> }",
                "#[output] does not take `Vec<Mat>`; it takes Mat, or Option<Mat>",
            ),
        ];
        for (code, expected) in cases {
            let err = error(code);
            assert!(err.contains(expected), "{code}: {err}");
        }
    }

    #[test]
    fn unsupported_types_name_the_field_and_what_is_taken() {
        let err = error(
            r#"/// x
            #[component(name = "x")]
            struct X { /// a map
            #[param] table: HashMap<String, f64> }"#,
        );
        assert!(err.contains("field `table`"), "{err}");
        assert!(err.contains("HashMap<String,f64>"), "{err}");
        assert!(err.contains("Vec<f64>"), "{err}");
        let err = error(
            r#"/// x
            #[component(name = "x")]
            struct X { /// in
            #[input] u: f64 }"#,
        );
        assert!(
            err.contains("field `u`: #[input] does not take `f64`"),
            "{err}"
        );
    }

    #[test]
    fn malformed_declarations_are_refused_with_what_to_write() {
        let cases = [
            ("struct X { }", "needs the type's name"),
            (
                "/// x\n#[component(name = \"x\")] struct X { /// p\n #[param] __params: f64 }",
                "names beginning with `__` are the derive's own",
            ),
            ("#[component(name = \"x\")] struct X {}", "needs a summary"),
            (
                "/// x\n#[component(name = \"a b\")] struct X {}",
                "letters, digits",
            ),
            (
                "/// x\n#[component(name = \"x\", colour = 1)] struct X {}",
                "unknown #[component] option",
            ),
            (
                "/// x\n#[component(name = \"x\")] struct X { #[input] u: Mat }",
                "needs a doc comment",
            ),
            (
                "/// x\n#[component(name = \"x\")] struct X { /// u\n #[input] #[output] u: Mat }",
                "two roles",
            ),
            (
                "/// x\n#[component(name = \"x\")] struct X { /// k\n #[param(default = 1.0)] k: Option<f64> }",
                "not both",
            ),
            (
                "/// x\n#[component(name = \"x\")] struct X { /// k\n #[param(min = 0.0)] k: String }",
                "numbers only",
            ),
            (
                "/// x\n#[component(name = \"x\")] struct X { /// k\n #[param(min = a)] k: f64 }",
                "number literal",
            ),
            (
                "/// x\n#[component(name = \"x\")] struct X<T> { t: T }",
                "generic",
            ),
            (
                "/// x\n#[component(name = \"x\")] struct X(f64);",
                "named fields",
            ),
            (
                "/// x\n#[component(name = \"x\")] struct X { /// a\n #[param] a: f64, /// b\n #[param(key = \"a\")] b: f64 }",
                "two fields have the key `a`",
            ),
        ];
        for (code, expected) in cases {
            let err = error(code);
            assert!(err.contains(expected), "{code}: {err}");
        }
    }
}
