//! `[[trigger]]`: a stimulus for a state machine when a CSMat's largest absolute element
//! crosses a threshold.

use super::keys::{Key, Section, TEXT};
use super::reader::Reader;
use super::{Description, Named};
use crate::fsm::Stimulus;
use crate::system::source::{Diagnostics, Location};

pub(super) const SECTION: Section = Section::list(
    "trigger",
    &[
        Key::new("habitat", TEXT),
        Key::new("input", TEXT),
        Key::new("above", "a threshold (or `below`)"),
        Key::new("below", "a threshold (or `above`)"),
        Key::new("machine", TEXT),
        Key::new("stimulus", TEXT),
    ],
    |d, r, _, p| read(d, r, p),
);

pub(crate) struct TriggerDecl {
    pub at: Location,
    pub habitat: Named,
    pub input: Named,
    pub above: Option<f64>,
    pub below: Option<f64>,
    pub machine: Named,
    pub stimulus: Stimulus,
}

fn read(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let habitat = r.required_text("habitat", p);
    let input = r.required_text("input", p);
    let machine = r.required_text("machine", p);
    let stimulus = r.required_text("stimulus", p);
    let Some((above, below)) = thresholds(r, p) else {
        return;
    };
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

/// `(above, below)`: at least one given, and a band if both are.
fn thresholds(r: &Reader<'_>, p: &mut Diagnostics) -> Option<(Option<f64>, Option<f64>)> {
    let above = r.number("above", p);
    let below = r.number("below", p);
    if r.raw("above").is_none() && r.raw("below").is_none() {
        r.missing("below", p);
        return None;
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
        return None;
    }
    Some((above, below))
}
