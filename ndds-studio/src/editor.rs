//! The description-file editor: ControlShell's Data-Flow Editor and FSM editor over the TOML
//! files `ndds run` reads.
//!
//! An [`Editor`] holds a system's files (the top file, the files it includes and the
//! state-machine files they name) as text, under one root directory it never leaves. Every
//! edit is a small change to one file's TOML made with `toml_edit` (so comments, order and
//! layout stay as written: changing a gain changes that one line), after which the whole
//! system is loaded again by the loader `ndds run` uses, in its check mode, with the edited
//! texts standing in for the files on disk ([`LoadOptions::overlay`]). The loader's
//! diagnostics are tied to the element they concern (a component, a key of it, a transition)
//! for the page to show there. Nothing is written until [`save`](Editor::save), which
//! refuses a file changed on disk since it was read and, unless forced, a system that does
//! not verify.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use ndds_client::Participant;
use ndds_runtime::system::{
    LoadOptions, MAX_FILE_BYTES, Overlay, System, SystemError, overlay_key,
};
use ndds_runtime::{ParamKind, Registry};
use serde::{Deserialize, Serialize};
use serde_json::{Value as Json, json};
use toml_edit::{ArrayOfTables, DocumentMut, Item, Table, Value};

/// Most files the editor holds for one system (as many as the loader reads).
pub const MAX_EDIT_FILES: usize = ndds_runtime::system::MAX_FILES;
/// Most `.toml` files [`Editor::list`] offers.
pub const MAX_LISTED: usize = 500;

/// Why an edit was refused. The files are unchanged.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EditError {
    /// A path outside the editor's root, or not a description file.
    #[error("`{0}`: {1}")]
    Path(String, String),
    /// Nothing is open.
    #[error("no description is open: open one, or start a new one")]
    NothingOpen,
    /// The file is not among the system's files.
    #[error("`{0}` is not one of this system's files ({1})")]
    UnknownFile(String, String),
    /// The file is not valid TOML, so it can only be replaced as a whole.
    #[error("`{0}` is not valid TOML ({1}): correct its text first")]
    Unparsed(String, String),
    /// The path names nothing that can take this edit.
    #[error("{0}")]
    Target(String),
    /// A value that is not TOML.
    #[error(
        "`{text}` is not a TOML value ({why}); write numbers as 1.5, text in quotes, lists as [1, 2]"
    )]
    Value {
        /// The text.
        text: String,
        /// The parser's reason.
        why: String,
    },
    /// A file could not be read or written.
    #[error("`{0}`: {1}")]
    Io(String, std::io::Error),
    /// Opening another system would forget unsaved changes.
    #[error("unsaved changes in {0}: save or revert them first, or discard them")]
    Unsaved(String),
    /// Saving was refused (the reason says what to do).
    #[error("{0}")]
    Refused(String),
}

/// One step of a path into a TOML document: a key, or an index into an array of tables.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Step {
    /// An index into an array of tables (`[[component]]` number N, from 0).
    Index(usize),
    /// A key.
    Key(String),
}

/// An edit the page asks for.
#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "op", rename_all = "snake_case")]
pub enum EditOp {
    /// The `.toml` files under the root, to choose one to open.
    List,
    /// Opens a top description file (relative to the root) and what it includes.
    Open {
        /// The file.
        path: String,
        /// Forget unsaved changes of the system open now (refused otherwise).
        #[serde(default)]
        discard: bool,
    },
    /// Starts an empty system in a file that does not exist yet.
    New {
        /// The file to save it as.
        path: String,
        /// Forget unsaved changes of the system open now (refused otherwise).
        #[serde(default)]
        discard: bool,
    },
    /// Sets (or, with `value: null`, removes) the key at the end of `path`; `value` is TOML
    /// (`55.0`, `"joints"`, `[1, 2]`, `{ a = 1 }`).
    Set {
        /// The file.
        file: String,
        /// Down to the key.
        path: Vec<Step>,
        /// The new value, or `None` to remove the key.
        value: Option<String>,
    },
    /// Appends a table to the array of tables at `path` (`["component"]`,
    /// `["machine", 0, "transition"]`), with these keys and TOML values in this order.
    Push {
        /// The file.
        file: String,
        /// The array of tables.
        path: Vec<Step>,
        /// Its keys and values.
        fields: Vec<(String, String)>,
    },
    /// Removes the table at the end of `path` (`["component", 2]`) or the key.
    Remove {
        /// The file.
        file: String,
        /// What to remove.
        path: Vec<Step>,
    },
    /// Replaces a file's whole text (to correct a file that is not valid TOML).
    Text {
        /// The file.
        file: String,
        /// Its new text.
        text: String,
    },
    /// Adds a state-machine file (`NAME.toml` beside the top file, a minimal program) and a
    /// `[[state_machine]]` naming it.
    NewMachine {
        /// The machine's name.
        name: String,
    },
    /// Writes the changed files.
    Save {
        /// Save even if the system does not verify.
        #[serde(default)]
        force: bool,
    },
    /// Forgets every change since the files were read or saved.
    Revert,
}

/// What a file is to the system.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FileKind {
    /// A description file (the top one or an included one).
    Description,
    /// A state-machine program named by `[[state_machine]]`.
    Machine,
}

#[derive(Debug)]
struct EditFile {
    /// Relative to the root.
    rel: PathBuf,
    kind: FileKind,
    /// Its text on disk when read or last saved (`None`: not on disk yet).
    original: Option<String>,
    text: String,
}

/// A problem the loader reported, tied to the element it concerns.
#[derive(Clone, Debug, Serialize)]
pub struct Problem {
    /// The file, relative to the root (`None`: the system as a whole).
    pub file: Option<String>,
    /// Line and column in that file (from 1).
    pub line: usize,
    /// Column.
    pub column: usize,
    /// What is wrong (and what was expected).
    pub message: String,
    /// The element: a path into the file's TOML (`["component", 1, "kp"]`), empty for the
    /// file as a whole.
    pub path: Vec<Step>,
}

/// The result of checking the edited system.
#[derive(Clone, Debug, Default)]
struct Checked {
    problems: Vec<Problem>,
    /// What the loader built, when it verified: a line saying so.
    summary: Option<String>,
    /// Each habitat's execution order (when it verified).
    orders: BTreeMap<String, Vec<String>>,
}

/// A system's description files being edited (see the module's documentation).
pub struct Editor {
    root: PathBuf,
    top: Option<PathBuf>,
    files: Vec<EditFile>,
    library: Registry,
    participant: Option<Participant>,
    checked: Checked,
}

impl Editor {
    /// An editor of the description files under `root` (which must exist), checking with
    /// `library`'s component types and, for systems with network bindings, `participant`
    /// (as `ndds run --check` does; nothing is started).
    pub fn new(
        root: &Path,
        library: Registry,
        participant: Option<Participant>,
    ) -> Result<Self, EditError> {
        let root = root
            .canonicalize()
            .map_err(|e| EditError::Io(root.display().to_string(), e))?;
        Ok(Self {
            root,
            top: None,
            files: Vec::new(),
            library,
            participant,
            checked: Checked::default(),
        })
    }

    /// Applies `op` and checks the system again; the editor's state (see [`state`](Self::state))
    /// is then what the page shows. On an error nothing changed.
    pub fn apply(&mut self, op: &EditOp) -> Result<String, EditError> {
        let said = match op {
            EditOp::List => return Ok(self.list().join("\n")),
            EditOp::Open { path, discard } => {
                let rel = self.relative(path)?;
                self.unsaved(*discard)?;
                if !self.root.join(&rel).is_file() {
                    return Err(EditError::Path(
                        path.clone(),
                        "no such file: choose one of the listed files, or start a new one".into(),
                    ));
                }
                self.top = Some(rel.clone());
                self.files.clear();
                self.discover()?;
                format!("opened `{}`", rel.display())
            }
            EditOp::New { path, discard } => {
                let rel = self.relative(path)?;
                self.unsaved(*discard)?;
                if self.root.join(&rel).exists() {
                    return Err(EditError::Path(
                        path.clone(),
                        "exists already: open it instead".into(),
                    ));
                }
                let stem = rel
                    .file_stem()
                    .map_or_else(|| "system".into(), |s| s.to_string_lossy().into_owned());
                let text = format!(
                    "[system]\nname = {}\n\n[[habitat]]\nname = \"control\"\nrate = 100.0\n",
                    toml_edit::Value::from(stem.as_str())
                );
                self.top = Some(rel.clone());
                self.files = vec![EditFile {
                    rel: rel.clone(),
                    kind: FileKind::Description,
                    original: None,
                    text,
                }];
                self.discover()?;
                format!("new system in `{}` (not saved yet)", rel.display())
            }
            EditOp::Set { file, path, value } => {
                let value = value.as_deref().map(parse_value).transpose()?;
                self.edit(file, |doc| set(doc, path, value))?;
                "changed".to_owned()
            }
            EditOp::Push { file, path, fields } => {
                let mut table = Table::new();
                for (key, text) in fields {
                    table.insert(key, Item::Value(parse_value(text)?));
                }
                self.edit(file, |doc| push(doc, path, table))?;
                "added".to_owned()
            }
            EditOp::Remove { file, path } => {
                self.edit(file, |doc| remove(doc, path))?;
                "removed".to_owned()
            }
            EditOp::Text { file, text } => {
                if text.len() as u64 > MAX_FILE_BYTES {
                    return Err(EditError::Target(format!(
                        "a description file is at most {MAX_FILE_BYTES} bytes"
                    )));
                }
                let index = self.file_index(file)?;
                self.files[index].text = text.clone();
                self.discover()?;
                "text replaced".to_owned()
            }
            EditOp::NewMachine { name } => self.new_machine(name)?,
            EditOp::Save { force } => return self.save(*force),
            EditOp::Revert => {
                self.files.retain(|f| f.original.is_some());
                for f in &mut self.files {
                    f.text = f.original.clone().unwrap_or_default();
                }
                if self.files.is_empty() {
                    self.top = None;
                }
                self.discover()?;
                "changes forgotten".to_owned()
            }
        };
        self.check();
        Ok(said)
    }

    /// Refuses to forget unsaved changes unless told to.
    fn unsaved(&self, discard: bool) -> Result<(), EditError> {
        let changed: Vec<String> = self
            .files
            .iter()
            .filter(|f| f.original.as_ref() != Some(&f.text))
            .map(|f| f.rel.display().to_string())
            .collect();
        if changed.is_empty() || discard {
            return Ok(());
        }
        Err(EditError::Unsaved(changed.join(", ")))
    }

    /// The `.toml` files under the root (relative paths, sorted; hidden directories and
    /// `target` skipped), at most [`MAX_LISTED`].
    pub fn list(&self) -> Vec<String> {
        let mut found = Vec::new();
        let mut dirs = vec![(self.root.clone(), 0)];
        while let Some((dir, depth)) = dirs.pop() {
            let Ok(entries) = std::fs::read_dir(&dir) else {
                continue;
            };
            for entry in entries.flatten() {
                let path = entry.path();
                let name = entry.file_name().to_string_lossy().into_owned();
                let Ok(kind) = entry.file_type() else {
                    continue;
                };
                if kind.is_dir() && depth < 6 && !name.starts_with('.') && name != "target" {
                    dirs.push((path, depth + 1));
                } else if kind.is_file()
                    && name.ends_with(".toml")
                    && let Ok(rel) = path.strip_prefix(&self.root)
                {
                    found.push(rel.display().to_string());
                }
            }
            if found.len() >= MAX_LISTED {
                break;
            }
        }
        found.sort();
        found.truncate(MAX_LISTED);
        found
    }

    /// A path the page names, relative to the root; refused outside it or without `.toml`.
    fn relative(&self, path: &str) -> Result<PathBuf, EditError> {
        let refuse = |why: &str| Err(EditError::Path(path.to_owned(), why.to_owned()));
        if !path.ends_with(".toml") {
            return refuse("description files end in `.toml`");
        }
        let joined = overlay_key(&self.root.join(path));
        let Ok(rel) = joined.strip_prefix(&self.root) else {
            return refuse(&format!(
                "outside the directory the studio edits ({})",
                self.root.display()
            ));
        };
        // A symbolic link may lead out of the root: where it really is counts (for a file not
        // made yet, where its nearest existing directory is).
        let existing = joined.ancestors().find(|a| a.exists());
        if let Some(real) = existing.and_then(|a| a.canonicalize().ok())
            && !real.starts_with(&self.root)
        {
            return refuse("leads outside the directory the studio edits");
        }
        Ok(rel.to_path_buf())
    }

    fn file_index(&self, file: &str) -> Result<usize, EditError> {
        if self.top.is_none() {
            return Err(EditError::NothingOpen);
        }
        let rel = self.relative(file)?;
        self.files
            .iter()
            .position(|f| f.rel == rel)
            .ok_or_else(|| EditError::UnknownFile(file.to_owned(), self.file_names().join(", ")))
    }

    fn file_names(&self) -> Vec<String> {
        self.files
            .iter()
            .map(|f| f.rel.display().to_string())
            .collect()
    }

    /// Applies `change` to one file's document; its text is replaced only if it succeeds.
    fn edit(
        &mut self,
        file: &str,
        change: impl FnOnce(&mut DocumentMut) -> Result<(), EditError>,
    ) -> Result<(), EditError> {
        let index = self.file_index(file)?;
        let f = &mut self.files[index];
        let mut doc: DocumentMut = f.text.parse().map_err(|e: toml_edit::TomlError| {
            EditError::Unparsed(file.to_owned(), first_line(&e.to_string()))
        })?;
        change(&mut doc)?;
        f.text = doc.to_string();
        self.discover()
    }

    /// Finds the files the top file includes and the state-machine files named, reading from
    /// disk those not held yet; forgets held files no longer named (unless changed).
    fn discover(&mut self) -> Result<(), EditError> {
        let Some(top) = self.top.clone() else {
            return Ok(());
        };
        let mut named: Vec<(PathBuf, FileKind)> = vec![(top, FileKind::Description)];
        let mut i = 0;
        while i < named.len() && named.len() <= MAX_EDIT_FILES {
            let (rel, kind) = named[i].clone();
            i += 1;
            if self.files.iter().all(|f| f.rel != rel) {
                match self.read(&rel) {
                    Some(text) => self.files.push(EditFile {
                        rel: rel.clone(),
                        kind,
                        original: Some(text.clone()),
                        text,
                    }),
                    // The loader says it cannot be read, where it is named.
                    None => continue,
                }
            }
            if kind == FileKind::Machine {
                continue;
            }
            let Some(f) = self.files.iter().find(|f| f.rel == rel) else {
                continue;
            };
            let dir = rel.parent().map(Path::to_path_buf).unwrap_or_default();
            for (child, kind) in references(&f.text) {
                let Ok(child) = self.relative(&dir.join(&child).to_string_lossy()) else {
                    continue; // the loader reports a file it cannot read
                };
                if named.iter().all(|(n, _)| *n != child) {
                    named.push((child, kind));
                }
            }
        }
        // Kept: the files named, and changed files (not to lose an edit).
        self.files.retain(|f| {
            named.iter().any(|(n, _)| *n == f.rel) || f.original.as_ref() != Some(&f.text)
        });
        for f in &mut self.files {
            if let Some((_, kind)) = named.iter().find(|(n, _)| *n == f.rel) {
                f.kind = *kind;
            }
        }
        Ok(())
    }

    /// A file's text from disk, if it is a regular file within the size limit.
    fn read(&self, rel: &Path) -> Option<String> {
        let path = self.root.join(rel);
        let meta = std::fs::metadata(&path).ok()?;
        if !meta.is_file() || meta.len() > MAX_FILE_BYTES {
            return None;
        }
        std::fs::read_to_string(path).ok()
    }

    fn new_machine(&mut self, name: &str) -> Result<String, EditError> {
        let Some(top) = self.top.clone() else {
            return Err(EditError::NothingOpen);
        };
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            return Err(EditError::Target(format!(
                "`{name}`: a machine's name is letters, digits, `_` and `-`"
            )));
        }
        let dir = top.parent().map(Path::to_path_buf).unwrap_or_default();
        let rel = dir.join(format!("{name}.toml"));
        if self.root.join(&rel).exists() || self.files.iter().any(|f| f.rel == rel) {
            return Err(EditError::Target(format!(
                "`{}` exists already",
                rel.display()
            )));
        }
        let quoted = Value::from(name);
        self.files.push(EditFile {
            rel: rel.clone(),
            kind: FileKind::Machine,
            original: None,
            text: format!(
                "main = {quoted}\n\n[stimuli]\nGo = \"transient\"\n\n[[machine]]\nname = {quoted}\n\
                 start = \"Idle\"\nstates = [\"Idle\", \"Running\"]\n\n[[machine.transition]]\n\
                 from = \"Idle\"\nwhen = \"Go\"\nnext = {{ 0 = \"Running\" }}\n"
            ),
        });
        let file = top.display().to_string();
        let entry = format!("{}", Value::from(format!("{name}.toml").as_str()));
        self.edit(&file, |doc| {
            let mut table = Table::new();
            table.insert("file", Item::Value(parse_value(&entry)?));
            push(doc, &[Step::Key("state_machine".into())], table)
        })?;
        Ok(format!(
            "added state machine `{name}` in `{}`",
            rel.display()
        ))
    }

    /// Writes the changed files (each through a temporary file renamed over it).
    pub fn save(&mut self, force: bool) -> Result<String, EditError> {
        if self.top.is_none() {
            return Err(EditError::NothingOpen);
        }
        if !force && self.checked.summary.is_none() {
            return Err(EditError::Refused(format!(
                "not saved: the system does not verify ({} problem{}); `ndds run` would refuse \
                 it. Correct them, or save anyway",
                self.checked.problems.len(),
                if self.checked.problems.len() == 1 {
                    ""
                } else {
                    "s"
                }
            )));
        }
        let changed: Vec<usize> = (0..self.files.len())
            .filter(|&i| self.files[i].original.as_ref() != Some(&self.files[i].text))
            .collect();
        // Nothing is written if any file changed on disk since it was read.
        for &i in &changed {
            let f = &self.files[i];
            let on_disk = self.read(&f.rel);
            if on_disk != f.original {
                return Err(EditError::Refused(format!(
                    "not saved: `{}` {} since it was opened; revert (or copy your change) and \
                     open it again",
                    f.rel.display(),
                    if f.original.is_none() {
                        "was created by someone else"
                    } else {
                        "was changed on disk"
                    }
                )));
            }
        }
        for &i in &changed {
            let path = self.root.join(&self.files[i].rel);
            let shown = self.files[i].rel.display().to_string();
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent).map_err(|e| EditError::Io(shown.clone(), e))?;
            }
            let temporary = path.with_extension(format!("toml.{}.tmp", std::process::id()));
            std::fs::write(&temporary, &self.files[i].text)
                .and_then(|()| {
                    // Keep the file's mode.
                    if let Ok(meta) = std::fs::metadata(&path) {
                        std::fs::set_permissions(&temporary, meta.permissions())?;
                    }
                    std::fs::rename(&temporary, &path)
                })
                .map_err(|e| {
                    let _ = std::fs::remove_file(&temporary);
                    EditError::Io(shown.clone(), e)
                })?;
            self.files[i].original = Some(self.files[i].text.clone());
        }
        let names: Vec<String> = changed
            .iter()
            .map(|&i| self.files[i].rel.display().to_string())
            .collect();
        Ok(if names.is_empty() {
            "nothing to save".to_owned()
        } else {
            format!("saved {}", names.join(", "))
        })
    }

    /// Loads the edited system as `ndds run --check` does, the edited texts standing in for
    /// the files.
    fn check(&mut self) {
        let Some(top) = &self.top else {
            self.checked = Checked::default();
            return;
        };
        let overlay: Overlay = self
            .files
            .iter()
            .map(|f| (overlay_key(&self.root.join(&f.rel)), f.text.clone()))
            .collect();
        let options = LoadOptions {
            check: true,
            overlay: Arc::new(overlay),
            ..LoadOptions::default().with_library(self.library.clone())
        };
        let path = self.root.join(top);
        let mut loaded = System::load_with(&path, None, options.clone());
        let mut offline = false;
        if let Err(SystemError::NeedsParticipant(_)) = &loaded {
            match &self.participant {
                Some(p) => loaded = System::load_with(&path, Some(p), options),
                None => offline = true,
            }
        }
        self.checked = match loaded {
            Ok(system) => {
                let d = system.runtime().describe();
                // Modules made from the library (not the runtime's own: bindings, rate
                // transitions).
                let components = d.modules.iter().filter(|m| !m.component.is_empty()).count();
                Checked {
                    problems: Vec::new(),
                    summary: Some(format!(
                        "verifies: {} habitat{}, {} component{}, {} configuration{}, {} state \
                         machine{}",
                        d.habitats.len(),
                        plural(d.habitats.len()),
                        components,
                        plural(components),
                        d.configurations.len(),
                        plural(d.configurations.len()),
                        system.machine_names().len(),
                        plural(system.machine_names().len()),
                    )),
                    orders: d.habitats.into_iter().map(|h| (h.name, h.order)).collect(),
                }
            }
            Err(SystemError::NeedsParticipant(_)) if offline => Checked {
                problems: Vec::new(),
                summary: Some(
                    "verifies as far as it can without a daemon (its network bindings are not \
                     built)"
                        .to_owned(),
                ),
                orders: BTreeMap::new(),
            },
            Err(SystemError::Invalid(d) | SystemError::NeedsParticipant(d)) => Checked {
                problems: {
                    // Each file's elements found once, however many problems it has.
                    let mut found = HashMap::new();
                    d.0.iter().map(|d| self.problem(d, &mut found)).collect()
                },
                summary: None,
                orders: BTreeMap::new(),
            },
            Err(other) => Checked {
                problems: vec![Problem {
                    file: None,
                    line: 0,
                    column: 0,
                    message: other.to_string(),
                    path: Vec::new(),
                }],
                summary: None,
                orders: BTreeMap::new(),
            },
        };
    }

    /// A diagnostic with its file relative to the root and the element it concerns.
    /// `found`: each file's [`elements`], found when first needed.
    fn problem(
        &self,
        d: &ndds_runtime::system::Diagnostic,
        found: &mut HashMap<PathBuf, Vec<(usize, Vec<Step>)>>,
    ) -> Problem {
        let mut path_at = |f: &EditFile, line: usize| {
            let elements = found
                .entry(f.rel.clone())
                .or_insert_with(|| elements(&f.text));
            element_at(elements, line)
        };
        let file = d
            .location
            .file
            .strip_prefix(&self.root)
            .map(Path::to_path_buf)
            .ok()
            .or_else(|| {
                let key = overlay_key(&d.location.file);
                key.strip_prefix(&self.root).ok().map(Path::to_path_buf)
            });
        let mut problem = Problem {
            file: file.as_ref().map(|f| f.display().to_string()),
            line: d.location.line,
            column: d.location.column,
            // Paths in messages as the page names files: relative to the root.
            message: match &d.expected {
                Some(e) => format!("{}; expected {e}", d.message),
                None => d.message.clone(),
            }
            .replace(&format!("{}/", self.root.display()), ""),
            path: Vec::new(),
        };
        // A state machine's file is reported where it is named: point into the machine file
        // when the message says where.
        if let Some(machine_file) = machine_file_of(&d.message)
            && let Ok(rel) = self.relative(&machine_file)
            && let Some(f) = self.files.iter().find(|f| f.rel == rel)
        {
            problem.file = Some(rel.display().to_string());
            if let Some((line, column)) = toml_line(&d.message) {
                problem.line = line;
                problem.column = column;
                problem.path = path_at(f, line);
            } else {
                problem.line = 0;
                problem.column = 0;
                problem.path = machine_path(&f.text, &d.message);
            }
            return problem;
        }
        if let Some(rel) = &file
            && let Some(f) = self.files.iter().find(|f| f.rel == *rel)
        {
            problem.path = path_at(f, d.location.line);
        }
        problem
    }

    /// The editor's state for the page: the files (text, parsed data, whether changed), the
    /// components' model for the diagram, the loader's verdict and problems, and the diff of
    /// the unsaved changes.
    pub fn state(&self) -> Json {
        let files: Vec<Json> = self
            .files
            .iter()
            .map(|f| {
                let parsed: Result<toml::Table, _> = f.text.parse::<toml::Table>();
                let (data, error) = match parsed {
                    Ok(t) => (serde_json::to_value(t).unwrap_or(Json::Null), None),
                    Err(e) => (Json::Null, Some(first_line(&e.to_string()))),
                };
                json!({
                    "path": f.rel.display().to_string(),
                    "kind": f.kind,
                    "changed": f.original.as_ref() != Some(&f.text),
                    "new": f.original.is_none(),
                    "text": f.text,
                    "data": data,
                    "error": error,
                    "values": if f.kind == FileKind::Description { value_texts(&f.text) } else { Json::Null },
                })
            })
            .collect();
        json!({
            "root": self.root.display().to_string(),
            "top": self.top.as_ref().map(|t| t.display().to_string()),
            "files": files,
            "ok": self.checked.summary.is_some(),
            "summary": self.checked.summary,
            "problems": self.checked.problems,
            "orders": self.checked.orders,
            "diff": self.diff(),
        })
    }

    /// The unsaved changes as a unified diff.
    pub fn diff(&self) -> String {
        let mut out = String::new();
        for f in &self.files {
            let original = f.original.as_deref().unwrap_or("");
            if original == f.text {
                continue;
            }
            let name = f.rel.display().to_string();
            let diff = similar::TextDiff::from_lines(original, f.text.as_str());
            out.push_str(
                &diff
                    .unified_diff()
                    .context_radius(2)
                    .header(
                        &if f.original.is_some() {
                            format!("a/{name}")
                        } else {
                            "/dev/null".to_owned()
                        },
                        &format!("b/{name}"),
                    )
                    .to_string(),
            );
        }
        out
    }

    /// The text of a file held (relative to the root), for tests and tools.
    pub fn text(&self, file: &str) -> Option<&str> {
        let rel = self.relative(file).ok()?;
        self.files
            .iter()
            .find(|f| f.rel == rel)
            .map(|f| f.text.as_str())
    }

    /// The problems the last check found.
    pub fn problems(&self) -> &[Problem] {
        &self.checked.problems
    }

    /// Whether the system verified at the last check.
    pub fn verifies(&self) -> bool {
        self.checked.summary.is_some()
    }
}

fn plural(n: usize) -> &'static str {
    if n == 1 { "" } else { "s" }
}

fn first_line(text: &str) -> String {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(" ")
        .chars()
        .take(300)
        .collect()
}

fn parse_value(text: &str) -> Result<Value, EditError> {
    text.trim()
        .parse::<Value>()
        .map_err(|e| EditError::Value {
            text: text.to_owned(),
            why: first_line(&e.to_string()),
        })
        .map(|mut v| {
            v.decor_mut().clear();
            v
        })
}

/// The table at `path` (keys of tables, indices into arrays of tables); `create`: missing
/// plain tables on the way are made.
fn table_at<'a>(
    root: &'a mut Table,
    path: &[Step],
    create: bool,
) -> Result<&'a mut Table, EditError> {
    let mut table = root;
    let mut i = 0;
    while i < path.len() {
        let Step::Key(key) = &path[i] else {
            return Err(EditError::Target(format!(
                "{}: an index must follow an array of tables",
                shown(path)
            )));
        };
        if let Some(Step::Index(n)) = path.get(i + 1) {
            let n = *n;
            let Some(array) = table.get_mut(key).and_then(Item::as_array_of_tables_mut) else {
                return Err(EditError::Target(format!(
                    "{}: there is no `[[{key}]]`",
                    shown(path)
                )));
            };
            let len = array.len();
            table = array.get_mut(n).ok_or_else(|| {
                EditError::Target(format!(
                    "{}: there {} only {len} `[[{key}]]`",
                    shown(path),
                    if len == 1 { "is" } else { "are" }
                ))
            })?;
            i += 2;
        } else {
            if create && !table.contains_key(key) {
                table.insert(key, Item::Table(Table::new()));
            }
            table = match table.get_mut(key) {
                Some(Item::Table(t)) => t,
                _ => {
                    return Err(EditError::Target(format!(
                        "{}: `{key}` is not a table",
                        shown(path)
                    )));
                }
            };
            i += 1;
        }
    }
    Ok(table)
}

fn shown(path: &[Step]) -> String {
    let parts: Vec<String> = path
        .iter()
        .map(|s| match s {
            Step::Key(k) => k.clone(),
            Step::Index(i) => i.to_string(),
        })
        .collect();
    format!("`{}`", parts.join("."))
}

fn split_key(path: &[Step]) -> Result<(&[Step], &str), EditError> {
    match path.split_last() {
        Some((Step::Key(key), parent)) => Ok((parent, key)),
        _ => Err(EditError::Target(format!(
            "{}: a path to a key ends in the key's name",
            shown(path)
        ))),
    }
}

fn set(doc: &mut DocumentMut, path: &[Step], value: Option<Value>) -> Result<(), EditError> {
    let (parent, key) = split_key(path)?;
    let table = table_at(doc.as_table_mut(), parent, value.is_some())?;
    match value {
        None => {
            table.remove(key);
        }
        Some(mut value) => match table.get_mut(key) {
            // The key, its place and its comment stay; only the value changes.
            Some(Item::Value(old)) => {
                *value.decor_mut() = old.decor().clone();
                *old = value;
            }
            Some(_) => {
                return Err(EditError::Target(format!(
                    "{}: is a table; edit its keys",
                    shown(path)
                )));
            }
            None => {
                table.insert(key, Item::Value(value));
            }
        },
    }
    Ok(())
}

fn push(doc: &mut DocumentMut, path: &[Step], mut new: Table) -> Result<(), EditError> {
    let (parent, key) = split_key(path)?;
    let table = table_at(doc.as_table_mut(), parent, false)?;
    // A blank line before the new `[[...]]`, as people write them.
    new.decor_mut().set_prefix("\n");
    match table.get_mut(key) {
        None => {
            let mut array = ArrayOfTables::new();
            array.push(new);
            table.insert(key, Item::ArrayOfTables(array));
        }
        Some(Item::ArrayOfTables(array)) => array.push(new),
        Some(_) => {
            return Err(EditError::Target(format!(
                "{}: is not an array of tables",
                shown(path)
            )));
        }
    }
    Ok(())
}

fn remove(doc: &mut DocumentMut, path: &[Step]) -> Result<(), EditError> {
    match path.split_last() {
        Some((Step::Index(n), rest)) => {
            let (parent, key) = split_key(rest)?;
            let table = table_at(doc.as_table_mut(), parent, false)?;
            let Some(array) = table.get_mut(key).and_then(Item::as_array_of_tables_mut) else {
                return Err(EditError::Target(format!(
                    "{}: there is no `[[{key}]]`",
                    shown(path)
                )));
            };
            if *n >= array.len() {
                return Err(EditError::Target(format!(
                    "{}: there are only {} `[[{key}]]`",
                    shown(path),
                    array.len()
                )));
            }
            array.remove(*n);
            if array.is_empty() {
                table.remove(key);
            }
            Ok(())
        }
        _ => set(doc, path, None),
    }
}

/// The files a description's text names: includes (descriptions) and `[[state_machine]]`
/// files (machines), as written (relative to the file).
fn references(text: &str) -> Vec<(String, FileKind)> {
    let Ok(table) = text.parse::<toml::Table>() else {
        return Vec::new();
    };
    let mut out = Vec::new();
    match table.get("include") {
        Some(toml::Value::String(s)) => out.push((s.clone(), FileKind::Description)),
        Some(toml::Value::Array(items)) => {
            for item in items {
                if let toml::Value::String(s) = item {
                    out.push((s.clone(), FileKind::Description));
                }
            }
        }
        _ => {}
    }
    if let Some(toml::Value::Array(machines)) = table.get("state_machine") {
        for m in machines {
            if let Some(toml::Value::String(file)) = m.get("file") {
                out.push((file.clone(), FileKind::Machine));
            }
        }
    }
    out
}

/// Where each element of a file starts: `(line, path)` for every table of an array of tables
/// (`["component", 1]`), every plain table (`["system"]`) and every key in them, in the order
/// written.
fn elements(text: &str) -> Vec<(usize, Vec<Step>)> {
    let Ok(doc) = toml_edit::Document::parse(text) else {
        return Vec::new();
    };
    let starts: Vec<usize> = std::iter::once(0)
        .chain(text.match_indices('\n').map(|(i, _)| i + 1))
        .collect();
    let line_of = |offset: usize| starts.partition_point(|&s| s <= offset).max(1);
    let mut out = Vec::new();
    fn walk(
        table: &Table,
        path: &mut Vec<Step>,
        line_of: &dyn Fn(usize) -> usize,
        out: &mut Vec<(usize, Vec<Step>)>,
    ) {
        for (key, item) in table.iter() {
            let key_span = table.key(key).and_then(|k| k.span());
            path.push(Step::Key(key.to_owned()));
            match item {
                Item::ArrayOfTables(array) => {
                    for (i, t) in array.iter().enumerate() {
                        path.push(Step::Index(i));
                        if let Some(span) = t.span() {
                            out.push((line_of(span.start), path.clone()));
                        }
                        walk(t, path, line_of, out);
                        path.pop();
                    }
                }
                Item::Table(t) => {
                    if let Some(span) = t.span() {
                        out.push((line_of(span.start), path.clone()));
                    }
                    walk(t, path, line_of, out);
                }
                _ => {
                    if let Some(span) = key_span {
                        out.push((line_of(span.start), path.clone()));
                    }
                }
            }
            path.pop();
        }
    }
    walk(doc.as_table(), &mut Vec::new(), &line_of, &mut out);
    out
}

/// The element a problem at `line` concerns, among a file's [`elements`]: the key on that
/// line, else the table it is in.
fn element_at(elements: &[(usize, Vec<Step>)], line: usize) -> Vec<Step> {
    let mut best: Option<&(usize, Vec<Step>)> = None;
    for element in elements {
        let (at, path) = element;
        if *at > line {
            continue;
        }
        let better = match best {
            None => true,
            Some((b, p)) => at > b || (at == b && path.len() > p.len()),
        };
        if better {
            best = Some(element);
        }
    }
    best.map(|(_, path)| path.clone()).unwrap_or_default()
}

/// The machine file a loader message is about (`state machine `FILE`: ...`).
fn machine_file_of(message: &str) -> Option<String> {
    let rest = message.strip_prefix("state machine `")?;
    let end = rest.find("`:")?;
    Some(rest[..end].to_owned())
}

/// `TOML parse error at line L, column C` in a message.
fn toml_line(message: &str) -> Option<(usize, usize)> {
    let rest = &message[message.find("at line ")? + "at line ".len()..];
    let (line, rest) = rest.split_once(", column ")?;
    let column: String = rest.chars().take_while(char::is_ascii_digit).collect();
    Some((line.trim().parse().ok()?, column.parse().ok()?))
}

/// The machine (and transition) a program's message names (``machine `M`, transition N``).
fn machine_path(text: &str, message: &str) -> Vec<Step> {
    let Some(start) = message.find("machine `").map(|i| i + "machine `".len()) else {
        return Vec::new();
    };
    // The first "machine `" is "state machine `FILE`"; the program's own comes after.
    let rest = &message[start..];
    let Some(after_file) = rest.find("machine `").map(|i| i + "machine `".len()) else {
        return Vec::new();
    };
    let rest = &rest[after_file..];
    let Some(end) = rest.find('`') else {
        return Vec::new();
    };
    let name = &rest[..end];
    let Ok(table) = text.parse::<toml::Table>() else {
        return Vec::new();
    };
    let Some(toml::Value::Array(machines)) = table.get("machine") else {
        return Vec::new();
    };
    let Some(index) = machines
        .iter()
        .position(|m| m.get("name").and_then(toml::Value::as_str) == Some(name))
    else {
        return Vec::new();
    };
    let mut path = vec![Step::Key("machine".into()), Step::Index(index)];
    if let Some(t) = rest[end..].strip_prefix("`, transition ") {
        let digits: String = t.chars().take_while(char::is_ascii_digit).collect();
        if let Ok(n) = digits.parse() {
            path.extend([Step::Key("transition".into()), Step::Index(n)]);
        }
    }
    path
}

/// Each array-of-tables entry's values as TOML text (what the page shows in its fields):
/// `{"component": [{"kp": "40.0", ...}, ...], ...}`.
fn value_texts(text: &str) -> Json {
    let Ok(doc) = text.parse::<DocumentMut>() else {
        return Json::Null;
    };
    let mut out = serde_json::Map::new();
    for (key, item) in doc.as_table().iter() {
        let rows: Vec<Json> = match item {
            Item::ArrayOfTables(array) => array.iter().map(table_texts).collect(),
            Item::Table(t) => vec![table_texts(t)],
            _ => continue,
        };
        out.insert(key.to_owned(), Json::Array(rows));
    }
    Json::Object(out)
}

fn table_texts(table: &Table) -> Json {
    let mut row = serde_json::Map::new();
    for (key, item) in table.iter() {
        if let Item::Value(v) = item {
            let mut v = v.clone();
            v.decor_mut().clear();
            row.insert(key.to_owned(), Json::String(v.to_string()));
        }
    }
    Json::Object(row)
}

/// The component types the editor offers: each with its summary and parameters (name, kind,
/// default, doc), and the sections of a description with their keys.
pub fn palette(library: &Registry) -> Json {
    let kind = |k: ParamKind| match k {
        ParamKind::Input => "input",
        ParamKind::Inputs => "inputs",
        ParamKind::Output => "output",
        ParamKind::Number => "number",
        ParamKind::Numbers => "numbers",
        ParamKind::Matrix => "matrix",
        ParamKind::Text => "text",
        ParamKind::File => "file",
        ParamKind::Bool => "bool",
        ParamKind::Table => "table",
    };
    let mut specs: Vec<Json> = library
        .specs()
        .map(|spec| {
            json!({
                "name": spec.name,
                "summary": spec.summary,
                "params": spec.params.iter().map(|p| json!({
                    "name": p.name,
                    "kind": kind(p.kind),
                    "takes": p.kind.describe(),
                    "default": p.default,
                    "doc": p.meaning(),
                    "unit": p.unit,
                    "range": p.range,
                })).collect::<Vec<_>>(),
            })
        })
        .collect();
    specs.sort_by(|a, b| a["name"].as_str().cmp(&b["name"].as_str()));
    let documented: BTreeSet<&str> = library.specs().map(|s| s.name).collect();
    let undocumented: Vec<&str> = library
        .types()
        .map(|(n, _)| n)
        .filter(|n| !documented.contains(n))
        .collect();
    let sections: Vec<Json> = ndds_runtime::system::SECTION_KEYS
        .iter()
        .map(|s| {
            json!({
                "name": s.name,
                "keys": s.keys.iter().map(|k| json!({"name": k.name, "takes": k.takes})).collect::<Vec<_>>(),
            })
        })
        .collect();
    json!({"components": specs, "undocumented": undocumented, "sections": sections})
}

#[cfg(test)]
mod tests;
