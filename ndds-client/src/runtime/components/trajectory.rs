//! (being written)

use crate::runtime::registry::Registry;

/// Registers this file's component types.
pub(crate) fn register(_registry: &mut Registry) {}
