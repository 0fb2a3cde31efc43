//! Permissions documents: who (an identity, with a name) may publish, subscribe, own or use
//! what (topic and port patterns), from when until when, signed by an administrator.
//!
//! The document is TOML (read by the daemon's and the CLI's `cli` feature, see
//! `docs/security.md`); this module holds what it means, its signature and the checks, so that
//! the discovery engine can enforce it without parsing anything.
//!
//! A signed document is the TOML text followed by one last line
//! `#! ndds-signature ed25519:<128 hex digits>`: the administrator's Ed25519 signature of every
//! byte before that line. TOML reads the line as a comment, so the signed file is still the
//! document.

use std::fmt;

use serde::Deserialize;

use super::identity::{Identity, PublicId};
use crate::hex::{hex, unhex};
use crate::wire::EndpointKind;

/// The start of a signed document's last line.
pub const SIGNATURE_LINE: &str = "#! ndds-signature ";

/// Patterns per rule list and subjects per document, at most (a document is written by people;
/// these bound what a forged or broken one can make a daemon hold).
pub const MAX_PATTERNS: usize = 1024;
/// Subjects per document, at most.
pub const MAX_SUBJECTS: usize = 4096;
/// Bytes of a pattern or a subject name, at most.
pub const MAX_NAME_LEN: usize = 256;

/// A topic or port pattern: `*` matches any run of characters (`/` included); every other
/// character matches itself. `arm/*` matches `arm/pose` and `arm/joint/3`; `*` matches
/// everything.
#[derive(Clone, PartialEq, Eq, Hash)]
pub struct Pattern(String);

impl Pattern {
    /// The pattern of `text`, or why not.
    pub fn new(text: &str) -> Result<Pattern, PermissionsError> {
        if text.is_empty() || text.len() > MAX_NAME_LEN || text.chars().any(char::is_control) {
            return Err(PermissionsError::BadPattern(text.to_owned()));
        }
        Ok(Pattern(text.to_owned()))
    }

    /// The pattern as written.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Whether `name` matches: linear in the lengths (greedy with one backtrack point, the
    /// classic wildcard algorithm), so a hostile pattern costs no more than a plain one.
    pub fn matches(&self, name: &str) -> bool {
        let (pattern, name) = (self.0.as_bytes(), name.as_bytes());
        let (mut p, mut n) = (0, 0);
        let mut star: Option<(usize, usize)> = None;
        while n < name.len() {
            if p < pattern.len() && pattern[p] == b'*' {
                star = Some((p, n));
                p += 1;
            } else if p < pattern.len() && pattern[p] == name[n] {
                p += 1;
                n += 1;
            } else if let Some((star_p, star_n)) = star {
                p = star_p + 1;
                n = star_n + 1;
                star = Some((star_p, star_n + 1));
            } else {
                return false;
            }
        }
        pattern[p..].iter().all(|c| *c == b'*')
    }
}

impl fmt::Display for Pattern {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl fmt::Debug for Pattern {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", self.0)
    }
}

impl<'de> Deserialize<'de> for Pattern {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let text = String::deserialize(deserializer)?;
        Pattern::new(&text).map_err(serde::de::Error::custom)
    }
}

/// What a subject may do with a topic or a port.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Action {
    /// Produce samples of a topic.
    Publish,
    /// Consume samples of a topic.
    Subscribe,
    /// Own a port (`port/NAME/...` topics on the owner's side).
    Own,
    /// Use a port (`port/NAME/...` topics on a user's side).
    Use,
}

impl Action {
    /// The word used in documents and messages.
    pub fn name(self) -> &'static str {
        match self {
            Action::Publish => "publish",
            Action::Subscribe => "subscribe",
            Action::Own => "own",
            Action::Use => "use",
        }
    }
}

/// What an endpoint asks of the document: the actions that allow it (one is enough) and the
/// name they apply to (the topic, or the port of a `port/NAME/LEAF` topic).
///
/// Ports (see `ndds_client::ports`) are made of topics: the owner produces `owner`, `all` and
/// `reply/USER` and consumes `users`, `request` and `all-reply`; a user the other way round;
/// both consume `owner`. So a subject that may own port `gripper` is let produce
/// `port/gripper/owner` without a `publish` rule for it.
pub fn needs(topic: &str, kind: EndpointKind) -> (&[Action], &str) {
    const OWN: &[Action] = &[Action::Own];
    const USE: &[Action] = &[Action::Use];
    const EITHER: &[Action] = &[Action::Own, Action::Use];
    if let Some(rest) = topic.strip_prefix("port/")
        && let Some((port, leaf)) = rest.split_once('/')
    {
        let producer = kind == EndpointKind::Producer;
        let actions = match leaf {
            "owner" if producer => OWN,
            "owner" => EITHER,
            "all" if producer => OWN,
            "all" => USE,
            "users" | "request" | "all-reply" if producer => USE,
            "users" | "request" | "all-reply" => OWN,
            reply if reply.starts_with("reply/") && producer => OWN,
            reply if reply.starts_with("reply/") => USE,
            _ => return (plain(kind), topic),
        };
        return (actions, port);
    }
    (plain(kind), topic)
}

fn plain(kind: EndpointKind) -> &'static [Action] {
    match kind {
        EndpointKind::Producer => &[Action::Publish],
        EndpointKind::Consumer => &[Action::Subscribe],
    }
}

/// One subject: an identity with a name and its rules.
#[derive(Clone, Debug, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Subject {
    /// A name for people (a host, a role).
    pub name: String,
    /// Its daemon's public key.
    pub key: PublicId,
    /// Topics it may produce.
    #[serde(default)]
    pub publish: Vec<Pattern>,
    /// Topics it may consume.
    #[serde(default)]
    pub subscribe: Vec<Pattern>,
    /// Ports it may own.
    #[serde(default)]
    pub own: Vec<Pattern>,
    /// Ports it may use.
    #[serde(default, rename = "use")]
    pub use_: Vec<Pattern>,
}

impl Subject {
    /// The patterns of one action.
    pub fn rules(&self, action: Action) -> &[Pattern] {
        match action {
            Action::Publish => &self.publish,
            Action::Subscribe => &self.subscribe,
            Action::Own => &self.own,
            Action::Use => &self.use_,
        }
    }
}

/// A permissions document, as the engine enforces it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Permissions {
    /// Grows with every new version of the document (said in messages, so people can tell
    /// which version refused them).
    pub serial: u64,
    /// The domain it is for (`None`: any).
    pub domain: Option<u16>,
    /// Valid from (Unix seconds).
    pub not_before: u64,
    /// Valid until (Unix seconds).
    pub not_after: u64,
    /// Its subjects.
    pub subjects: Vec<Subject>,
}

/// Why an endpoint may not be matched: said to the clients concerned, counted, and shown
/// by `ndds nodes`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Refusal {
    /// The node's datagrams carry no identity signature.
    #[error("node is not authenticated (its discovery datagrams are not signed by an identity)")]
    Unauthenticated,
    /// The node's identity is not a subject of the document.
    #[error(
        "identity {key} is not a subject of permissions document {serial} (add it with `ndds security add`, then sign)"
    )]
    UnknownSubject {
        /// The node's identity.
        key: PublicId,
        /// The document's serial.
        serial: u64,
    },
    /// The subject has no rule allowing this.
    #[error(
        "subject `{subject}` may not {} `{name}`: no rule of permissions document {serial} allows it ({})",
        action_words(actions),
        held_words(held)
    )]
    NotAllowed {
        /// The subject's name.
        subject: String,
        /// The actions that would have allowed it.
        actions: Vec<Action>,
        /// The topic or port.
        name: String,
        /// The patterns the subject holds for those actions.
        held: Vec<String>,
        /// The document's serial.
        serial: u64,
    },
    /// The document is outside its validity window.
    #[error("permissions document {serial} is not valid now (valid {window})")]
    Expired {
        /// The document's serial.
        serial: u64,
        /// Its window, in words.
        window: String,
    },
}

fn action_words(actions: &[Action]) -> String {
    let words: Vec<_> = actions.iter().map(|a| a.name()).collect();
    words.join(" or ")
}

fn held_words(held: &[String]) -> String {
    if held.is_empty() {
        "it holds no such rule".to_owned()
    } else {
        format!("it holds {}", held.join(", "))
    }
}

impl Permissions {
    /// The subject with this key.
    pub fn subject(&self, key: &PublicId) -> Option<&Subject> {
        self.subjects.iter().find(|s| s.key == *key)
    }

    /// Whether `key` may have an endpoint of `kind` on `topic`; `Ok` with the subject's name.
    pub fn check(
        &self,
        key: Option<&PublicId>,
        topic: &str,
        kind: EndpointKind,
    ) -> Result<&str, Refusal> {
        let key = key.ok_or(Refusal::Unauthenticated)?;
        let subject = self.subject(key).ok_or(Refusal::UnknownSubject {
            key: *key,
            serial: self.serial,
        })?;
        let (actions, name) = needs(topic, kind);
        let allowed = actions
            .iter()
            .any(|action| subject.rules(*action).iter().any(|p| p.matches(name)));
        if allowed {
            return Ok(&subject.name);
        }
        Err(Refusal::NotAllowed {
            subject: subject.name.clone(),
            actions: actions.to_vec(),
            name: name.to_owned(),
            held: actions
                .iter()
                .flat_map(|action| {
                    subject
                        .rules(*action)
                        .iter()
                        .map(move |p| format!("{} '{}'", action.name(), p))
                })
                .collect(),
            serial: self.serial,
        })
    }

    /// Whether `unix_now` lies in the validity window.
    pub fn valid_at(&self, unix_now: u64) -> bool {
        (self.not_before..self.not_after).contains(&unix_now)
    }

    /// Checks the document's own rules: a window, names and patterns within bounds, each key
    /// and name once.
    pub fn validate(&self) -> Result<(), PermissionsError> {
        if self.not_before >= self.not_after {
            return Err(PermissionsError::EmptyWindow);
        }
        if self.subjects.len() > MAX_SUBJECTS {
            return Err(PermissionsError::TooMany("subjects", MAX_SUBJECTS));
        }
        for (i, subject) in self.subjects.iter().enumerate() {
            if subject.name.is_empty()
                || subject.name.len() > MAX_NAME_LEN
                || subject.name.chars().any(char::is_control)
            {
                return Err(PermissionsError::BadName(subject.name.clone()));
            }
            for action in [Action::Publish, Action::Subscribe, Action::Own, Action::Use] {
                if subject.rules(action).len() > MAX_PATTERNS {
                    return Err(PermissionsError::TooMany("patterns", MAX_PATTERNS));
                }
            }
            for earlier in &self.subjects[..i] {
                if earlier.key == subject.key {
                    return Err(PermissionsError::DuplicateKey(
                        earlier.name.clone(),
                        subject.name.clone(),
                    ));
                }
                if earlier.name == subject.name {
                    return Err(PermissionsError::DuplicateName(subject.name.clone()));
                }
            }
        }
        Ok(())
    }
}

/// Why a document or its signature was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PermissionsError {
    /// An empty, overlong or control-character pattern.
    #[error("`{0}` is not a pattern (1 to 256 characters, `*` for any run of characters)")]
    BadPattern(String),
    /// An empty, overlong or control-character subject name.
    #[error("`{0}` is not a subject name (1 to 256 printable characters)")]
    BadName(String),
    /// Two subjects with one key.
    #[error("subjects `{0}` and `{1}` have the same key: one identity is one subject")]
    DuplicateKey(String, String),
    /// Two subjects with one name.
    #[error("two subjects are named `{0}`")]
    DuplicateName(String),
    /// Too many subjects or patterns.
    #[error("more {0} than the limit of {1}")]
    TooMany(&'static str, usize),
    /// `not_before` is not before `not_after`.
    #[error("the validity window is empty (`not_before` must be before `not_after`)")]
    EmptyWindow,
    /// No signature line.
    #[error(
        "the document is not signed (no `{SIGNATURE_LINE}` line at its end): sign it with `ndds security sign`"
    )]
    Unsigned,
    /// The signature line is malformed.
    #[error("the signature line is malformed: expected `{SIGNATURE_LINE}ed25519:<128 hex digits>`")]
    BadSignatureLine,
    /// The signature does not verify with the administrator key.
    #[error(
        "the signature does not verify with administrator key {0}: the document was changed after signing, or signed by another key"
    )]
    BadSignature(PublicId),
}

/// Splits a signed document into the signed text and the signature.
pub fn split_signed(text: &str) -> Result<(&str, [u8; 64]), PermissionsError> {
    let body = text.strip_suffix('\n').unwrap_or(text);
    let start = body.rfind('\n').map_or(0, |i| i + 1);
    let last = &body[start..];
    let Some(signature) = last.strip_prefix(SIGNATURE_LINE) else {
        return Err(PermissionsError::Unsigned);
    };
    let digits = signature
        .trim()
        .strip_prefix(super::identity::KEY_PREFIX)
        .ok_or(PermissionsError::BadSignatureLine)?;
    let signature = unhex::<64>(digits).ok_or(PermissionsError::BadSignatureLine)?;
    Ok((&text[..start], signature))
}

/// The text of a document without its signature line (if any).
pub fn unsigned_text(text: &str) -> &str {
    split_signed(text).map_or(text, |(body, _)| body)
}

/// Checks a signed document's signature with the administrator key; `Ok` with the signed
/// text (to be parsed).
pub fn verify_signed<'t>(text: &'t str, admin: &PublicId) -> Result<&'t str, PermissionsError> {
    let (body, signature) = split_signed(text)?;
    if !admin.verifies(&signed_message(body), &signature) {
        return Err(PermissionsError::BadSignature(*admin));
    }
    Ok(body)
}

/// `text` (its signature line removed, if any) signed with `admin`: the file to install.
pub fn sign(text: &str, admin: &Identity) -> String {
    let mut body = unsigned_text(text).to_owned();
    if !body.is_empty() && !body.ends_with('\n') {
        body.push('\n');
    }
    let signature = admin.sign(&signed_message(&body));
    body.push_str(SIGNATURE_LINE);
    body.push_str(super::identity::KEY_PREFIX);
    body.push_str(&hex(&signature));
    body.push('\n');
    body
}

/// What is signed: a domain separator, then the text.
fn signed_message(body: &str) -> Vec<u8> {
    let mut message = b"ndds-permissions-v1\n".to_vec();
    message.extend_from_slice(body.as_bytes());
    message
}
