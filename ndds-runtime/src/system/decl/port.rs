//! `[[port]]`: a port (docs/ports.md) owned by the system, serving configuration switches or
//! a state machine's stimuli.

use super::keys::{Key, Section, TEXT};
use super::reader::Reader;
use super::{Description, Named};
use crate::system::source::{Diagnostics, Location};
use ndds_client::ports::Restrictions;

pub(super) const SECTION: Section = Section::list(
    "port",
    &[
        Key::new("name", TEXT),
        Key::new("serves", SERVES),
        Key::new("machine", "the state machine the stimuli are for"),
        Key::new("users", "a list of who may use it"),
        Key::new("max_users", "how many may use it at once"),
        Key::new("timeout", "seconds"),
        Key::new("priority", "an integer"),
    ],
    |d, r, _, p| read(d, r, p),
);

/// What a port may serve.
const SERVES: &str = "\"configuration\" or \"stimuli\"";

/// What a port declared in a description file answers.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Serves {
    /// Requests are configuration names; the system switches to them.
    Configuration,
    /// Requests are stimuli (`NAME` or `NAME=VALUE`) for this state machine.
    Stimuli(String),
}

pub(crate) struct PortDecl {
    pub name: Named,
    pub serves: Serves,
    pub machine_at: Option<Location>,
    pub restrictions: Restrictions,
}

fn read(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let name = r.required_text("name", p);
    let serves = r.required_text("serves", p);
    let machine = r.text("machine", p);
    let serves = serves.and_then(|s| served(&s, machine.as_ref(), r, p));
    let restrictions = restrictions(r, p);
    let name = name.and_then(|n| checked_name(n, p));
    if let (Some(name), Some(serves)) = (name, serves) {
        d.ports.push(PortDecl {
            name,
            serves,
            machine_at: machine.map(|m| m.at),
            restrictions,
        });
    }
}

fn served(
    serves: &Named,
    machine: Option<&Named>,
    r: &Reader<'_>,
    p: &mut Diagnostics,
) -> Option<Serves> {
    match serves.name.as_str() {
        "configuration" => Some(Serves::Configuration),
        "stimuli" => {
            if machine.is_none() {
                r.missing("machine", p);
            }
            machine.map(|m| Serves::Stimuli(m.name.clone()))
        }
        other => {
            p.expected(&serves.at, format!("a port cannot serve `{other}`"), SERVES);
            None
        }
    }
}

fn restrictions(r: &Reader<'_>, p: &mut Diagnostics) -> Restrictions {
    let mut restrictions = Restrictions {
        users: r.texts("users", p).into_iter().map(|n| n.name).collect(),
        ..Restrictions::default()
    };
    restrictions.max_users = r
        .integer("max_users", (1, u32::MAX as i64), p)
        .map(|n| n as u32);
    restrictions.timeout_ms = r.seconds("timeout", p).map(|t| t.as_millis() as u64);
    if let Some(prio) = r.integer("priority", (i32::MIN as i64, i32::MAX as i64), p) {
        restrictions.priority = Some(prio as i32);
    }
    restrictions
}

/// `name`, if ports can live under `port/NAME/...`.
fn checked_name(name: Named, p: &mut Diagnostics) -> Option<Named> {
    if !name.name.contains('/') && !name.name.chars().any(char::is_control) {
        return Some(name);
    }
    p.expected(
        &name.at,
        format!("bad port name `{}`", name.name),
        "a name without `/` or control characters (ports live under port/NAME/...)",
    );
    None
}
