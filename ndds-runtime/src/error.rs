//! [`RuntimeError`]: what building or changing a system can refuse.

use super::database::ObjectKind;
use super::habitat::HabitatError;
use super::module::ModuleError;
use super::sort::SortError;
use ndds_client::error::DeclareError;

/// What can go wrong building or changing a system.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RuntimeError {
    /// Called from inside a module's routine, where it cannot be carried out (it would wait
    /// for the routine itself). `switch`, and a habitat's `start`, `stop`, `set_rate` and
    /// `reset`, are queued instead.
    #[error("{operation} cannot be called from inside a module's routine")]
    InsideRoutine {
        /// What was called.
        operation: &'static str,
    },
    /// A second object of one kind with one name.
    #[error("{kind} `{name}` already exists")]
    Duplicate {
        /// Its kind.
        kind: ObjectKind,
        /// Its name.
        name: String,
    },
    /// An object that must exist does not.
    #[error("unknown {kind} `{name}`")]
    Unknown {
        /// Its kind.
        kind: ObjectKind,
        /// Its name.
        name: String,
    },
    /// An empty name, or one with a `/` where topic names are derived from it.
    #[error("bad {kind} name `{name}`: {why}")]
    BadName {
        /// Its kind.
        kind: ObjectKind,
        /// The name.
        name: String,
        /// What is wrong with it.
        why: &'static str,
    },
    /// No component type of that name is registered.
    #[error("unknown component type `{name}` (registered: {known})")]
    UnknownType {
        /// The name asked for.
        name: String,
        /// The registered ones.
        known: String,
    },
    /// The module's constructor failed.
    #[error("module `{module}` could not be built: {source}")]
    Build {
        /// The module.
        module: String,
        /// Why.
        source: ModuleError,
    },
    /// Adding the module (or switching) would leave a habitat's active set unsortable.
    #[error("habitat `{habitat}`: {source}")]
    Sort {
        /// The habitat.
        habitat: String,
        /// The double writer or algebraic loop.
        source: SortError,
    },
    /// Two active modules in different habitats would write one CSMat.
    #[error("CSMat `{mat}` would be written by `{first}` and `{second}`")]
    DoubleWriter {
        /// The CSMat.
        mat: String,
        /// One writer.
        first: String,
        /// The other.
        second: String,
    },
    /// A CSMat created with another shape than it already has.
    #[error("CSMat `{name}` is already {rows}x{cols}; cannot create it as {new_rows}x{new_cols}")]
    ShapeConflict {
        /// The CSMat.
        name: String,
        /// Its rows.
        rows: usize,
        /// Its columns.
        cols: usize,
        /// Rows asked for.
        new_rows: usize,
        /// Columns asked for.
        new_cols: usize,
    },
    /// A group used with a category it does not belong to.
    #[error("module group `{group}` belongs to category `{actual}`, not `{category}`")]
    WrongCategory {
        /// The group.
        group: String,
        /// The category named.
        category: String,
        /// Its category.
        actual: String,
    },
    /// Network bindings and services need a participant.
    #[error("runtime `{0}` has no participant: create it with Runtime::with_participant")]
    NoParticipant(String),
    /// A producer or consumer could not be declared.
    #[error("declaring topic `{topic}`: {source}")]
    Declare {
        /// The topic.
        topic: String,
        /// Why.
        source: DeclareError,
    },
    /// A habitat operation failed.
    #[error(transparent)]
    Habitat(#[from] HabitatError),
    /// A runtime of this name already runs in the domain (it owns the name's command port).
    #[error(
        "system `{name}` already runs in this domain: {owner}; stop it, or run this copy in \
         another domain (--domain)"
    )]
    AlreadyRunning {
        /// The runtime's name.
        name: String,
        /// Where the running one is.
        owner: ndds_client::ports::OwnerLocation,
    },
    /// The command port could not be declared or served.
    #[error("runtime `{runtime}`: command port: {reason}")]
    CommandPort {
        /// The runtime.
        runtime: String,
        /// Why.
        reason: String,
    },
}
