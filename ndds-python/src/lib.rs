//! # ndds-python
//!
//! The native part of the `ndds` Python package (`import ndds`): participants, producers and
//! consumers, sample types, ports and systems, over `ndds-client` and `ndds-runtime`. The
//! package's pure-Python part (`python/ndds/`) turns dataclasses into type specs, wraps CSMats
//! as NumPy arrays and adds iteration, asyncio and callbacks; see README.md.
//!
//! ## Layout
//! - `typedesc`: a Python type declaration → the Rust type's description; `DataType`.
//! - `codec`: samples between Python objects and postcard bytes, driven by the layout.
//! - `endpoints`: `Participant`, `Producer`, `Consumer`, `Sample`, `Notification`.
//! - `ports`: `PortUser`, `PortOwner`, `Request`.
//! - `system`: `System`.
//! - `errors`: the exceptions.

mod codec;
mod endpoints;
mod errors;
mod ports;
mod system;
mod typedesc;

use pyo3::prelude::*;

/// The native module `ndds._ndds`; `import ndds` is the documented interface.
#[pymodule]
fn _ndds(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<typedesc::DataType>()?;
    m.add_function(wrap_pyfunction!(typedesc::declare_type, m)?)?;
    m.add_function(wrap_pyfunction!(typedesc::csmat_type, m)?)?;
    m.add_class::<endpoints::PyParticipant>()?;
    m.add_class::<endpoints::PyProducer>()?;
    m.add_class::<endpoints::PyConsumer>()?;
    m.add_class::<endpoints::PySample>()?;
    m.add_class::<endpoints::PyNotification>()?;
    m.add_class::<ports::PyPortUser>()?;
    m.add_class::<ports::PyPortOwner>()?;
    m.add_class::<ports::PyRequest>()?;
    m.add_class::<system::PySystem>()?;
    m.add("Error", py.get_type::<errors::Error>())?;
    m.add("Timeout", py.get_type::<errors::Timeout>())?;
    m.add("Refused", py.get_type::<errors::Refused>())?;
    m.add("Disconnected", py.get_type::<errors::Disconnected>())?;
    m.add(
        "IncompatibleType",
        py.get_type::<errors::IncompatibleType>(),
    )?;
    Ok(())
}
