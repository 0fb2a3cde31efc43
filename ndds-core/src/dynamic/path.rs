//! Where a value sits in the JSON tree, kept as a chain of stack frames so that walking a value
//! never allocates for it; rendered as a JSON pointer only when an error needs it.

use std::fmt::Write as _;

/// One step from a value to a value inside it.
#[derive(Clone, Copy, Debug)]
pub(super) enum Step<'a> {
    /// The value inside an option or newtype struct: the same place in JSON.
    Inner,
    /// An element of an array.
    Index(usize),
    /// A member of an object (struct field, map key, enum variant).
    Name(&'a str),
}

/// A value's place: the steps from the root, innermost last.
#[derive(Clone, Copy, Debug)]
pub(super) struct Path<'a> {
    parent: Option<&'a Path<'a>>,
    step: Step<'a>,
    depth: usize,
}

impl<'a> Path<'a> {
    /// The root value.
    pub(super) const ROOT: Path<'static> = Path {
        parent: None,
        step: Step::Inner,
        depth: 0,
    };

    /// The place one `step` inside this one.
    pub(super) fn child(&'a self, step: Step<'a>) -> Path<'a> {
        Path {
            parent: Some(self),
            step,
            depth: self.depth + 1,
        }
    }

    /// Steps from the root, each one counting (including [`Step::Inner`]).
    pub(super) fn depth(&self) -> usize {
        self.depth
    }

    /// The JSON pointer of this place, with the root written `/`.
    pub(super) fn render(&self) -> String {
        let mut steps = Vec::new();
        let mut at = Some(self);
        while let Some(path) = at {
            steps.push(path.step);
            at = path.parent;
        }
        let mut out = String::new();
        for step in steps.iter().rev() {
            match step {
                Step::Inner => {}
                Step::Index(index) => {
                    let _ = write!(out, "/{index}");
                }
                Step::Name(name) => {
                    out.push('/');
                    out.push_str(&name.replace('~', "~0").replace('/', "~1"));
                }
            }
        }
        if out.is_empty() {
            out.push('/');
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn renders_json_pointers() {
        let root = Path::ROOT;
        assert_eq!(root.render(), "/");
        let field = root.child(Step::Name("pose"));
        let inner = field.child(Step::Inner);
        let item = inner.child(Step::Index(3));
        let odd = item.child(Step::Name("a/b~c"));
        assert_eq!(odd.render(), "/pose/3/a~1b~0c");
        assert_eq!(odd.depth(), 4);
    }
}
