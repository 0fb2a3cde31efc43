//! `ndds echo --field PATH`: one value inside each decoded sample.
//!
//! A path is struct fields (and map keys) separated by dots, each followed by any number of
//! `[INDEX]` into a list: `data`, `pose.x`, `data[1]`, `joints[0].limits[1]`; a sample that
//! is itself a list starts with an index: `[2]`. It is applied to the sample's JSON form (the
//! form `ndds echo --json` prints), so an option is its value or `null`, and an enum is an
//! object keyed by its variant.

use std::fmt;

use serde_json::Value;

use ndds_core::suggest;

/// A parsed `--field` path.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FieldPath {
    text: String,
    steps: Vec<Step>,
}

#[derive(Clone, Debug, PartialEq, Eq)]
enum Step {
    Name(String),
    Index(usize),
}

/// Why a path does not lead to a value in a sample.
#[derive(Debug, PartialEq, Eq)]
pub enum FieldError {
    /// A struct (or map) has no member of that name.
    NoMember {
        /// The path up to the struct (empty: the sample).
        at: String,
        /// The missing name.
        name: String,
        /// The members it has.
        members: Vec<String>,
    },
    /// A name was applied to a value that has no members.
    NotAStruct {
        /// The path up to the value.
        at: String,
        /// What the value is (`a number`, `a list`, ...).
        kind: &'static str,
    },
    /// An index beyond a list's end.
    NoElement {
        /// The path up to the list.
        at: String,
        /// The index asked for.
        index: usize,
        /// The list's length in this sample.
        len: usize,
    },
    /// An index was applied to a value that is not a list.
    NotAList {
        /// The path up to the value.
        at: String,
        /// What the value is.
        kind: &'static str,
    },
}

impl FieldPath {
    /// Parses `pose.x`, `data[1]`, `[0].name`; the error says what is wrong where.
    pub fn parse(text: &str) -> Result<FieldPath, String> {
        let mut steps = Vec::new();
        let mut rest = text;
        let mut first = true;
        while !rest.is_empty() || first {
            if !first {
                rest = rest
                    .strip_prefix('.')
                    .ok_or_else(|| format!("{text:?}: expected `.` or `[` before {rest:?}"))?;
            }
            let end = rest.find(['.', '[', ']']).unwrap_or(rest.len());
            let (name, after) = rest.split_at(end);
            let leading_index = first && name.is_empty() && after.starts_with('[');
            if name.is_empty() && !leading_index {
                return Err(format!("{text:?}: empty field name"));
            }
            if !name.is_empty() {
                steps.push(Step::Name(name.to_owned()));
            }
            rest = after;
            while let Some(inside) = rest.strip_prefix('[') {
                let (digits, after) = inside
                    .split_once(']')
                    .ok_or_else(|| format!("{text:?}: `[` without `]`"))?;
                let index = digits.trim().parse().map_err(|_| {
                    format!("{text:?}: [{digits}] is not a list index (0, 1, 2, ...)")
                })?;
                steps.push(Step::Index(index));
                rest = after;
            }
            first = false;
        }
        Ok(FieldPath {
            text: text.to_owned(),
            steps,
        })
    }

    /// The path as given.
    pub fn as_str(&self) -> &str {
        &self.text
    }

    /// The value the path leads to in `sample`.
    pub fn select<'v>(&self, sample: &'v Value) -> Result<&'v Value, FieldError> {
        let mut value = sample;
        let mut at = String::new();
        for step in &self.steps {
            value = match step {
                Step::Name(name) => member(value, name, &at)?,
                Step::Index(index) => element(value, *index, &at)?,
            };
            match step {
                Step::Name(name) if at.is_empty() => at.push_str(name),
                Step::Name(name) => at = format!("{at}.{name}"),
                Step::Index(index) => at = format!("{at}[{index}]"),
            }
        }
        Ok(value)
    }
}

fn member<'v>(value: &'v Value, name: &str, at: &str) -> Result<&'v Value, FieldError> {
    let Value::Object(members) = value else {
        return Err(FieldError::NotAStruct {
            at: at.to_owned(),
            kind: kind(value),
        });
    };
    members.get(name).ok_or_else(|| FieldError::NoMember {
        at: at.to_owned(),
        name: name.to_owned(),
        members: members.keys().cloned().collect(),
    })
}

fn element<'v>(value: &'v Value, index: usize, at: &str) -> Result<&'v Value, FieldError> {
    let Value::Array(elements) = value else {
        return Err(FieldError::NotAList {
            at: at.to_owned(),
            kind: kind(value),
        });
    };
    elements.get(index).ok_or(FieldError::NoElement {
        at: at.to_owned(),
        index,
        len: elements.len(),
    })
}

fn kind(value: &Value) -> &'static str {
    match value {
        Value::Null => "null (an empty option)",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "a list",
        Value::Object(_) => "a struct",
    }
}

/// `the sample` or `` `pose` ``.
fn place(at: &str) -> String {
    if at.is_empty() {
        "the sample".to_owned()
    } else {
        format!("`{at}`")
    }
}

impl fmt::Display for FieldError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FieldError::NoMember { at, name, members } => {
                write!(f, "{} has no field `{name}`", place(at))?;
                if let Some(question) =
                    suggest::did_you_mean(&suggest::suggest(name, members.iter()))
                {
                    write!(f, "; {question}")?;
                }
                let listed: Vec<String> = members.iter().map(|m| format!("`{m}`")).collect();
                match listed.as_slice() {
                    [] => write!(f, " (it has none)"),
                    _ => write!(f, " (its fields: {})", listed.join(", ")),
                }
            }
            FieldError::NotAStruct { at, kind } => {
                write!(f, "{} is {kind}, it has no fields", place(at))
            }
            FieldError::NoElement { at, index, len } => write!(
                f,
                "{} has {len} element{} in this sample, no [{index}]",
                place(at),
                if *len == 1 { "" } else { "s" }
            ),
            FieldError::NotAList { at, kind } => {
                write!(f, "{} is {kind}, not a list: no index applies", place(at))
            }
        }
    }
}

impl std::error::Error for FieldError {}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;

    fn path(text: &str) -> FieldPath {
        FieldPath::parse(text).unwrap()
    }

    #[test]
    fn paths_parse_into_names_and_indices() {
        assert_eq!(path("data").steps, [Step::Name("data".into())]);
        assert_eq!(
            path("joints[0].limits[1]").steps,
            [
                Step::Name("joints".into()),
                Step::Index(0),
                Step::Name("limits".into()),
                Step::Index(1)
            ]
        );
        assert_eq!(path("[2][0]").steps, [Step::Index(2), Step::Index(0)]);
        for bad in [
            "", ".x", "a..b", "a.", "a[", "a[x]", "a[-1]", "a]b", "a[0]b", "x.[1]",
        ] {
            assert!(FieldPath::parse(bad).is_err(), "{bad:?} refused");
        }
    }

    #[test]
    fn a_path_selects_a_field_an_element_or_a_nested_value() {
        let sample = json!({"data": [1.0, 2.5], "pose": {"x": 3, "y": 4}, "tags": {"a": 1}});
        assert_eq!(path("data[1]").select(&sample), Ok(&json!(2.5)));
        assert_eq!(path("pose.x").select(&sample), Ok(&json!(3)));
        assert_eq!(path("pose").select(&sample), Ok(&json!({"x": 3, "y": 4})));
        assert_eq!(path("tags.a").select(&sample), Ok(&json!(1)));
        assert_eq!(path("[1]").select(&json!([7, 8])), Ok(&json!(8)));
    }

    #[test]
    fn a_wrong_path_names_what_is_there() {
        let sample = json!({"data": [1.0, 2.5], "pose": {"x": 3, "y": 4}});
        let err = path("pose.z").select(&sample).unwrap_err();
        assert_eq!(
            err.to_string(),
            "`pose` has no field `z` (its fields: `x`, `y`)"
        );
        let err = path("dta").select(&sample).unwrap_err();
        assert_eq!(
            err.to_string(),
            "the sample has no field `dta`; did you mean `data`? (its fields: `data`, `pose`)"
        );
        let err = path("data[2]").select(&sample).unwrap_err();
        assert_eq!(
            err.to_string(),
            "`data` has 2 elements in this sample, no [2]"
        );
        let err = path("pose.x.y").select(&sample).unwrap_err();
        assert_eq!(err.to_string(), "`pose.x` is a number, it has no fields");
        let err = path("pose[0]").select(&sample).unwrap_err();
        assert_eq!(
            err.to_string(),
            "`pose` is a struct, not a list: no index applies"
        );
        let err = path("data").select(&json!(5)).unwrap_err();
        assert_eq!(err.to_string(), "the sample is a number, it has no fields");
    }
}
