//! What a field's Rust type is, as far as the derive must know: a `Mat`, an optional or a
//! list of them, or a parameter type; and the doc comments that become the spec's text.

use syn::spanned::Spanned as _;
use syn::{Attribute, Expr, ExprLit, Ident, Lit, Meta, Type};

use crate::model::ParamType;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum MatType {
    Mat,
    Optional,
    List,
}

/// The last segment of a type's path, with its one generic argument if any.
fn last_segment(ty: &Type) -> Option<(String, Option<&Type>)> {
    let Type::Path(path) = ty else { return None };
    if path.qself.is_some() {
        return None;
    }
    let segment = path.path.segments.last()?;
    let argument = match &segment.arguments {
        syn::PathArguments::None => None,
        syn::PathArguments::AngleBracketed(args) => {
            let mut types = args.args.iter().filter_map(|a| match a {
                syn::GenericArgument::Type(t) => Some(t),
                _ => None,
            });
            let first = types.next()?;
            if types.next().is_some() {
                return None;
            }
            Some(first)
        }
        syn::PathArguments::Parenthesized(_) => return None,
    };
    Some((segment.ident.to_string(), argument))
}

fn is_plain(ty: &Type, name: &str) -> bool {
    matches!(last_segment(ty), Some((n, None)) if n == name)
}

pub(crate) fn mat_type(ty: &Type) -> Option<MatType> {
    match last_segment(ty)? {
        (name, None) if name == "Mat" => Some(MatType::Mat),
        (name, Some(inner)) if name == "Option" && is_plain(inner, "Mat") => {
            Some(MatType::Optional)
        }
        (name, Some(inner)) if name == "Vec" && is_plain(inner, "Mat") => Some(MatType::List),
        _ => None,
    }
}

pub(crate) fn option_inner(ty: &Type) -> Option<&Type> {
    match last_segment(ty)? {
        (name, Some(inner)) if name == "Option" => Some(inner),
        _ => None,
    }
}

pub(crate) fn param_type(ty: &Type) -> Option<ParamType> {
    const WHOLE: &[&str] = &[
        "u8", "u16", "u32", "u64", "usize", "i8", "i16", "i32", "i64", "isize",
    ];
    Some(match last_segment(ty)? {
        (name, None) => match name.as_str() {
            "f64" => ParamType::Number,
            "String" => ParamType::Text,
            "PathBuf" => ParamType::File,
            "bool" => ParamType::Bool,
            "Params" => ParamType::Table,
            n if WHOLE.contains(&n) => ParamType::Whole,
            _ => return None,
        },
        (name, Some(inner)) if name == "Vec" && is_plain(inner, "f64") => ParamType::Numbers,
        (name, Some(inner)) if name == "DMatrix" && is_plain(inner, "f64") => ParamType::Matrix,
        _ => return None,
    })
}

pub(crate) fn wrong_type(ty: &Type, ident: &Ident, role: &str, takes: &str) -> syn::Error {
    let shown = quote::quote!(#ty).to_string().replace(' ', "");
    syn::Error::new(
        ty.span(),
        format!("field `{ident}`: {role} does not take `{shown}`; it takes {takes}"),
    )
}

/// The lines of the `///` comments on `attrs`, trimmed.
pub(crate) fn doc_text(attrs: &[Attribute]) -> Vec<String> {
    attrs
        .iter()
        .filter(|a| a.path().is_ident("doc"))
        .filter_map(|a| match &a.meta {
            Meta::NameValue(nv) => match &nv.value {
                Expr::Lit(ExprLit {
                    lit: Lit::Str(s), ..
                }) => Some(s.value().trim().to_owned()),
                _ => None,
            },
            _ => None,
        })
        .collect()
}

/// The first paragraph of the doc comment, as one line.
pub(crate) fn first_paragraph(attrs: &[Attribute]) -> String {
    let lines = doc_text(attrs);
    lines
        .iter()
        .take_while(|l| !l.is_empty())
        .cloned()
        .collect::<Vec<_>>()
        .join(" ")
}
