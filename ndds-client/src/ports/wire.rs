//! What ports exchange on their topics (`port/<P>/request`, `port/<P>/reply/<user>`,
//! `port/<P>/owner`).

use serde::{Deserialize, Serialize};

/// A request from a user to the owner.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Request {
    /// Per-user sequence number; the reply carries it back.
    pub id: u64,
    /// The user's reply topic suffix (unique per user handle).
    pub user: String,
    /// The task that sent it.
    pub task: String,
    /// The message, postcard-encoded.
    #[serde(with = "serde_bytes")]
    pub payload: Vec<u8>,
    /// A withdrawal, not a request: the sender of request `id` stopped waiting (its timeout
    /// passed), so the owner drops that request if it has not received it yet (the payload
    /// is empty).
    pub withdraw: bool,
    /// The incarnation of the owner it is for: another owner of the port (one being replaced,
    /// or its replacement) drops it, so that no request is run by two owners.
    pub owner: u64,
    /// Not on the wire: the owner's filter answered the sender already
    /// ([`Verdict::Accept`](super::Verdict::Accept)), so the owner's reply is not sent.
    #[serde(skip)]
    pub answered: bool,
}

/// A reply from the owner.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Reply {
    /// The request's id.
    pub id: u64,
    /// The replying owner's incarnation: a user takes replies from the owner it sent to
    /// only (not from one that was replaced meanwhile).
    pub owner: u64,
    /// The reply, postcard-encoded.
    #[serde(with = "serde_bytes")]
    pub payload: Vec<u8>,
    /// Not a reply: the port's filter refused the request, for this reason (the payload is
    /// empty).
    pub refused: Option<String>,
}

pub use ndds_core::ports::Usage;

/// Restrictions an owner declares with its port, checked when users match it.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Restrictions {
    /// The owner's own usages (empty: any): the owner may only use the port through these,
    /// and users only in the usages that complement them (see [`Usage`]).
    pub usages: Vec<Usage>,
    /// Tasks allowed to use the port (empty: any).
    pub users: Vec<String>,
    /// At most this many active users (users heard recently), admitted first come.
    pub max_users: Option<u32>,
    /// Operations on the port time out after this long at most (milliseconds).
    pub timeout_ms: Option<u64>,
    /// The port's priority for `select` (higher first); `None`, the default, ranks below
    /// every port with a priority, as the paper gives ports without one.
    pub priority: Option<i32>,
    /// A filter spliced in at the owner's end.
    pub filter: Option<Filter>,
    /// The class of the process the port serves (the paper's process type restriction):
    /// it decides how the port's primitives wait.
    pub class: ProcessClass,
}

/// How a port's primitives wait for what they are waiting for (Shin, section 4.2, after
/// Roberts): by parking the thread until woken (a context switch each way), or, for a
/// tightly-coupled process whose exchanges are much more frequent than its computations, by
/// busy-waiting first.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum ProcessClass {
    /// Park until woken: the paper's independent, loosely-coupled, serialized-motion and
    /// work-coupled processes, whose exchanges are rare next to their computations.
    #[default]
    Loose,
    /// A user's `send` and `query` and the owner's `receive` busy-wait (poll without
    /// parking) for up to `spin_us` microseconds before they park: a reply that comes
    /// within that time is taken without the wake-up of a parked thread. Each waiting
    /// thread keeps a core busy meanwhile: for a parent and its slave child on cores of
    /// their own. Blocking forms only (an async form leaves waiting to its executor).
    Tight {
        /// How long to busy-wait before parking, in microseconds.
        spin_us: u32,
    },
}

impl ProcessClass {
    /// The busy-wait a tightly-coupled port is given when none is named (a module file's
    /// `class = "tight"` without `spin_us`): 100 µs.
    pub const DEFAULT_SPIN_US: u32 = 100;

    /// How long this class busy-waits before parking (zero for [`ProcessClass::Loose`]).
    pub fn spin(self) -> std::time::Duration {
        match self {
            Self::Loose => std::time::Duration::ZERO,
            Self::Tight { spin_us } => std::time::Duration::from_micros(u64::from(spin_us)),
        }
    }
}

/// A filter task spliced into a port (Shin's port filter restriction).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Filter {
    /// Accepts up to `capacity` requests ahead of the owner and answers each at once, so a
    /// `send` does not block until the buffer is full (then it waits for room): the library
    /// filter [`BoundedBuffer`](super::BoundedBuffer). In the restrictions given to
    /// [`PortOwner::declare_with`](super::PortOwner::declare_with), it needs the reply type
    /// `()`.
    BoundedBuffer {
        /// Requests held at most.
        capacity: u32,
    },
    /// A filter written by the owner's module
    /// ([`PortOwner::declare_filtered`](super::PortOwner::declare_filtered)): it passes each
    /// request on, answers it or refuses it.
    Task,
}

impl Restrictions {
    /// Which restriction refuses `task` using the port for `usages`, and why; `None` when
    /// none does (`max_users` is the owner's to decide).
    pub fn refusal(&self, task: &str, usages: &[Usage]) -> Option<(&'static str, String)> {
        if !self.users.is_empty() && !self.users.iter().any(|u| u == task) {
            return Some((
                "user list",
                format!("`{task}` is not among {:?}", self.users),
            ));
        }
        if let Some(bad) = usages.iter().find(|u| !u.of_user()) {
            return Some((
                "usage",
                format!("{bad:?} is an owner's usage, not a user's"),
            ));
        }
        if !self.usages.is_empty()
            && let Some(bad) = usages
                .iter()
                .find(|u| !self.usages.iter().any(|o| o.user_complement() == Some(**u)))
        {
            return Some((
                "usage",
                format!(
                    "{bad:?} complements none of the owner's usages {:?}",
                    self.usages
                ),
            ));
        }
        None
    }

    /// Whether the owner's usages allow one of `any` (no usages declared: everything).
    pub fn owner_may(&self, any: &[Usage]) -> bool {
        self.usages.is_empty() || any.iter().any(|u| self.usages.contains(u))
    }

    /// Whether the owner must admit users one by one.
    pub fn restricted(&self) -> bool {
        !self.users.is_empty() || !self.usages.is_empty() || self.max_users.is_some()
    }
}

/// A user's declaration, repeated while it uses the port.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct UserInfo {
    /// The user handle's id (its reply topic suffix).
    pub user: String,
    /// The using task.
    pub task: String,
    /// What it does with the port.
    pub usages: Vec<Usage>,
}

/// An owner's declaration, repeated while it owns the port.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct OwnerInfo {
    /// The owning task.
    pub task: String,
    /// Its process id.
    pub pid: u32,
    /// Random per owner handle: two owners never share it.
    pub incarnation: u64,
    /// Fingerprint of the request type.
    pub request_format: u64,
    /// Fingerprint of the reply type.
    pub reply_format: u64,
    /// The port's restrictions.
    pub restrictions: Restrictions,
    /// With `max_users`: the user handles admitted now.
    pub admitted: Vec<String>,
    /// Requests buffered at the owner and not received yet (by its filter or `select`).
    pub queue: u32,
    /// Takeover claim: 0 for an owner that declared the port; a replacement
    /// ([`PortOwner::take_over`](super::PortOwner::take_over)) claims one above every claim it
    /// heard. The highest claim owns the port; two owners with the same claim are a conflict.
    pub claim: u64,
}

/// A running module's declaration, on `module/<name>`: written once when it starts and kept
/// for late readers (`ndds modules`); the module is there while its producer is matched.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModuleInfo {
    /// The module.
    pub name: String,
    /// The module that started it (`costart`), if one did.
    pub parent: Option<String>,
    /// The modules it may start.
    pub children: Vec<String>,
    /// Its tasks.
    pub tasks: Vec<String>,
    /// The ports it owns.
    pub owns: Vec<String>,
    /// The ports it uses.
    pub uses: Vec<String>,
    /// Its process id.
    pub pid: u32,
    /// Its host's name.
    pub host: String,
}
