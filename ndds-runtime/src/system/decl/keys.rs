//! The key tables: one [`Section`] per section of the format, listing its [`Key`]s. The loader
//! reads a section through its table ([`Reader`] knows the keys), reports any other key with
//! the closest known one, and the reference test checks that docs/description-files.md lists
//! exactly these keys. A key is added to its section's table and nowhere else.

use super::reader::Reader;
use super::{Description, SpecLookup, list, suggest};
use crate::system::source::{Diagnostics, Location, Raw, RawValue};

/// What a string key takes, as a message shows it.
pub(super) const TEXT: &str = "\"...\"";

/// One key of a section.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Key {
    /// The key as written.
    pub name: &'static str,
    /// What it takes, as the message for a missing key shows it after `` `name = ` ``.
    pub takes: &'static str,
}

impl Key {
    pub(super) const fn new(name: &'static str, takes: &'static str) -> Self {
        Self { name, takes }
    }
}

impl AsRef<str> for Key {
    fn as_ref(&self) -> &str {
        self.name
    }
}

/// How a section is written at the top level of a file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Form {
    /// One table: `[system]`.
    Table,
    /// A list of tables: `[[habitat]]`.
    List,
}

/// Reads one table of a section into the description.
type Read = fn(&mut Description, &Reader<'_>, &SpecLookup<'_>, &mut Diagnostics);

/// A section of a description file: its name, its keys (in the order the reference lists
/// them) and its reader.
#[derive(Clone, Copy, Debug)]
pub struct Section {
    /// The top-level key (`habitat` for `[[habitat]]`).
    pub name: &'static str,
    /// Its keys.
    pub keys: &'static [Key],
    /// Whether other keys are allowed too: `[[component]]`'s are its type's parameters,
    /// checked against the type's documentation instead.
    pub open: bool,
    form: Form,
    read: Read,
}

impl Section {
    /// A section written as one table.
    pub(super) const fn table(name: &'static str, keys: &'static [Key], read: Read) -> Self {
        Self {
            name,
            keys,
            open: false,
            form: Form::Table,
            read,
        }
    }

    /// A section written as a list of tables.
    pub(super) const fn list(name: &'static str, keys: &'static [Key], read: Read) -> Self {
        Self {
            form: Form::List,
            ..Self::table(name, keys, read)
        }
    }

    /// The same section, taking other keys too.
    pub(super) const fn open(self) -> Self {
        Self { open: true, ..self }
    }

    /// The names of its keys, in order.
    pub fn key_names(&self) -> impl Iterator<Item = &'static str> + 'static {
        self.keys.iter().map(|k| k.name)
    }

    /// The section as messages name it: `[system]`, `[[habitat]]`.
    pub(super) fn title(&self) -> String {
        match self.form {
            Form::Table => format!("[{}]", self.name),
            Form::List => format!("[[{}]]", self.name),
        }
    }

    /// Reads the section's value at the top level of a file (`at`: where its key is).
    pub(super) fn read_all(
        &self,
        d: &mut Description,
        raw: &Raw,
        at: &Location,
        spec: &SpecLookup<'_>,
        p: &mut Diagnostics,
    ) {
        if self.form == Form::Table {
            return self.read_one(d, raw, spec, p);
        }
        let RawValue::Array(entries) = &raw.value else {
            let name = self.name;
            let what = format!("`{name}` is {}", raw.value.kind());
            p.expected(at, what, format!("a list of tables: `[[{name}]]`"));
            return;
        };
        for entry in entries {
            self.read_one(d, entry, spec, p);
        }
    }

    fn read_one(&self, d: &mut Description, raw: &Raw, spec: &SpecLookup<'_>, p: &mut Diagnostics) {
        let Some(r) = Reader::new(raw, &self.title(), self.keys, p) else {
            return;
        };
        if !self.open {
            r.known_keys(p);
        }
        (self.read)(d, &r, spec, p);
    }
}

/// Reports a top-level key that is neither `include` nor a section.
pub(super) fn unknown_section(key: &str, at: &Location, known: &[&str], p: &mut Diagnostics) {
    p.expected(
        at,
        format!("unknown section `{key}`"),
        format!("one of {}{}", list(known), suggest(key, known)),
    );
}
