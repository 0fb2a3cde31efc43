//! One field of a component struct: its role attribute (`#[input]`, `#[inputs]`,
//! `#[output]`, `#[param]`, `#[state]`) and options, read and checked against its type.

use syn::meta::ParseNestedMeta;
use syn::spanned::Spanned as _;
use syn::{Attribute, Expr, ExprLit, Ident, Lit, LitStr, Meta, Type};

use crate::model::{Field, PARAM_TYPES, Param, ParamType, Range, Reading, Role, Shape};
use crate::types::{MatType, doc_text, mat_type, option_inner, param_type, wrong_type};

impl Field {
    pub(crate) fn parse(field: &syn::Field) -> syn::Result<Self> {
        let ident = field.ident.clone().expect("named fields have names");
        if ident.to_string().starts_with("__") {
            return Err(syn::Error::new(
                ident.span(),
                format!(
                    "field `{ident}`: names beginning with `__` are the derive's own (its \
                     generated code uses them); rename the field"
                ),
            ));
        }
        let doc = doc_text(&field.attrs).join(" ");
        let mut role = None;
        let mut key = None;
        for attr in &field.attrs {
            let Some(which) = attr.path().get_ident().map(Ident::to_string) else {
                continue;
            };
            let parsed = match which.as_str() {
                "input" => parse_input(attr, &field.ty, &ident, &mut key)?,
                "inputs" => parse_inputs(attr, &field.ty, &ident, &mut key)?,
                "output" => parse_output(attr, &field.ty, &ident, &mut key)?,
                "param" => Role::Param(parse_param(attr, &field.ty, &ident, &mut key)?),
                "state" => parse_state(attr)?,
                _ => continue,
            };
            if role.is_some() {
                return Err(syn::Error::new(
                    attr.span(),
                    format!(
                        "field `{ident}` has two roles; give it one of #[input], #[inputs], \
                         #[output], #[param] or #[state]"
                    ),
                ));
            }
            role = Some(parsed);
        }
        let role = role.unwrap_or(Role::State { init: None });
        let described = !matches!(role, Role::State { .. });
        if described && doc.trim().is_empty() {
            return Err(syn::Error::new(
                ident.span(),
                format!(
                    "field `{ident}` needs a doc comment: it is the parameter's line in the \
                     reference docs and the editor"
                ),
            ));
        }
        let key = key.unwrap_or_else(|| default_key(&ident));
        Ok(Self {
            span: ident.span(),
            ident,
            key,
            doc,
            role,
            ty: field.ty.clone(),
        })
    }

    /// Whether the field is a key of the description file's table.
    pub fn is_described(&self) -> bool {
        !matches!(self.role, Role::State { .. })
    }
}

/// The key of a field without `key = "..."`: its name, without `r#` (`r#final`) or a leading
/// `_` (`_rows`: a parameter no routine reads, used only while building).
fn default_key(ident: &Ident) -> String {
    let name = ident.to_string();
    let name = name.strip_prefix("r#").unwrap_or(&name);
    name.strip_prefix('_').unwrap_or(name).to_owned()
}

/// Reads the options of a role attribute (none for a bare `#[input]`): `key = "..."` into
/// `key`, every other one through `option`, which answers `false` for a name it does not
/// take; such a name is refused with `takes` (the attribute's options, in words).
fn options(
    attr: &Attribute,
    key: &mut Option<String>,
    takes: &str,
    mut option: impl FnMut(&str, &ParseNestedMeta<'_>) -> syn::Result<bool>,
) -> syn::Result<()> {
    if !matches!(attr.meta, Meta::List(_)) {
        return Ok(());
    }
    attr.parse_nested_meta(|meta| {
        let name = meta.path.get_ident().map(Ident::to_string);
        match name.as_deref() {
            Some("key") => *key = Some(meta.value()?.parse::<LitStr>()?.value()),
            Some(name) if option(name, &meta)? => {}
            _ => return Err(meta.error(takes)),
        }
        Ok(())
    })
}

/// Whether a `Mat` field of `role` is optional (`Option<Mat>`); any other type is refused.
fn single_mat(ty: &Type, ident: &Ident, role: &str) -> syn::Result<bool> {
    match mat_type(ty) {
        Some(MatType::Mat) => Ok(false),
        Some(MatType::Optional) => Ok(true),
        _ => Err(wrong_type(ty, ident, role, "Mat, or Option<Mat>")),
    }
}

/// `same_as = FIELD`.
fn same_as(meta: &ParseNestedMeta<'_>) -> syn::Result<Shape> {
    Ok(Shape::SameAs {
        field: meta.value()?.parse()?,
        first: false,
    })
}

fn parse_input(
    attr: &Attribute,
    ty: &Type,
    ident: &Ident,
    key: &mut Option<String>,
) -> syn::Result<Role> {
    let optional = single_mat(ty, ident, "#[input]")?;
    let mut state = Reading::Execute;
    let mut shape = Shape::Any;
    let takes = "unknown #[input] option; it takes `state`, `state = EXPR`, \
                 `shape = (ROWS, COLS)`, `same_as = FIELD` and `key = \"...\"`";
    options(attr, key, takes, |name, meta| {
        match name {
            "state" if meta.input.peek(syn::Token![=]) => {
                state = Reading::StateIf(meta.value()?.parse()?);
            }
            "state" => state = Reading::State,
            "shape" => shape = Shape::Expr(meta.value()?.parse()?),
            "same_as" => shape = same_as(meta)?,
            _ => return Ok(false),
        }
        Ok(true)
    })?;
    Ok(Role::Input {
        optional,
        state,
        shape,
    })
}

fn parse_inputs(
    attr: &Attribute,
    ty: &Type,
    ident: &Ident,
    key: &mut Option<String>,
) -> syn::Result<Role> {
    if mat_type(ty) != Some(MatType::List) {
        return Err(wrong_type(ty, ident, "#[inputs]", "Vec<Mat>"));
    }
    let mut same_shape = false;
    let takes = "unknown #[inputs] option; it takes `same_shape` and `key = \"...\"`";
    options(attr, key, takes, |name, _| {
        same_shape |= name == "same_shape";
        Ok(name == "same_shape")
    })?;
    Ok(Role::Inputs { same_shape })
}

fn parse_output(
    attr: &Attribute,
    ty: &Type,
    ident: &Ident,
    key: &mut Option<String>,
) -> syn::Result<Role> {
    let optional = single_mat(ty, ident, "#[output]")?;
    let mut shape = Shape::Any;
    let takes = "unknown #[output] option; it takes `shape = (ROWS, COLS)`, \
                 `same_as = FIELD`, `like = TEMPLATE` and `key = \"...\"`";
    options(attr, key, takes, |name, meta| {
        match name {
            "shape" => shape = Shape::Expr(meta.value()?.parse()?),
            "same_as" => shape = same_as(meta)?,
            "like" => shape = Shape::Like(meta.value()?.parse()?),
            _ => return Ok(false),
        }
        Ok(true)
    })?;
    Ok(Role::Output { optional, shape })
}

fn parse_param(
    attr: &Attribute,
    ty: &Type,
    ident: &Ident,
    key: &mut Option<String>,
) -> syn::Result<Param> {
    let mut tunable = false;
    let mut column = false;
    let mut any_number = false;
    let mut default = None;
    let mut default_doc = None;
    let mut unit = None;
    let mut range = Range::default();
    let takes = "unknown #[param] option; it takes `default = EXPR`, \
                 `default_doc = \"...\"`, `unit = \"...\"`, `min`, `max`, `above`, \
                 `below` (number literals), `finite = false`, `tunable`, `column` \
                 and `key = \"...\"`";
    options(attr, key, takes, |name, meta| {
        match name {
            "tunable" => tunable = true,
            "column" => column = true,
            "finite" => any_number = !meta.value()?.parse::<syn::LitBool>()?.value,
            "default" => default = Some(meta.value()?.parse::<Expr>()?),
            "default_doc" => default_doc = Some(meta.value()?.parse::<LitStr>()?.value()),
            "unit" => unit = Some(meta.value()?.parse::<LitStr>()?.value()),
            "min" => range.min = Some(number_literal(&meta.value()?.parse()?)?),
            "max" => range.max = Some(number_literal(&meta.value()?.parse()?)?),
            "above" => range.above = Some(number_literal(&meta.value()?.parse()?)?),
            "below" => range.below = Some(number_literal(&meta.value()?.parse()?)?),
            _ => return Ok(false),
        }
        Ok(true)
    })?;
    let (inner, optional) = match option_inner(ty) {
        Some(inner) => (inner, true),
        None => (ty, false),
    };
    let ty_kind = if tunable {
        match (mat_type(inner), optional) {
            (Some(MatType::Mat), false) => {
                let list_default = default
                    .as_ref()
                    .is_some_and(|d| matches!(d, Expr::Array(_) | Expr::Macro(_)));
                if column || list_default {
                    ParamType::TunableColumn
                } else {
                    ParamType::Tunable
                }
            }
            _ => {
                return Err(syn::Error::new(
                    ty.span(),
                    format!(
                        "field `{ident}`: a `tunable` parameter is a Mat (its CSMat \
                         `<module>.{ident}`), not an Option"
                    ),
                ));
            }
        }
    } else {
        param_type(inner).ok_or_else(|| wrong_type(ty, ident, "#[param]", PARAM_TYPES))?
    };
    if column && !tunable {
        return Err(syn::Error::new(
            ident.span(),
            format!(
                "field `{ident}`: `column` is for a `tunable` Mat given as a list; a list that \
                 is not tunable is a Vec<f64>"
            ),
        ));
    }
    if any_number && (ty_kind == ParamType::Whole || !ty_kind.numeric()) {
        return Err(syn::Error::new(
            ident.span(),
            format!(
                "field `{ident}`: `finite = false` applies to f64, Vec<f64>, DMatrix<f64> and \
                 tunable Mats only"
            ),
        ));
    }
    if optional && default.is_some() {
        return Err(syn::Error::new(
            ident.span(),
            format!(
                "field `{ident}`: an Option parameter is `None` when absent; give either \
                 Option<T> or a `default`, not both"
            ),
        ));
    }
    if !range.is_empty() && !ty_kind.numeric() {
        return Err(syn::Error::new(
            ident.span(),
            format!("field `{ident}`: `min`/`max`/`above`/`below` apply to numbers only"),
        ));
    }
    if default_doc.is_some() && default.is_none() && !optional {
        return Err(syn::Error::new(
            ident.span(),
            format!("field `{ident}`: `default_doc` without a `default`"),
        ));
    }
    Ok(Param {
        ty: ty_kind,
        optional,
        default,
        default_doc,
        unit,
        range,
        any_number,
    })
}

fn parse_state(attr: &Attribute) -> syn::Result<Role> {
    let mut init = None;
    if matches!(attr.meta, Meta::List(_)) {
        attr.parse_nested_meta(|meta| {
            if meta.path.is_ident("init") {
                init = Some(meta.value()?.parse::<Expr>()?);
                Ok(())
            } else {
                Err(meta.error("unknown #[state] option; it takes `init = EXPR`"))
            }
        })?;
    }
    Ok(Role::State { init })
}

fn number_literal(expr: &Expr) -> syn::Result<f64> {
    let (negative, inner) = match expr {
        Expr::Unary(unary) if matches!(unary.op, syn::UnOp::Neg(_)) => (true, &*unary.expr),
        other => (false, other),
    };
    let value = match inner {
        Expr::Lit(ExprLit {
            lit: Lit::Float(f), ..
        }) => f.base10_parse::<f64>()?,
        Expr::Lit(ExprLit {
            lit: Lit::Int(i), ..
        }) => i.base10_parse::<f64>()?,
        other => {
            return Err(syn::Error::new(
                other.span(),
                "a bound is a number literal (`min = 0.0`)",
            ));
        }
    };
    Ok(if negative { -value } else { value })
}
