//! `[[state_machine]]`: a state machine program (the format of docs/fsm.md) in a file of its
//! own, relative to the file that names it.

use std::path::{Path, PathBuf};

use super::Description;
use super::keys::{Key, Section, TEXT};
use super::reader::Reader;
use crate::fsm::Program;
use crate::system::source::{self, Diagnostics, Location};

pub(super) const SECTION: Section =
    Section::list("state_machine", &[Key::new("file", TEXT)], |d, r, _, p| {
        read(d, r, p)
    });

pub(crate) struct MachineDecl {
    pub at: Location,
    pub file: PathBuf,
    pub program: Program,
}

fn read(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let Some(name) = r.required_text("file", p) else {
        return;
    };
    // Relative to the file it is written in.
    let path =
        r.at.file
            .parent()
            .map_or_else(|| PathBuf::from(&name.name), |dir| dir.join(&name.name));
    let text = match source::from_overlay(&d.overlay, &path) {
        Some(text) if text.len() as u64 > source::MAX_FILE_BYTES => {
            Err(format!("`{}` is too large", path.display()))
        }
        Some(text) => Ok(text.clone()),
        None => read_text(&path),
    };
    let program = match text {
        Err(problem) => return p.push(&name.at, problem),
        Ok(text) => Program::from_toml(&text),
    };
    match program {
        Ok(program) => d.machines.push(MachineDecl {
            at: name.at,
            file: path,
            program,
        }),
        Err(err) => p.push(
            &name.at,
            format!("state machine `{}`: {err}", path.display()),
        ),
    }
}

/// The text of a regular file of at most [`source::MAX_FILE_BYTES`], else what is wrong.
fn read_text(path: &Path) -> Result<String, String> {
    let shown = path.display();
    let text = match std::fs::metadata(path) {
        Ok(m) if !m.is_file() => return Err(format!("`{shown}` is not a regular file")),
        Ok(m) if m.len() > source::MAX_FILE_BYTES => return Err(format!("`{shown}` is too large")),
        Ok(_) => source::read_bounded(path),
        Err(e) => Err(e),
    };
    text.map_err(|err| format!("cannot read `{shown}`: {err}"))
}
