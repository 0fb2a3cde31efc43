//! Systems: a description file loaded, started, driven and watched from Python, as `ndds run`
//! does, with the built-in component library.

use std::path::PathBuf;

use ndds_runtime::fsm::Stimulus;
use ndds_runtime::system::{LoadOptions, System};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::endpoints::{PyParticipant, seconds};
use crate::errors;

/// A control system loaded from a description file.
#[pyclass(module = "ndds._ndds", name = "System", subclass)]
pub(crate) struct PySystem {
    inner: System,
    /// Builds an `ndds.CsMat` from `(name, rows, cols, data, row_fields, col_fields)`.
    csmat: Py<PyAny>,
}

fn system_error(err: impl std::fmt::Display) -> PyErr {
    errors::Error::new_err(err.to_string())
}

#[pymethods]
impl PySystem {
    #[new]
    #[pyo3(signature = (path, csmat, *, participant=None, simulated=false, name=None, check=false))]
    fn new(
        py: Python<'_>,
        path: PathBuf,
        csmat: Py<PyAny>,
        participant: Option<PyRef<'_, PyParticipant>>,
        simulated: bool,
        name: Option<String>,
        check: bool,
    ) -> PyResult<Self> {
        let options = LoadOptions {
            simulated,
            name,
            check,
            ..LoadOptions::default().with_library(ndds_components::library())
        };
        let participant = participant.map(|p| p.get()).transpose()?;
        let inner = py
            .detach(move || System::load_with(&path, participant.as_ref(), options))
            .map_err(system_error)?;
        Ok(Self { inner, csmat })
    }

    /// The system's name.
    #[getter]
    fn name(&self) -> String {
        self.inner.name().to_owned()
    }

    /// The topics the system publishes and subscribes to.
    #[getter]
    fn topics(&self) -> Vec<String> {
        self.inner.topics().to_vec()
    }

    /// The state machines' names.
    #[getter]
    fn machines(&self) -> Vec<String> {
        self.inner.machine_names()
    }

    /// Starts the habitats, state machines and ports.
    fn start(&self, py: Python<'_>) -> PyResult<()> {
        py.detach(|| self.inner.start()).map_err(system_error)
    }

    /// Stops everything (also done when the object is collected).
    fn stop(&self, py: Python<'_>) {
        py.detach(|| self.inner.stop());
    }

    /// Runs `seconds` of simulated time (a system loaded with `simulated=True`); returns the
    /// samples run.
    fn simulate(&self, py: Python<'_>, seconds_: f64) -> PyResult<u64> {
        seconds("seconds", seconds_)?;
        py.detach(|| self.inner.simulate(seconds_))
            .map_err(system_error)
    }

    /// Switches to configuration `name`.
    fn switch(&self, py: Python<'_>, name: &str) -> PyResult<()> {
        py.detach(|| self.inner.runtime().switch(name))
            .map_err(system_error)
    }

    /// The active configuration (None before any switch).
    #[getter]
    fn configuration(&self) -> Option<String> {
        self.inner.runtime().current_configuration()
    }

    /// Sends stimulus `name` (with `value`, for a condition) to state machine `machine`.
    #[pyo3(signature = (machine, name, value=None))]
    fn stimulus(&self, machine: &str, name: &str, value: Option<String>) -> PyResult<()> {
        let Some(running) = self.inner.machine(machine) else {
            return Err(errors::Error::new_err(format!(
                "no running state machine `{machine}` (machines: {}; start the system first)",
                self.inner.machine_names().join(", ")
            )));
        };
        let mut stimulus = Stimulus::event(name);
        stimulus.value = value;
        running.send(stimulus).map_err(system_error)
    }

    /// The state of state machine `machine`.
    fn state(&self, machine: &str) -> PyResult<String> {
        self.inner
            .machine(machine)
            .map(|m| m.snapshot().state)
            .ok_or_else(|| errors::Error::new_err(format!("no running state machine `{machine}`")))
    }

    /// The current value of CSMat `name`, as an ndds.CsMat.
    fn mat(&self, py: Python<'_>, name: &str) -> PyResult<Py<PyAny>> {
        let mat = self.inner.runtime().mat(name);
        if !mat.is_bound() {
            return Err(errors::Error::new_err(format!(
                "the system has no CSMat `{name}`"
            )));
        }
        let value = mat.snapshot();
        crate::endpoints::csmat_object(py, &self.csmat, &value).map(Bound::unbind)
    }

    /// A snapshot: system, configuration, habitats (statistics), machines (states) and the
    /// displayed CSMats, as `ndds run` shows it.
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let status = self.inner.status();
        let out = PyDict::new(py);
        out.set_item("system", &status.system)?;
        out.set_item("configuration", &status.configuration)?;
        let habitats = PyDict::new(py);
        for h in &status.habitats {
            let d = PyDict::new(py);
            d.set_item("running", h.running)?;
            d.set_item("rate_hz", h.rate_hz)?;
            d.set_item("samples", h.samples)?;
            d.set_item("overruns", h.overruns)?;
            d.set_item("module_errors", h.module_errors)?;
            d.set_item("configuration", &h.configuration)?;
            d.set_item("exec_p50_us", h.exec.p50_us)?;
            habitats.set_item(&h.habitat, d)?;
        }
        out.set_item("habitats", habitats)?;
        let machines = PyDict::new(py);
        for m in &status.machines {
            machines.set_item(&m.machine, &m.state)?;
        }
        out.set_item("machines", machines)?;
        let display = PyDict::new(py);
        for (name, value) in &status.display {
            display.set_item(
                name,
                crate::endpoints::csmat_object(py, &self.csmat, value)?,
            )?;
        }
        out.set_item("display", display)?;
        Ok(out)
    }
}
