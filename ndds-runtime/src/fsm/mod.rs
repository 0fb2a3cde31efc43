//! Finite state machines for strategic control (ControlShell section 6).
//!
//! A state program ([`Program`]) declares stimuli of three kinds — transient, latched and
//! condition — and machines of states joined by transitions. A transition leaves a state (or
//! any state: a *global* transition) when its condition, a boolean expression over stimuli
//! ([`Expr`]), holds; it runs an action whose integer code picks the next state, or *calls* a
//! sub-machine whose return state gives the code. [`Machine`] is the engine, without threads;
//! [`verify`] reports what would go wrong before anything runs; [`StateMachine`] runs a
//! program on its own thread, fed by one queue from any thread and from the network, with
//! actions ([`ActionSet::runtime`]) that switch configurations and start or stop habitats.

mod command;
mod def;
mod engine;
mod expr;
pub(crate) mod task;
#[cfg(test)]
mod tests;
mod verify;
mod vocabulary;

pub use command::{CommandReply, command_port};
pub use def::{ActionRef, DefError, MachineDef, Program, StimulusKind, TransitionDef};
pub use engine::{
    Actions, Fault, Fired, MAX_CALL_DEPTH, MAX_STEPS, Machine, MachineState, Outcome, Stimulus,
};
pub use expr::{Expr, ParseError, Stimuli};
pub use task::{ActionSet, FsmError, MAX_NAME_LEN, MAX_VALUE_LEN, QUEUE_LIMIT, StateMachine};
pub use verify::{FsmProblem, verify};
pub use vocabulary::{Accepted, Refusal, Vocabulary};
