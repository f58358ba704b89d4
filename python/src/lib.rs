//! `hamflight._core`: the native module of the `hamflight` Python package. It wraps the very f32
//! core the firmware runs (`hamflight`), and the host crate (`host-train`) for the SITL plant,
//! the scenario files and the data and training commands. The Python-facing documentation is in
//! `hamflight/__init__.py`, `hamflight/_core.pyi` and `docs/python.md`, and in the `///` comments
//! of the `#[pyclass]`es, `#[pymethods]` and `#[pyfunction]`s: they are the docstrings `help()`
//! shows, and `_core.pyi` repeats them word for word (`tests/test_docstrings.py`).

mod arrays;
mod blob;
mod controller;
mod plant;
mod sitl;

use std::path::PathBuf;

use pyo3::prelude::*;

/// `path` itself, or, when it is relative and does not exist, the package's copy of the
/// repository file it names (`hamflight.data`): `scenarios/NAME.toml` and `weights/default.hfw`
/// work outside a checkout. Anything else (or a failed lookup) returns `path` unchanged, so the
/// caller's error names what was asked for.
pub fn packaged_or(py: Python<'_>, path: PathBuf, folder: &str) -> PathBuf {
    if path.is_absolute() || path.exists() {
        return path;
    }
    py.import("hamflight.data")
        .and_then(|m| m.call_method1("_packaged", (&path, folder)))
        .and_then(|f| f.extract::<Option<PathBuf>>())
        .ok()
        .flatten()
        .unwrap_or(path)
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<controller::Controller>()?;
    m.add_class::<controller::ControllerBatch>()?;
    m.add_class::<controller::Setpoint>()?;
    m.add_class::<controller::StepResult>()?;
    m.add_class::<controller::BatchResult>()?;
    m.add_class::<controller::Faults>()?;
    m.add_class::<blob::Blob>()?;
    m.add("BlobError", py.get_type::<blob::BlobError>())?;
    m.add("CONTROLLER_NAMES", controller::core_names())?;
    m.add("GAIN_KEYWORDS", controller::GAIN_KEYS.to_vec())?;
    m.add("BLOB_HEADER_LEN", blob::LAYOUT.0)?;
    m.add("BLOB_CRC_LEN", blob::LAYOUT.1)?;
    m.add_class::<sitl::Scenario>()?;
    m.add_class::<plant::Plant>()?;
    m.add_class::<sitl::FlightResult>()?;
    m.add_function(wrap_pyfunction!(sitl::fly, m)?)?;
    m.add_function(wrap_pyfunction!(sitl::controllers, m)?)?;
    m.add_function(wrap_pyfunction!(sitl::run_tool, m)?)?;
    m.add_function(wrap_pyfunction!(controller::_restore_controller, m)?)?;
    m.add_function(wrap_pyfunction!(blob::_restore_blob, m)?)?;
    m.add_function(wrap_pyfunction!(sitl::_restore_scenario, m)?)?;
    Ok(())
}
