//! The code a checked [`Component`] generates: `impl ndds_runtime::Component` with the spec
//! (a `const`) and the factory.
//!
//! The factory works in two phases, so that every parameter is refused before any CSMat is
//! declared (a refused instance leaves nothing behind in the linking database):
//!
//! 1. every parameter value and CSMat name is read from the table, in field order, into a
//!    local named after its field (CSMat names into `__name_FIELD`); ranges are checked; a
//!    CSMat both read and written is refused;
//! 2. in field order again, CSMats are declared (inputs, outputs, tunable parameters) and
//!    state fields initialised, each into a local named after its field, so that a `shape`,
//!    `like` or `init` expression may name parameters and earlier CSMats.
//!
//! Then the struct is made from the locals and `finish`, if given, runs on it.

use proc_macro2::TokenStream;
use quote::{format_ident, quote};
use syn::Expr;

use crate::model::{Component, Field, Param, ParamType, Reading, Role, Shape};

/// The `impl` for `c`.
pub fn expand(c: &Component) -> TokenStream {
    let ident = &c.ident;
    let spec = spec(c);
    let build = build(c);
    quote! {
        impl ::ndds_runtime::Component for #ident {
            fn spec() -> &'static ::ndds_runtime::ComponentSpec {
                const SPEC: ::ndds_runtime::ComponentSpec = #spec;
                &SPEC
            }

            #[allow(clippy::redundant_clone, clippy::useless_conversion, unused_variables)]
            fn build(
                __binder: &mut ::ndds_runtime::Binder<'_>,
                __params: &::ndds_runtime::Params,
            ) -> ::core::result::Result<Self, ::ndds_runtime::ModuleError> {
                #build
            }
        }
    }
}

fn spec(c: &Component) -> TokenStream {
    let name = &c.name;
    let summary = &c.summary;
    let params = c.fields.iter().filter_map(param_spec);
    quote! {
        ::ndds_runtime::ComponentSpec {
            name: #name,
            summary: #summary,
            params: &[#(#params),*],
        }
    }
}

fn some(text: Option<&str>) -> TokenStream {
    match text {
        Some(t) => quote!(::core::option::Option::Some(#t)),
        None => quote!(::core::option::Option::None),
    }
}

fn param_spec(field: &Field) -> Option<TokenStream> {
    let (kind, default, unit, range) = match &field.role {
        Role::State { .. } => return None,
        Role::Input { optional, .. } => ("Input", optional.then(|| "none".to_owned()), None, None),
        Role::Inputs { .. } => ("Inputs", None, None, None),
        Role::Output { optional, .. } => {
            ("Output", optional.then(|| "none".to_owned()), None, None)
        }
        Role::Param(p) => (
            p.ty.kind(),
            default_text(p),
            p.unit.clone(),
            p.range.words(),
        ),
    };
    let kind = format_ident!("{kind}");
    let name = &field.key;
    let doc = &field.doc;
    let default = some(default.as_deref());
    let unit = some(unit.as_deref());
    let range = some(range.as_deref());
    Some(quote! {
        ::ndds_runtime::ParamSpec {
            name: #name,
            kind: ::ndds_runtime::ParamKind::#kind,
            default: #default,
            doc: #doc,
            unit: #unit,
            range: #range,
        }
    })
}

/// How the spec shows a parameter's default: `default_doc`, else the default expression
/// (`1.0` as `1`, a string literal as its text), else `none` for an `Option`.
fn default_text(p: &Param) -> Option<String> {
    if let Some(doc) = &p.default_doc {
        return Some(doc.clone());
    }
    match &p.default {
        Some(expr) => Some(expr_text(expr)),
        None if p.optional => Some("none".to_owned()),
        None => None,
    }
}

fn expr_text(expr: &Expr) -> String {
    if let Expr::Lit(syn::ExprLit { lit, .. }) = expr {
        match lit {
            syn::Lit::Str(s) => return s.value(),
            // `1u64` as 1, `0.5_f64` as 0.5.
            syn::Lit::Int(i) => return i.base10_digits().to_owned(),
            syn::Lit::Float(f) => {
                if let Ok(x) = f.base10_parse::<f64>() {
                    return format!("{x}");
                }
            }
            _ => {}
        }
    }
    let text = quote!(#expr).to_string().replace(' ', "");
    match text.parse::<f64>() {
        Ok(x) => format!("{x}"),
        Err(_) => text,
    }
}

fn mat_name(field: &Field) -> syn::Ident {
    format_ident!("__name_{}", field.ident)
}

fn build(c: &Component) -> TokenStream {
    let read = c.fields.iter().map(read_phase);
    let distinct = distinct(&c.fields);
    let declare = c.fields.iter().map(declare_phase);
    let idents = c.fields.iter().map(|f| &f.ident);
    let finish = c
        .finish
        .as_ref()
        .map(|f| quote!((#f)(&mut __this, __binder)?;));
    quote! {
        use ::ndds_runtime::component::support as __support;
        #(#read)*
        #distinct
        #(#declare)*
        #[allow(unused_mut)]
        let mut __this = Self { #(#idents),* };
        #finish
        ::core::result::Result::Ok(__this)
    }
}

/// Phase 1: the field's value or CSMat name(s) from the table.
fn read_phase(field: &Field) -> TokenStream {
    let key = &field.key;
    let ident = &field.ident;
    match &field.role {
        Role::State { .. } => quote!(),
        Role::Input { optional: true, .. } | Role::Output { optional: true, .. } => {
            let name = mat_name(field);
            quote!(let #name: ::core::option::Option<::std::string::String> =
                __support::optional(__params, #key)?;)
        }
        Role::Input { .. } | Role::Output { .. } => {
            let name = mat_name(field);
            quote!(let #name: ::std::string::String = __support::mat_name(__params, #key)?;)
        }
        Role::Inputs { .. } => {
            let name = mat_name(field);
            quote!(let #name: ::std::vec::Vec<::std::string::String> =
                __support::mat_names(__params, #key)?;)
        }
        Role::Param(p) => {
            let (local, ty) = match p.ty {
                ParamType::Tunable => (format_ident!("__value_{ident}"), quote!(f64)),
                ParamType::TunableColumn => (
                    format_ident!("__value_{ident}"),
                    quote!(::std::vec::Vec<f64>),
                ),
                _ => {
                    let ty = &field.ty;
                    (ident.clone(), quote!(#ty))
                }
            };
            let value = param_value(p, key, &ty);
            let check = range_check(p, key, &local);
            quote! {
                let #local: #ty = #value;
                #check
            }
        }
    }
}

/// The value of the parameter `key` as `ty`; with `finite = false` read through
/// `support::NonFinite`, which accepts infinities and NaN.
fn param_value(p: &Param, key: &str, ty: &TokenStream) -> TokenStream {
    let (read, unwrap) = if p.any_number {
        (quote!(__support::NonFinite<#ty>), quote!(.0))
    } else {
        (ty.clone(), quote!())
    };
    if p.optional {
        return if p.any_number {
            quote!(__support::optional::<__support::NonFinite<_>>(__params, #key)?
                .map(|__value| __value.0))
        } else {
            quote!(__support::optional(__params, #key)?)
        };
    }
    // An integer literal has no `Into<u64>` (it would fall back to i32): an integer default
    // is typed by the field alone.
    let default = p.default.as_ref().map(|default| match p.ty {
        ParamType::Whole => quote!(#default),
        _ => quote!(::core::convert::Into::<#ty>::into(#default)),
    });
    match default {
        Some(default) => quote! {
            match __support::optional::<#read>(__params, #key)? {
                ::core::option::Option::Some(value) => value #unwrap,
                ::core::option::Option::None => #default,
            }
        },
        None => quote!(__support::required::<#read>(__params, #key)? #unwrap),
    }
}

fn range_check(p: &Param, key: &str, local: &syn::Ident) -> TokenStream {
    if p.range.words().is_none() {
        return quote!();
    }
    let bound = |b: Option<f64>| match b {
        Some(x) => quote!(::core::option::Option::Some(#x)),
        None => quote!(::core::option::Option::None),
    };
    let (min, max, above, below) = (
        bound(p.range.min),
        bound(p.range.max),
        bound(p.range.above),
        bound(p.range.below),
    );
    quote! {
        __support::Range { min: #min, max: #max, above: #above, below: #below }
            .check(#key, &#local)?;
    }
}

/// A CSMat the module writes may be neither read nor written twice by it.
fn distinct(fields: &[Field]) -> TokenStream {
    let mut inputs = Vec::new();
    let mut outputs = Vec::new();
    for field in fields {
        let name = mat_name(field);
        match &field.role {
            Role::Input { optional: true, .. } => {
                inputs.push(
                    quote!(if let ::core::option::Option::Some(__mat_name) = &#name {
                        __inputs.push(__mat_name.as_str());
                    }),
                );
            }
            Role::Input { .. } => inputs.push(quote!(__inputs.push(#name.as_str());)),
            Role::Inputs { .. } => {
                inputs.push(
                    quote!(__inputs.extend(#name.iter().map(::std::string::String::as_str));),
                );
            }
            Role::Output { optional: true, .. } => {
                outputs.push(
                    quote!(if let ::core::option::Option::Some(__mat_name) = &#name {
                        __outputs.push(__mat_name.as_str());
                    }),
                );
            }
            Role::Output { .. } => outputs.push(quote!(__outputs.push(#name.as_str());)),
            _ => {}
        }
    }
    if outputs.is_empty() {
        return quote!();
    }
    quote! {
        {
            #[allow(unused_mut)]
            let mut __inputs: ::std::vec::Vec<&str> = ::std::vec::Vec::new();
            #(#inputs)*
            let mut __outputs: ::std::vec::Vec<&str> = ::std::vec::Vec::new();
            #(#outputs)*
            __support::distinct(&__inputs, &__outputs)?;
        }
    }
}

fn shape(shape: &Shape) -> TokenStream {
    match shape {
        Shape::Any | Shape::Like(_) => quote!(::ndds_runtime::Shape::Any),
        Shape::Expr(e) => quote!(::ndds_runtime::Shape::from(#e)),
        Shape::SameAs { .. } => {
            let other = same_as(shape);
            quote!(__support::shape_of(#other))
        }
    }
}

/// The CSMat a `same_as` names: the field, or the first of an `#[inputs]` field.
fn same_as(shape: &Shape) -> TokenStream {
    match shape {
        Shape::SameAs { field, first: true } => quote!(&#field[0]),
        Shape::SameAs { field, .. } => quote!(&#field),
        _ => quote!(),
    }
}

/// `let IDENT = DECLARE(name)` for a CSMat field; for an optional one, only when its name
/// was given (`None` otherwise).
fn bind(
    ident: &syn::Ident,
    name: &syn::Ident,
    optional: bool,
    declare: impl Fn(TokenStream) -> TokenStream,
) -> TokenStream {
    if optional {
        let declare = declare(quote!(__mat_name));
        quote! {
            let #ident = match &#name {
                ::core::option::Option::Some(__mat_name) => {
                    ::core::option::Option::Some(#declare)
                }
                ::core::option::Option::None => ::core::option::Option::None,
            };
        }
    } else {
        let declare = declare(quote!(&#name));
        quote!(let #ident = #declare;)
    }
}

/// Phase 2: the field itself.
fn declare_phase(field: &Field) -> TokenStream {
    let ident = &field.ident;
    let key = &field.key;
    let name = mat_name(field);
    match &field.role {
        Role::Input {
            optional,
            state,
            shape: s,
        } => {
            let shape = shape(s);
            let declare = |n: TokenStream| match state {
                Reading::Execute => quote!(__binder.input(#n, #shape)),
                Reading::State => quote!(__binder.state_input(#n, #shape)),
                Reading::StateIf(when) => quote! {
                    if #when {
                        __binder.state_input(#n, #shape)
                    } else {
                        __binder.input(#n, #shape)
                    }
                },
            };
            bind(ident, &name, *optional, declare)
        }
        Role::Inputs { same_shape } => {
            quote!(let #ident = __support::inputs(__binder, #key, &#name, #same_shape)?;)
        }
        Role::Output { optional, shape: s } => {
            let declare = |n: TokenStream| match s {
                Shape::SameAs { .. } => {
                    let input = same_as(s);
                    quote!(__binder.output_same_as(#n, #input))
                }
                Shape::Like(template) => quote!(__binder.output_like(#n, #template)),
                other => {
                    let shape = shape(other);
                    quote!(__binder.output(#n, #shape))
                }
            };
            bind(ident, &name, *optional, declare)
        }
        Role::Param(p) => match p.ty {
            ParamType::Tunable => {
                let value = format_ident!("__value_{ident}");
                quote!(let #ident = __support::tunable(__binder, #key, #value);)
            }
            ParamType::TunableColumn => {
                let value = format_ident!("__value_{ident}");
                quote!(let #ident = __support::tunable_column(__binder, #key, &#value);)
            }
            _ => quote!(),
        },
        Role::State { init } => match init {
            Some(init) => quote!(let #ident = #init;),
            None => quote!(let #ident = ::core::default::Default::default();),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn expanded(code: &str) -> String {
        let input = syn::parse_str(code).expect("valid Rust");
        expand(&Component::parse(&input).expect("a valid component")).to_string()
    }

    #[test]
    fn the_spec_lists_described_fields_in_order_with_kinds_defaults_units_and_ranges() {
        let out = expanded(
            r#"
            /// y = k·u.
            #[component(name = "gain")]
            struct Gain {
                /// u
                #[input] input: Mat,
                /// y
                #[output(same_as = input)] output: Mat,
                /// the gain
                #[param(tunable, default = 1.0, unit = "1", above = 0)] k: Mat,
                /// how many
                #[param(default_doc = "all")] n: Option<u32>,
                value: Vec<f64>,
            }"#,
        );
        let spec = out.split("fn build").next().unwrap();
        let names: Vec<&str> = ["\"input\"", "\"output\"", "\"k\"", "\"n\""]
            .into_iter()
            .filter(|n| spec.contains(n))
            .collect();
        assert_eq!(names.len(), 4, "{spec}");
        assert!(
            !spec.contains("\"value\""),
            "state is not a parameter: {spec}"
        );
        assert!(spec.find("\"input\"") < spec.find("\"k\""), "{spec}");
        assert!(spec.contains("ParamKind :: Number"), "{spec}");
        assert!(
            spec.contains("Some (\"1\")"),
            "default 1.0 shown as 1: {spec}"
        );
        assert!(spec.contains("Some (\"> 0\")"), "{spec}");
        assert!(spec.contains("Some (\"all\")"), "{spec}");
    }

    #[test]
    fn the_factory_reads_every_parameter_before_declaring_any_csmat() {
        let out = expanded(
            r#"
            /// x
            #[component(name = "x", finish = Self::finish)]
            struct X {
                /// y
                #[output(shape = (n, 1))] y: Mat,
                /// n
                #[param(min = 1)] n: usize,
                /// u
                #[input(state)] u: Option<Mat>,
            }"#,
        );
        let build = out.split("fn build").nth(1).unwrap();
        let read_n = build.find("required :: < usize >").expect("n read");
        let declare_y = build.find("__binder . output").expect("y declared");
        assert!(read_n < declare_y, "{build}");
        assert!(build.contains("distinct"), "{build}");
        assert!(build.contains("state_input"), "{build}");
        assert!(
            build.contains("(Self :: finish) (& mut __this , __binder)"),
            "{build}"
        );
    }

    #[test]
    fn optional_outputs_conditional_inputs_and_unchecked_numbers() {
        let out = expanded(
            r#"
            /// x
            #[component(name = "x")]
            struct X {
                #[state(init = 2)]
                n: usize,
                /// terms
                #[inputs] terms: Vec<Mat>,
                /// u
                #[input(state = n > 1)] u: Mat,
                /// y
                #[output(same_as = terms)] y: Mat,
                /// v
                #[output(shape = (n, 1))] v: Option<Mat>,
                /// lower
                #[param(tunable, column, finite = false)] lower: Mat,
                /// count
                #[param(default = 3)] count: u32,
                /// limit
                #[param(finite = false)] limit: Option<f64>,
            }"#,
        );
        let (spec, build) = out.split_once("fn build").unwrap();
        assert!(
            spec.contains("name : \"v\" , kind : :: ndds_runtime :: ParamKind :: Output , default : :: core :: option :: Option :: Some (\"none\")"),
            "an optional output defaults to none: {spec}"
        );
        assert!(spec.contains("Some (\"3\")"), "{spec}");
        assert!(
            build.contains("if n > 1 { __binder . state_input"),
            "{build}"
        );
        assert!(
            build.contains("output_same_as (& __name_y , & terms [0])"),
            "{build}"
        );
        assert!(
            build.contains("__outputs . push (__mat_name . as_str ())"),
            "{build}"
        );
        assert!(
            build.contains("NonFinite < :: std :: vec :: Vec < f64 > >"),
            "{build}"
        );
        assert!(build.contains("NonFinite < _ >"), "{build}");
        assert!(
            build.contains("None => 3"),
            "an integer default is typed by its field: {build}"
        );
        assert!(build.contains("tunable_column"), "{build}");
    }

    #[test]
    fn defaults_are_shown_as_written() {
        let expr = |code: &str| expr_text(&syn::parse_str(code).unwrap());
        assert_eq!(expr("1.0"), "1");
        assert_eq!(expr("0.25"), "0.25");
        assert_eq!(expr("\"linear\""), "linear");
        assert_eq!(expr("1u64"), "1");
        assert_eq!(expr("0.5_f64"), "0.5");
        assert_eq!(expr("-1.0"), "-1");
        assert_eq!(expr("vec![0.0, 1.0]"), "vec![0.0,1.0]");
    }
}
