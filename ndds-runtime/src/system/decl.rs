//! From parsed files to checked declarations: every section, key and value of a description
//! is checked here, and every problem is reported where it was written.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::time::Duration;

use nalgebra::DMatrix;

use super::source::{Diagnostics, Location, Raw, RawTable, RawValue, SourceFile};
use crate::fsm::{ActionRef, Program, Stimulus};
use crate::{
    Clock, ComponentSpec, CsMat, HabitatOptions, MAX_RATE_HZ, MIN_RATE_HZ, ParamKind, ParamValue,
    Params,
};
use ndds_client::ports::Restrictions;
use ndds_client::{ConsumerQos, ProducerQos, Reliability};

/// The top-level keys of a description file.
pub const SECTIONS: &[&str] = &[
    "include",
    "system",
    "habitat",
    "mat",
    "component",
    "configuration",
    "subscribe",
    "publish",
    "rate_transition",
    "state_machine",
    "trigger",
    "port",
];

/// Keys of each section (the reference in docs/description-files.md is checked against it).
pub const SECTION_KEYS: &[(&str, &[&str])] = &[
    (
        "system",
        &["name", "configuration", "display", "description"],
    ),
    (
        "habitat",
        &[
            "name",
            "rate",
            "clock",
            "topic",
            "priority",
            "cpu",
            "stats_interval",
        ],
    ),
    (
        "mat",
        &["name", "value", "rows", "cols", "row_units", "col_units"],
    ),
    ("component", &["name", "type", "habitat", "group"]),
    ("configuration", &["name", "groups"]),
    (
        "subscribe",
        &[
            "mat",
            "topic",
            "habitat",
            "shape",
            "reliable",
            "deadline",
            "min_separation",
        ],
    ),
    (
        "publish",
        &[
            "mat",
            "topic",
            "habitat",
            "reliable",
            "strength",
            "persistence",
        ],
    ),
    ("rate_transition", &["name", "from", "to"]),
    ("state_machine", &["file"]),
    (
        "trigger",
        &["habitat", "input", "above", "below", "machine", "stimulus"],
    ),
    (
        "port",
        &[
            "name",
            "serves",
            "machine",
            "users",
            "max_users",
            "timeout",
            "priority",
        ],
    ),
];

fn keys_of(section: &str) -> &'static [&'static str] {
    SECTION_KEYS
        .iter()
        .find(|(s, _)| *s == section)
        .map_or(&[], |(_, k)| k)
}

/// Most elements of a subscribed CSMat (32 MiB of `f64`).
pub const MAX_SUBSCRIBED_ELEMENTS: usize = 1 << 22;

/// A name with where it was written.
#[derive(Clone, Debug)]
pub(crate) struct Named {
    pub name: String,
    pub at: Location,
}

pub(crate) struct HabitatDecl {
    pub name: Named,
    pub options: HabitatOptions,
}

pub(crate) struct MatDecl {
    pub name: Named,
    pub value: CsMat,
}

pub(crate) struct ComponentDecl {
    pub name: Named,
    pub type_name: Named,
    pub habitat: Named,
    /// `(category, group)`.
    pub group: Option<(String, String, Location)>,
    pub params: Params,
    /// CSMats named by parameters: name, where, and how the component uses it.
    pub mats: Vec<(String, Location, ParamKind)>,
    /// Where each parameter was written.
    pub param_at: BTreeMap<String, Location>,
}

pub(crate) struct ConfigurationDecl {
    pub name: Named,
    pub groups: Vec<(String, String, Location)>,
}

pub(crate) struct SubscribeDecl {
    pub at: Location,
    pub mat: Named,
    pub topic: String,
    pub habitat: Named,
    pub shape: (usize, usize),
    pub qos: ConsumerQos,
}

pub(crate) struct PublishDecl {
    pub at: Location,
    pub mat: Named,
    pub topic: String,
    pub habitat: Named,
    pub qos: ProducerQos,
}

pub(crate) struct RateDecl {
    pub name: Named,
    pub from: (Named, Named),
    pub to: (Named, Named),
}

pub(crate) struct MachineDecl {
    pub at: Location,
    pub file: PathBuf,
    pub program: Program,
}

pub(crate) struct TriggerDecl {
    pub at: Location,
    pub habitat: Named,
    pub input: Named,
    pub above: Option<f64>,
    pub below: Option<f64>,
    pub machine: Named,
    pub stimulus: Stimulus,
}

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

/// A whole description, checked.
#[derive(Default)]
pub(crate) struct Description {
    pub name: Option<Named>,
    pub configuration: Option<Named>,
    pub display: Vec<Named>,
    pub description: Option<String>,
    pub habitats: Vec<HabitatDecl>,
    pub mats: Vec<MatDecl>,
    pub components: Vec<ComponentDecl>,
    pub configurations: Vec<ConfigurationDecl>,
    pub subscribes: Vec<SubscribeDecl>,
    pub publishes: Vec<PublishDecl>,
    pub rates: Vec<RateDecl>,
    pub machines: Vec<MachineDecl>,
    pub triggers: Vec<TriggerDecl>,
    pub ports: Vec<PortDecl>,
    /// Where the top file starts.
    pub start: Option<Location>,
    /// Habitats declared with a problem (reported): references to them are not reported
    /// again as unknown.
    pub broken_habitats: Vec<String>,
}

/// Reads values out of one table, reporting what is wrong with each.
struct Reader<'a> {
    table: &'a RawTable,
    at: Location,
    what: String,
}

impl<'a> Reader<'a> {
    fn new(raw: &'a Raw, what: &str, p: &mut Diagnostics) -> Option<Self> {
        match &raw.value {
            RawValue::Table(table) => Some(Self {
                table,
                at: raw.at.clone(),
                what: what.to_owned(),
            }),
            other => {
                p.expected(&raw.at, format!("{what} is {}", other.kind()), "a table");
                None
            }
        }
    }

    /// Reports keys not in `allowed`.
    fn known_keys(&self, allowed: &[&str], p: &mut Diagnostics) {
        for (key, at, _) in &self.table.entries {
            if !allowed.contains(&key.as_str()) {
                p.expected(
                    at,
                    format!("unknown key `{key}` in {}", self.what),
                    format!("one of {}{}", list(allowed), suggest(key, allowed)),
                );
            }
        }
    }

    fn raw(&self, key: &str) -> Option<&'a Raw> {
        self.table.get(key)
    }

    fn missing(&self, key: &str, expected: &str, p: &mut Diagnostics) {
        p.expected(
            &self.at,
            format!("{} has no `{key}`", self.what),
            format!("`{key} = ` {expected}"),
        );
    }

    fn text(&self, key: &str, p: &mut Diagnostics) -> Option<Named> {
        let raw = self.raw(key)?;
        match &raw.value {
            RawValue::Text(s) if !s.trim().is_empty() => Some(Named {
                name: s.clone(),
                at: raw.at.clone(),
            }),
            RawValue::Text(_) => {
                p.expected(&raw.at, format!("`{key}` is empty"), "a non-empty string");
                None
            }
            _ => wrong_kind(raw, key, "a string", p),
        }
    }

    fn required_text(&self, key: &str, p: &mut Diagnostics) -> Option<Named> {
        if self.raw(key).is_none() {
            self.missing(key, "\"...\"", p);
            return None;
        }
        self.text(key, p)
    }

    fn number(&self, key: &str, p: &mut Diagnostics) -> Option<f64> {
        let raw = self.raw(key)?;
        number(raw, key, p)
    }

    fn integer(&self, key: &str, range: (i64, i64), p: &mut Diagnostics) -> Option<i64> {
        let raw = self.raw(key)?;
        match raw.value {
            RawValue::Integer(n) if (range.0..=range.1).contains(&n) => Some(n),
            RawValue::Integer(n) => {
                p.expected(
                    &raw.at,
                    format!("`{key}` is {n}"),
                    format!("an integer from {} to {}", range.0, range.1),
                );
                None
            }
            _ => wrong_kind(raw, key, "an integer", p),
        }
    }

    fn boolean(&self, key: &str, p: &mut Diagnostics) -> Option<bool> {
        let raw = self.raw(key)?;
        match raw.value {
            RawValue::Bool(b) => Some(b),
            _ => wrong_kind(raw, key, "true or false", p),
        }
    }

    /// Seconds, as a positive finite number.
    fn seconds(&self, key: &str, p: &mut Diagnostics) -> Option<Duration> {
        let raw = self.raw(key)?;
        let x = number(raw, key, p)?;
        if x.is_finite() && x > 0.0 && x <= 1e9 {
            Some(Duration::from_secs_f64(x))
        } else {
            p.expected(
                &raw.at,
                format!("`{key}` is {x}"),
                "a positive number of seconds",
            );
            None
        }
    }

    fn texts(&self, key: &str, p: &mut Diagnostics) -> Vec<Named> {
        let Some(raw) = self.raw(key) else {
            return Vec::new();
        };
        texts(raw, key, p)
    }
}

/// Reports that `key` holds the wrong kind of value.
fn wrong_kind<T>(raw: &Raw, key: &str, expected: &str, p: &mut Diagnostics) -> Option<T> {
    p.expected(
        &raw.at,
        format!("`{key}` is {}", raw.value.kind()),
        expected,
    );
    None
}

fn number(raw: &Raw, key: &str, p: &mut Diagnostics) -> Option<f64> {
    match raw.value {
        RawValue::Integer(n) => Some(n as f64),
        RawValue::Float(x) if x.is_finite() => Some(x),
        RawValue::Float(x) => {
            p.expected(&raw.at, format!("`{key}` is {x}"), "a finite number");
            None
        }
        _ => wrong_kind(raw, key, "a number", p),
    }
}

fn texts(raw: &Raw, key: &str, p: &mut Diagnostics) -> Vec<Named> {
    let items: Vec<&Raw> = match &raw.value {
        RawValue::Array(items) => items.iter().collect(),
        RawValue::Text(_) => vec![raw],
        _ => return wrong_kind(raw, key, "a list of strings", p).unwrap_or_default(),
    };
    let mut out = Vec::new();
    for item in items {
        match &item.value {
            RawValue::Text(s) if !s.trim().is_empty() => out.push(Named {
                name: s.clone(),
                at: item.at.clone(),
            }),
            other => p.expected(
                &item.at,
                format!("an element of `{key}` is {}", other.kind()),
                "a non-empty string",
            ),
        }
    }
    out
}

/// The numbers of an array (a number is a list of one).
fn numbers(raw: &Raw, key: &str, p: &mut Diagnostics) -> Option<Vec<f64>> {
    match &raw.value {
        RawValue::Integer(_) | RawValue::Float(_) => number(raw, key, p).map(|x| vec![x]),
        RawValue::Array(items) => {
            let mut out = Vec::with_capacity(items.len());
            let mut ok = true;
            for item in items {
                match number(item, key, p) {
                    Some(x) => out.push(x),
                    None => ok = false,
                }
            }
            ok.then_some(out)
        }
        _ => wrong_kind(raw, key, "a number or a list of numbers", p),
    }
}

/// A matrix: an array of equally long rows; a list of numbers is a column, a number 1 × 1.
fn matrix(raw: &Raw, key: &str, p: &mut Diagnostics) -> Option<DMatrix<f64>> {
    let RawValue::Array(rows) = &raw.value else {
        return numbers(raw, key, p).map(|xs| DMatrix::from_column_slice(xs.len(), 1, &xs));
    };
    if rows.is_empty() || !matches!(rows[0].value, RawValue::Array(_)) {
        return numbers(raw, key, p).map(|xs| DMatrix::from_column_slice(xs.len(), 1, &xs));
    }
    let mut data = Vec::new();
    let mut cols = None;
    for row in rows {
        if !matches!(row.value, RawValue::Array(_)) {
            p.expected(
                &row.at,
                format!("a row of `{key}` is {}", row.value.kind()),
                "a list of numbers (every row an array)",
            );
            return None;
        }
        let values = numbers(row, key, p)?;
        match cols {
            None => cols = Some(values.len()),
            Some(n) if n != values.len() => {
                p.expected(
                    &row.at,
                    format!("a row of `{key}` has {} numbers", values.len()),
                    format!("{n}, like the first row"),
                );
                return None;
            }
            Some(_) => {}
        }
        data.extend(values);
    }
    let cols = cols.unwrap_or(0);
    if cols == 0 {
        p.expected(
            &raw.at,
            format!("`{key}` has empty rows"),
            "at least one column",
        );
        return None;
    }
    Some(DMatrix::from_row_slice(rows.len(), cols, &data))
}

/// Converts a parameter value without a spec: numbers, lists, matrices, strings, tables.
fn generic(raw: &Raw, key: &str, p: &mut Diagnostics) -> Option<ParamValue> {
    Some(match &raw.value {
        RawValue::Integer(_) | RawValue::Float(_) => ParamValue::Number(number(raw, key, p)?),
        RawValue::Text(s) => ParamValue::Text(s.clone()),
        RawValue::Bool(b) => ParamValue::Bool(*b),
        RawValue::Array(items) => match items.first().map(|i| &i.value) {
            Some(RawValue::Text(_)) => {
                ParamValue::Texts(texts(raw, key, p).into_iter().map(|n| n.name).collect())
            }
            Some(RawValue::Array(_)) => ParamValue::Matrix(matrix(raw, key, p)?),
            _ => ParamValue::Numbers(numbers(raw, key, p)?),
        },
        RawValue::Table(table) => {
            let mut params = Params::new();
            for (k, _, v) in &table.entries {
                params.0.insert(k.clone(), generic(v, k, p)?);
            }
            ParamValue::Table(params)
        }
        RawValue::Datetime => {
            p.expected(
                &raw.at,
                format!("`{key}` is a date-time"),
                "a number, string or list",
            );
            return None;
        }
    })
}

/// Converts a parameter value as its spec says.
fn typed(raw: &Raw, key: &str, kind: ParamKind, p: &mut Diagnostics) -> Option<ParamValue> {
    let wrong = |p: &mut Diagnostics| {
        p.expected(
            &raw.at,
            format!("parameter `{key}` is {}", raw.value.kind()),
            kind.describe(),
        );
        None
    };
    match kind {
        ParamKind::Number => match raw.value {
            RawValue::Integer(_) | RawValue::Float(_) => {
                number(raw, key, p).map(ParamValue::Number)
            }
            _ => wrong(p),
        },
        ParamKind::Numbers => match raw.value {
            RawValue::Integer(_) | RawValue::Float(_) | RawValue::Array(_) => {
                numbers(raw, key, p).map(ParamValue::Numbers)
            }
            _ => wrong(p),
        },
        ParamKind::Matrix => match raw.value {
            RawValue::Integer(_) | RawValue::Float(_) | RawValue::Array(_) => {
                matrix(raw, key, p).map(ParamValue::Matrix)
            }
            _ => wrong(p),
        },
        ParamKind::File => match &raw.value {
            RawValue::Text(s) if !s.trim().is_empty() => {
                // Relative to the file it is written in, like includes.
                let dir = raw.at.file.parent().unwrap_or(std::path::Path::new(""));
                Some(ParamValue::Text(dir.join(s).to_string_lossy().into_owned()))
            }
            _ => wrong(p),
        },
        ParamKind::Text | ParamKind::Input | ParamKind::Output => match &raw.value {
            RawValue::Text(s) if !s.trim().is_empty() => Some(ParamValue::Text(s.clone())),
            _ => wrong(p),
        },
        ParamKind::Inputs => match &raw.value {
            RawValue::Text(_) | RawValue::Array(_) => {
                let names = texts(raw, key, p);
                (!names.is_empty())
                    .then(|| ParamValue::Texts(names.into_iter().map(|n| n.name).collect()))
                    .or_else(|| {
                        p.expected(&raw.at, format!("`{key}` is empty"), "at least one CSMat");
                        None
                    })
            }
            _ => wrong(p),
        },
        ParamKind::Bool => match raw.value {
            RawValue::Bool(b) => Some(ParamValue::Bool(b)),
            _ => wrong(p),
        },
        ParamKind::Table => match raw.value {
            RawValue::Table(_) => generic(raw, key, p),
            _ => wrong(p),
        },
    }
}

/// Names a message lists at most.
const LISTED: usize = 12;
/// Above this many known names, no "did you mean" (each would cost a comparison with all).
const SUGGESTED_FROM: usize = 256;

/// `"a", "b" or "c"` for messages (at most [`LISTED`] names, then how many more).
pub(crate) fn list<S: AsRef<str>>(items: &[S]) -> String {
    let quoted: Vec<String> = items
        .iter()
        .take(LISTED)
        .map(|s| format!("`{}`", s.as_ref()))
        .collect();
    let text = match quoted.len() {
        0 => "nothing".to_owned(),
        1 => quoted[0].clone(),
        n => format!("{} or {}", quoted[..n - 1].join(", "), quoted[n - 1]),
    };
    match items.len().saturating_sub(LISTED) {
        0 => text,
        more => format!("{text} ({more} more)"),
    }
}

/// ` (did you mean `x`?)` when a known name is close to `name` (the closest, by
/// [`ndds_core::suggest`]'s rule, which the command line uses too).
pub(crate) fn suggest<S: AsRef<str>>(name: &str, known: &[S]) -> String {
    if known.len() > SUGGESTED_FROM {
        return String::new();
    }
    ndds_core::suggest::suggest(name, known)
        .first()
        .map(|k| format!(" (did you mean `{k}`?)"))
        .unwrap_or_default()
}

fn category_group(named: &Named, p: &mut Diagnostics) -> Option<(String, String, Location)> {
    match named.name.split_once('/') {
        Some((c, g)) if !c.is_empty() && !g.is_empty() && !g.contains('/') => {
            Some((c.to_owned(), g.to_owned(), named.at.clone()))
        }
        _ => {
            p.expected(
                &named.at,
                format!("group `{}` does not name its category", named.name),
                "\"CATEGORY/GROUP\", e.g. \"controllers/PD\"",
            );
            None
        }
    }
}

/// The documented parameters of a component type: `Ok(None)` for a type registered without
/// a spec, `Err(known types)` for no such type.
pub(crate) type SpecLookup<'a> =
    dyn Fn(&str) -> Result<Option<&'static ComponentSpec>, Vec<String>> + 'a;

/// Checks every section of every file. `spec` gives the documented parameters of a component
/// type (`Ok(None)`: a type registered without a spec; `Err(known)`: no such type).
pub(crate) fn describe(
    files: &[SourceFile],
    spec: &SpecLookup<'_>,
    p: &mut Diagnostics,
) -> Description {
    let mut d = Description {
        start: files.last().map(|f| f.start.clone()),
        ..Description::default()
    };
    // Included files come first, the top file last: its [system] keys win.
    for file in files {
        for (key, at, raw) in &file.top.entries {
            let section = key.as_str();
            if !SECTIONS.contains(&section) {
                p.expected(
                    at,
                    format!("unknown section `{key}`"),
                    format!("one of {}{}", list(SECTIONS), suggest(key, SECTIONS)),
                );
                continue;
            }
            match section {
                "include" => {} // resolved while reading
                "system" => system(&mut d, raw, p),
                _ => {
                    let RawValue::Array(entries) = &raw.value else {
                        p.expected(
                            at,
                            format!("`{section}` is {}", raw.value.kind()),
                            format!("a list of tables: `[[{section}]]`"),
                        );
                        continue;
                    };
                    for entry in entries {
                        let what = format!("[[{section}]]");
                        let Some(r) = Reader::new(entry, &what, p) else {
                            continue;
                        };
                        if section != "component" {
                            r.known_keys(keys_of(section), p);
                        }
                        match section {
                            "habitat" => habitat(&mut d, &r, p),
                            "mat" => mat(&mut d, &r, p),
                            "component" => component(&mut d, &r, spec, p),
                            "configuration" => configuration(&mut d, &r, p),
                            "subscribe" => subscribe(&mut d, &r, p),
                            "publish" => publish(&mut d, &r, p),
                            "rate_transition" => rate(&mut d, &r, p),
                            "state_machine" => machine(&mut d, &r, &file.path, p),
                            "trigger" => trigger(&mut d, &r, p),
                            "port" => port(&mut d, &r, p),
                            _ => unreachable!("SECTIONS lists every section handled"),
                        }
                    }
                }
            }
        }
    }
    cross_check(&d, p);
    d
}

fn system(d: &mut Description, raw: &Raw, p: &mut Diagnostics) {
    let Some(r) = Reader::new(raw, "[system]", p) else {
        return;
    };
    r.known_keys(keys_of("system"), p);
    // A later file (the including one) overrides what an earlier one set.
    if let Some(name) = r.text("name", p) {
        if name.name.contains('/')
            || name
                .name
                .chars()
                .any(|c| c.is_whitespace() || c.is_control())
        {
            p.expected(
                &name.at,
                format!("bad system name `{}`", name.name),
                "a name without `/`, spaces or control characters (it names topics cs/NAME/...)",
            );
        } else {
            d.name = Some(name);
        }
    }
    if let Some(conf) = r.text("configuration", p) {
        d.configuration = Some(conf);
    }
    if let Some(text) = r.text("description", p) {
        d.description = Some(text.name);
    }
    if r.raw("display").is_some() {
        d.display = r.texts("display", p);
    }
}

fn habitat(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let name = r.required_text("name", p);
    let rate = match r.raw("rate") {
        None => {
            r.missing("rate", "the sample rate in Hz", p);
            None
        }
        Some(raw) => number(raw, "rate", p).and_then(|hz| {
            if (MIN_RATE_HZ..=MAX_RATE_HZ).contains(&hz) {
                Some(hz)
            } else {
                p.expected(
                    &raw.at,
                    format!("`rate` is {hz} Hz"),
                    format!("a rate from {MIN_RATE_HZ:.6} to {MAX_RATE_HZ} Hz"),
                );
                None
            }
        }),
    };
    let clock = match r.text("clock", p) {
        None => Some(Clock::Timer),
        Some(c) => match c.name.as_str() {
            "timer" => Some(Clock::Timer),
            "manual" => Some(Clock::Manual),
            "topic" => match r.text("topic", p) {
                Some(topic) => Some(Clock::Topic(topic.name)),
                None => {
                    r.missing("topic", "the topic whose u64 ticks clock it", p);
                    None
                }
            },
            other => {
                p.expected(
                    &c.at,
                    format!("unknown clock `{other}`"),
                    "\"timer\", \"manual\" or \"topic\"",
                );
                None
            }
        },
    };
    let priority = r.integer("priority", (1, 99), p);
    let cpu = r.integer("cpu", (0, 4095), p);
    let interval = r.seconds("stats_interval", p);
    if let Some(raw) = r.raw("stats_interval")
        && interval.is_some_and(|i| !(0.01..=3600.0).contains(&i.as_secs_f64()))
    {
        p.expected(
            &raw.at,
            "`stats_interval` out of range",
            "0.01 to 3600 seconds",
        );
    }
    if let Some(name) = &name
        && (rate.is_none() || clock.is_none())
    {
        d.broken_habitats.push(name.name.clone());
    }
    if let (Some(name), Some(rate), Some(clock)) = (name, rate, clock) {
        let mut options = HabitatOptions::rate(rate).clock(clock);
        options.realtime_priority = priority.map(|x| x as i32);
        options.cpu = cpu.map(|x| x as usize);
        if let Some(i) = interval {
            options.stats_interval = i;
        }
        d.habitats.push(HabitatDecl { name, options });
    }
}

fn mat(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let name = r.required_text("name", p);
    let value = match r.raw("value") {
        None => {
            r.missing(
                "value",
                "a number, a list (a column) or an array of rows",
                p,
            );
            None
        }
        Some(raw) => matrix(raw, "value", p),
    };
    let (Some(name), Some(value)) = (name, value) else {
        return;
    };
    if value.is_empty() {
        if let Some(raw) = r.raw("value") {
            p.expected(&raw.at, "`value` is empty", "at least one number");
        }
        return;
    }
    let mut mat = CsMat::from_matrix(&name.name, value);
    for (axis, names_key, units_key) in [
        ("row", "rows", "row_units"),
        ("column", "cols", "col_units"),
    ] {
        let names = r.texts(names_key, p);
        let units = r.texts(units_key, p);
        if names.is_empty() && units.is_empty() {
            continue;
        }
        let count = if axis == "row" {
            mat.rows()
        } else {
            mat.cols()
        };
        let key_at = r
            .raw(names_key)
            .or(r.raw(units_key))
            .map_or(r.at.clone(), |x| x.at.clone());
        if names.len() != count || (!units.is_empty() && units.len() != count) {
            p.expected(
                &key_at,
                format!(
                    "CSMat `{}` has {count} {axis}s but {} {axis} names and {} units",
                    name.name,
                    names.len(),
                    units.len()
                ),
                format!("{count} names (`{names_key}`) and {count} units (`{units_key}`) or none"),
            );
            continue;
        }
        let pairs: Vec<(&str, &str)> = names
            .iter()
            .enumerate()
            .map(|(i, n)| {
                (
                    n.name.as_str(),
                    units.get(i).map_or("", |u| u.name.as_str()),
                )
            })
            .collect();
        let result = if axis == "row" {
            mat.clone().with_row_fields(pairs)
        } else {
            mat.clone().with_col_fields(pairs)
        };
        match result {
            Ok(m) => mat = m,
            Err(err) => p.push(&key_at, err.to_string()),
        }
    }
    d.mats.push(MatDecl { name, value: mat });
}

fn component(d: &mut Description, r: &Reader<'_>, spec_of: &SpecLookup<'_>, p: &mut Diagnostics) {
    let reserved = keys_of("component");
    let name = r.required_text("name", p);
    let type_name = r.required_text("type", p);
    let habitat = r.required_text("habitat", p);
    let group = r.text("group", p).and_then(|g| category_group(&g, p));
    let (Some(name), Some(type_name), Some(habitat)) = (name, type_name, habitat) else {
        return;
    };
    let spec = match spec_of(&type_name.name) {
        Ok(spec) => spec,
        Err(known) => {
            p.expected(
                &type_name.at,
                format!("unknown component type `{}`", type_name.name),
                if known.is_empty() {
                    "a registered type, but this runtime has none: load with a component \
                     library (ndds_components::library() for the built-in one)"
                        .to_owned()
                } else {
                    format!(
                        "a registered type{}: {}",
                        suggest(&type_name.name, &known),
                        known.join(", ")
                    )
                }
                .chars()
                .take(2048)
                .collect::<String>(),
            );
            // Its string parameters may be outputs: count them as provided, so one mistake
            // gives one message.
            let mats = r
                .table
                .entries
                .iter()
                .filter(|(k, _, _)| !reserved.contains(&k.as_str()))
                .filter_map(|(_, _, raw)| match &raw.value {
                    RawValue::Text(s) => Some((s.clone(), raw.at.clone(), ParamKind::Output)),
                    _ => None,
                })
                .collect();
            d.components.push(ComponentDecl {
                name,
                type_name,
                habitat,
                group,
                params: Params::new(),
                mats,
                param_at: BTreeMap::new(),
            });
            return;
        }
    };
    let mut params = Params::new();
    let mut mats = Vec::new();
    let mut param_at = BTreeMap::new();
    let mut ok = true;
    for (key, key_at, raw) in &r.table.entries {
        if reserved.contains(&key.as_str()) {
            continue;
        }
        param_at.insert(key.clone(), raw.at.clone());
        let value = match spec {
            None => {
                // Undocumented type: any string may name a CSMat it writes.
                if let RawValue::Text(s) = &raw.value {
                    mats.push((s.clone(), raw.at.clone(), ParamKind::Output));
                }
                generic(raw, key, p)
            }
            Some(spec) => match spec.param(key) {
                None => {
                    let known: Vec<&str> = spec.params.iter().map(|s| s.name).collect();
                    p.expected(
                        key_at,
                        format!("`{}` has no parameter `{key}`", spec.name),
                        format!(
                            "one of {}{}, or {}",
                            list(&known),
                            suggest(key, &known),
                            list(reserved)
                        ),
                    );
                    ok = false;
                    continue;
                }
                Some(param) => {
                    let value = typed(raw, key, param.kind, p);
                    match (&value, param.kind) {
                        (
                            Some(ParamValue::Text(mat)),
                            kind @ (ParamKind::Input | ParamKind::Output),
                        ) => mats.push((mat.clone(), raw.at.clone(), kind)),
                        (Some(ParamValue::Texts(_)), ParamKind::Inputs) => {
                            for n in texts(raw, key, &mut Diagnostics::default()) {
                                mats.push((n.name, n.at, ParamKind::Input));
                            }
                        }
                        _ => {}
                    }
                    value
                }
            },
        };
        match value {
            Some(v) => {
                params.0.insert(key.clone(), v);
            }
            None => ok = false,
        }
    }
    if let Some(spec) = spec {
        for param in spec.params {
            if param.default.is_none() && !params.0.contains_key(param.name) && ok {
                p.expected(
                    &name.at,
                    format!(
                        "component `{}` ({}) has no `{}`",
                        name.name, spec.name, param.name
                    ),
                    format!("`{} = ` {}", param.name, param.kind.describe()),
                );
                ok = false;
            }
        }
    }
    // Pushed even when a parameter is wrong (the problem is reported and nothing is built):
    // its outputs still count as provided.
    {
        d.components.push(ComponentDecl {
            name,
            type_name,
            habitat,
            group,
            params,
            mats,
            param_at,
        });
    }
}

fn configuration(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let name = r.required_text("name", p);
    if r.raw("groups").is_none() {
        r.missing("groups", "a list of \"CATEGORY/GROUP\"", p);
    }
    let groups: Vec<_> = r
        .texts("groups", p)
        .iter()
        .filter_map(|g| category_group(g, p))
        .collect();
    if let Some(name) = name {
        d.configurations.push(ConfigurationDecl { name, groups });
    }
}

fn shape(r: &Reader<'_>, p: &mut Diagnostics) -> Option<(usize, usize)> {
    let Some(raw) = r.raw("shape") else {
        r.missing("shape", "[ROWS, COLS]", p);
        return None;
    };
    let xs = numbers(raw, "shape", p)?;
    match xs.as_slice() {
        [rows, cols]
            if rows.fract() == 0.0
                && cols.fract() == 0.0
                && (1.0..=65536.0).contains(rows)
                && (1.0..=65536.0).contains(cols)
                && rows * cols <= MAX_SUBSCRIBED_ELEMENTS as f64 =>
        {
            Some((*rows as usize, *cols as usize))
        }
        _ => {
            p.expected(
                &raw.at,
                "`shape` is not two whole numbers of a usable size",
                format!(
                    "[ROWS, COLS], each 1 to 65536, at most {MAX_SUBSCRIBED_ELEMENTS} elements"
                ),
            );
            None
        }
    }
}

fn subscribe(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let mat = r.required_text("mat", p);
    let topic = r.required_text("topic", p);
    let habitat = r.required_text("habitat", p);
    let shape = shape(r, p);
    let mut qos = ConsumerQos::default();
    if r.boolean("reliable", p) == Some(true) {
        qos.reliability = Reliability::Reliable { depth: 64 };
    }
    qos.deadline = r.seconds("deadline", p);
    if let Some(s) = r.seconds("min_separation", p) {
        qos.min_separation = s;
    }
    if let (Some(mat), Some(topic), Some(habitat), Some(shape)) = (mat, topic, habitat, shape) {
        d.subscribes.push(SubscribeDecl {
            at: r.at.clone(),
            mat,
            topic: topic.name,
            habitat,
            shape,
            qos,
        });
    }
}

fn publish(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let mat = r.required_text("mat", p);
    let topic = r.required_text("topic", p);
    let habitat = r.required_text("habitat", p);
    let mut qos = ProducerQos::default();
    if r.boolean("reliable", p) == Some(true) {
        qos.reliability = Reliability::Reliable { depth: 64 };
    }
    if let Some(s) = r.integer("strength", (i32::MIN as i64, i32::MAX as i64), p) {
        qos.strength = s as i32;
    }
    if let Some(s) = r.seconds("persistence", p) {
        qos.persistence = s;
    }
    if let (Some(mat), Some(topic), Some(habitat)) = (mat, topic, habitat) {
        d.publishes.push(PublishDecl {
            at: r.at.clone(),
            mat,
            topic: topic.name,
            habitat,
            qos,
        });
    }
}

fn endpoint(r: &Reader<'_>, key: &str, p: &mut Diagnostics) -> Option<(Named, Named)> {
    let Some(raw) = r.raw(key) else {
        r.missing(key, "{ habitat = \"...\", mat = \"...\" }", p);
        return None;
    };
    let inner = Reader::new(raw, &format!("`{key}`"), p)?;
    inner.known_keys(&["habitat", "mat"], p);
    let habitat = inner.required_text("habitat", p);
    let mat = inner.required_text("mat", p);
    Some((habitat?, mat?))
}

fn rate(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let name = r.required_text("name", p);
    let from = endpoint(r, "from", p);
    let to = endpoint(r, "to", p);
    if let (Some(name), Some(from), Some(to)) = (name, from, to) {
        d.rates.push(RateDecl { name, from, to });
    }
}

fn machine(d: &mut Description, r: &Reader<'_>, file: &std::path::Path, p: &mut Diagnostics) {
    let Some(name) = r.required_text("file", p) else {
        return;
    };
    let path = file
        .parent()
        .map_or_else(|| PathBuf::from(&name.name), |dir| dir.join(&name.name));
    let text = match std::fs::metadata(&path) {
        Ok(m) if !m.is_file() => {
            p.push(
                &name.at,
                format!("`{}` is not a regular file", path.display()),
            );
            return;
        }
        Ok(m) if m.len() > super::source::MAX_FILE_BYTES => {
            p.push(&name.at, format!("`{}` is too large", path.display()));
            return;
        }
        Ok(_) => super::source::read_bounded(&path),
        Err(e) => Err(e),
    };
    match text {
        Err(err) => p.push(&name.at, format!("cannot read `{}`: {err}", path.display())),
        Ok(text) => match Program::from_toml(&text) {
            Ok(program) => d.machines.push(MachineDecl {
                at: name.at,
                file: path,
                program,
            }),
            Err(err) => p.push(
                &name.at,
                format!("state machine `{}`: {err}", path.display()),
            ),
        },
    }
}

fn trigger(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let habitat = r.required_text("habitat", p);
    let input = r.required_text("input", p);
    let machine = r.required_text("machine", p);
    let stimulus = r.required_text("stimulus", p);
    let above = r.number("above", p);
    let below = r.number("below", p);
    if above.is_none() && below.is_none() && r.raw("above").is_none() && r.raw("below").is_none() {
        r.missing("below", "a threshold (or `above`)", p);
        return;
    }
    if let (Some(a), Some(b)) = (above, below)
        && a >= b
    {
        if let Some(raw) = r.raw("below") {
            p.expected(
                &raw.at,
                format!("`below = {b}` is not above `above = {a}`: the trigger could never fire"),
                "above < below (a band), or only one of them",
            );
        }
        return;
    }
    if let (Some(habitat), Some(input), Some(machine), Some(stimulus)) =
        (habitat, input, machine, stimulus)
    {
        d.triggers.push(TriggerDecl {
            at: r.at.clone(),
            habitat,
            input,
            above,
            below,
            machine,
            stimulus: Stimulus::parse(&stimulus.name),
        });
    }
}

fn port(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let name = r.required_text("name", p);
    let serves = r.required_text("serves", p);
    let machine = r.text("machine", p);
    let serves = serves.and_then(|s| match s.name.as_str() {
        "configuration" => Some(Serves::Configuration),
        "stimuli" => match &machine {
            Some(m) => Some(Serves::Stimuli(m.name.clone())),
            None => {
                r.missing("machine", "the state machine the stimuli are for", p);
                None
            }
        },
        other => {
            p.expected(
                &s.at,
                format!("a port cannot serve `{other}`"),
                "\"configuration\" or \"stimuli\"",
            );
            None
        }
    });
    let mut restrictions = Restrictions {
        users: r.texts("users", p).into_iter().map(|n| n.name).collect(),
        ..Restrictions::default()
    };
    restrictions.max_users = r
        .integer("max_users", (1, u32::MAX as i64), p)
        .map(|n| n as u32);
    restrictions.timeout_ms = r.seconds("timeout", p).map(|t| t.as_millis() as u64);
    if let Some(prio) = r.integer("priority", (i32::MIN as i64, i32::MAX as i64), p) {
        restrictions.priority = prio as i32;
    }
    let name = name.filter(|n| {
        let ok = !n.name.contains('/') && !n.name.chars().any(char::is_control);
        if !ok {
            p.expected(
                &n.at,
                format!("bad port name `{}`", n.name),
                "a name without `/` or control characters (ports live under port/NAME/...)",
            );
        }
        ok
    });
    if let (Some(name), Some(serves)) = (name, serves) {
        d.ports.push(PortDecl {
            name,
            serves,
            machine_at: machine.map(|m| m.at),
            restrictions,
        });
    }
}

/// Names used twice, and references to habitats, CSMats, groups, configurations and machines
/// that nothing declares.
fn cross_check(d: &Description, p: &mut Diagnostics) {
    fn unique<'a>(kind: &str, names: impl Iterator<Item = &'a Named>, p: &mut Diagnostics) {
        let mut seen: BTreeMap<&str, &Location> = BTreeMap::new();
        for n in names {
            if let Some(first) = seen.get(n.name.as_str()) {
                p.push(
                    &n.at,
                    format!("duplicate {kind} `{}` (first declared at {first})", n.name),
                );
            } else {
                seen.insert(&n.name, &n.at);
            }
        }
    }
    unique("habitat", d.habitats.iter().map(|h| &h.name), p);
    unique("CSMat", d.mats.iter().map(|m| &m.name), p);
    unique("component", d.components.iter().map(|c| &c.name), p);
    unique("configuration", d.configurations.iter().map(|c| &c.name), p);
    unique("rate transition", d.rates.iter().map(|c| &c.name), p);
    unique("port", d.ports.iter().map(|c| &c.name), p);
    let machine_names: Vec<Named> = d
        .machines
        .iter()
        .map(|m| Named {
            name: m.program.main.clone(),
            at: m.at.clone(),
        })
        .collect();
    unique("state machine", machine_names.iter(), p);

    let habitats: Vec<&str> = d.habitats.iter().map(|h| h.name.name.as_str()).collect();
    let check_habitat = |h: &Named, p: &mut Diagnostics| {
        if !habitats.contains(&h.name.as_str()) && !d.broken_habitats.contains(&h.name) {
            p.expected(
                &h.at,
                format!("unknown habitat `{}`", h.name),
                format!(
                    "a habitat declared with [[habitat]]{}: {}",
                    suggest(&h.name, &habitats),
                    list(&habitats)
                ),
            );
        }
    };
    for c in &d.components {
        check_habitat(&c.habitat, p);
    }
    for s in &d.subscribes {
        check_habitat(&s.habitat, p);
    }
    for s in &d.publishes {
        check_habitat(&s.habitat, p);
    }
    for r in &d.rates {
        check_habitat(&r.from.0, p);
        check_habitat(&r.to.0, p);
    }
    for t in &d.triggers {
        check_habitat(&t.habitat, p);
    }

    // CSMats: what provides each name.
    let mut provided: BTreeSet<&str> = BTreeSet::new();
    provided.extend(d.mats.iter().map(|m| m.name.name.as_str()));
    provided.extend(d.subscribes.iter().map(|s| s.mat.name.as_str()));
    provided.extend(d.rates.iter().map(|r| r.to.1.name.as_str()));
    for c in &d.components {
        provided.extend(
            c.mats
                .iter()
                .filter(|(_, _, k)| *k == ParamKind::Output)
                .map(|(m, _, _)| m.as_str()),
        );
    }
    let known: Vec<&str> = provided.iter().copied().collect();
    let components: BTreeSet<&str> = d.components.iter().map(|c| c.name.name.as_str()).collect();
    // `<component>.<parameter>`: a component's parameter CSMat (which ones exist is the
    // component's to say; verify() reports a name that none creates).
    let is_parameter = |name: &str| {
        name.rsplit_once('.')
            .is_some_and(|(component, _)| components.contains(component))
    };
    let check_mat = |name: &str, at: &Location, p: &mut Diagnostics| {
        if !provided.contains(name) && !is_parameter(name) {
            p.expected(
                at,
                format!(
                    "unknown CSMat `{name}`: no [[mat]], component output, [[subscribe]] or \
                     rate transition provides it"
                ),
                format!("one of {}{}", list(&known), suggest(name, &known)),
            );
        }
    };
    for c in &d.components {
        for (mat, at, kind) in &c.mats {
            if *kind == ParamKind::Input {
                check_mat(mat, at, p);
            }
        }
    }
    for s in &d.publishes {
        check_mat(&s.mat.name, &s.mat.at, p);
    }
    for r in &d.rates {
        check_mat(&r.from.1.name, &r.from.1.at, p);
    }
    for t in &d.triggers {
        check_mat(&t.input.name, &t.input.at, p);
    }
    for n in &d.display {
        check_mat(&n.name, &n.at, p);
    }

    // Groups and configurations.
    let groups: BTreeSet<String> = d
        .components
        .iter()
        .filter_map(|c| c.group.as_ref().map(|(c, g, _)| format!("{c}/{g}")))
        .collect();
    let group_list: Vec<&String> = groups.iter().collect();
    for conf in &d.configurations {
        for (c, g, at) in &conf.groups {
            let full = format!("{c}/{g}");
            if !groups.contains(&full) {
                p.expected(
                    at,
                    format!(
                        "configuration `{}` names group `{full}`, which no component is in",
                        conf.name.name
                    ),
                    format!(
                        "one of {}{}",
                        list(&group_list),
                        suggest(&full, &group_list)
                    ),
                );
            }
        }
    }
    if let Some(conf) = &d.configuration {
        let names: Vec<&str> = d
            .configurations
            .iter()
            .map(|c| c.name.name.as_str())
            .collect();
        if !names.contains(&conf.name.as_str()) {
            p.expected(
                &conf.at,
                format!("unknown configuration `{}`", conf.name),
                format!(
                    "one declared with [[configuration]]{}: {}",
                    suggest(&conf.name, &names),
                    list(&names)
                ),
            );
        }
    }

    // Machines named by triggers and ports.
    let machines: Vec<&str> = d.machines.iter().map(|m| m.program.main.as_str()).collect();
    let check_machine = |name: &str, at: &Location, p: &mut Diagnostics| {
        if !machines.contains(&name) {
            p.expected(
                at,
                format!("unknown state machine `{name}`"),
                format!(
                    "the main machine of a [[state_machine]] file{}: {}",
                    suggest(name, &machines),
                    list(&machines)
                ),
            );
        }
    };
    for t in &d.triggers {
        check_machine(&t.machine.name, &t.machine.at, p);
        if let Some(m) = d.machines.iter().find(|m| m.program.main == t.machine.name)
            && !m.program.stimuli.contains_key(&t.stimulus.name)
        {
            p.push(
                &t.at,
                format!(
                    "state machine `{}` declares no stimulus `{}`",
                    t.machine.name, t.stimulus.name
                ),
            );
        }
    }
    for port in &d.ports {
        if let (Serves::Stimuli(m), Some(at)) = (&port.serves, &port.machine_at) {
            check_machine(m, at, p);
        }
    }
    // `set CSMAT V1 V2 ...` actions name CSMats of this system and give numbers.
    for m in &d.machines {
        for (machine, def) in &m.program.machines {
            for t in &def.transitions {
                let ActionRef::Named { name, argument } = &t.action else {
                    continue;
                };
                if name != "set" {
                    continue;
                }
                let argument = argument.as_deref().unwrap_or("");
                let mut words = argument.split_whitespace();
                let mat = words.next().unwrap_or("");
                let numbers_ok = words.clone().count() > 0
                    && words.all(|w| w.parse::<f64>().is_ok_and(f64::is_finite));
                if !(provided.contains(mat) || is_parameter(mat)) || !numbers_ok {
                    p.expected(
                        &m.at,
                        format!(
                            "state machine `{machine}` ({}): action `set {argument}`",
                            m.file.display()
                        ),
                        format!(
                            "`set CSMAT V1 V2 ...` with a CSMat of this system{} and its values",
                            suggest(mat, &known)
                        ),
                    );
                }
            }
        }
    }
}
