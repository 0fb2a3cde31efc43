//! `[[state_machine]]`: a state machine program (the format of docs/fsm.md) in a file of its
//! own, relative to the file that names it.

use std::path::PathBuf;

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
    let text = source::file_text(&path, &path, source::from_overlay(&d.overlay, &path));
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
