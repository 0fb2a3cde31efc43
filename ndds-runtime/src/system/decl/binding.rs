//! Network bindings: `[[subscribe]]` (a topic written into a CSMat at the start of each
//! sample) and `[[publish]]` (a CSMat published after its writer, every sample).

use super::keys::{Key, Section, TEXT};
use super::reader::Reader;
use super::values::numbers;
use super::{Description, Named};
use crate::system::source::{Diagnostics, Location};
use ndds_client::{ConsumerQos, ProducerQos, Reliability};

/// Most elements of a subscribed CSMat (32 MiB of `f64`).
pub(crate) const MAX_SUBSCRIBED_ELEMENTS: usize = 1 << 22;

/// The history a reliable binding keeps.
const RELIABLE: Reliability = Reliability::Reliable { depth: 64 };

pub(super) const SUBSCRIBE: Section = Section::list(
    "subscribe",
    &[
        Key::new("mat", TEXT),
        Key::new("topic", TEXT),
        Key::new("habitat", TEXT),
        Key::new("shape", "[ROWS, COLS]"),
        Key::new("reliable", "true or false"),
        Key::new("deadline", "seconds"),
        Key::new("min_separation", "seconds"),
    ],
    |d, r, _, p| subscribe(d, r, p),
);

pub(super) const PUBLISH: Section = Section::list(
    "publish",
    &[
        Key::new("mat", TEXT),
        Key::new("topic", TEXT),
        Key::new("habitat", TEXT),
        Key::new("reliable", "true or false"),
        Key::new("strength", "an NDDS producer strength"),
        Key::new("persistence", "seconds"),
    ],
    |d, r, _, p| publish(d, r, p),
);

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

fn subscribe(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let mat = r.required_text("mat", p);
    let topic = r.required_text("topic", p);
    let habitat = r.required_text("habitat", p);
    let shape = shape(r, p);
    let mut qos = ConsumerQos::default();
    if r.boolean("reliable", p) == Some(true) {
        qos.reliability = RELIABLE;
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

/// `[ROWS, COLS]`: whole numbers, each 1 to 65536, at most [`MAX_SUBSCRIBED_ELEMENTS`].
fn shape(r: &Reader<'_>, p: &mut Diagnostics) -> Option<(usize, usize)> {
    let Some(raw) = r.raw("shape") else {
        r.missing("shape", p);
        return None;
    };
    let size = |x: &f64| x.fract() == 0.0 && (1.0..=65536.0).contains(x);
    match numbers(raw, "shape", p)?.as_slice() {
        [rows, cols]
            if size(rows) && size(cols) && rows * cols <= MAX_SUBSCRIBED_ELEMENTS as f64 =>
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

fn publish(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let mat = r.required_text("mat", p);
    let topic = r.required_text("topic", p);
    let habitat = r.required_text("habitat", p);
    let mut qos = ProducerQos::default();
    if r.boolean("reliable", p) == Some(true) {
        qos.reliability = RELIABLE;
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
