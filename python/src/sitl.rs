//! `hamflight.sitl`: the host crate's SITL plant and scenario files, and its data and training
//! commands.

use std::path::PathBuf;

use host_train::control::{Controller as HostController, CoreController};
use host_train::fly::{fly_with_states, FlightLog, Report, StateLog};
use host_train::sim::{Scenario as HostScenario, ScenarioSpec, TrajectoryPoint};
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple, PyType};
use serde_json::Value;

use crate::controller::{core_names, named, AnyModel, Controller};

fn err(e: anyhow::Error) -> PyErr {
    PyValueError::new_err(format!("{e:#}"))
}

fn json_loads<'py>(py: Python<'py>, text: &str) -> PyResult<Bound<'py, PyAny>> {
    py.import("json")?.call_method1("loads", (text,))
}

/// `obj` as a JSON value, its floats exactly (no decimal text in between, so a dict that
/// `to_dict` gave comes back bit for bit): dicts with string keys, lists and tuples, strings,
/// ints, floats, bools and None, as `json.dumps` takes them; numpy arrays and scalars as their
/// `tolist()`. `at` names the key in errors (`disturbance.wind_m_s2[0]`).
fn json_value(obj: &Bound<'_, PyAny>, at: &str) -> PyResult<Value> {
    let bad = |what: &str| {
        let at = if at.is_empty() { "the spec" } else { at };
        PyValueError::new_err(format!("bad scenario: {at}: {what}"))
    };
    let key = |k: &str| {
        if at.is_empty() {
            k.to_owned()
        } else {
            format!("{at}.{k}")
        }
    };
    if obj.is_none() {
        Ok(Value::Null)
    } else if let Ok(b) = obj.cast::<PyBool>() {
        Ok(Value::Bool(b.is_true()))
    } else if let Ok(i) = obj.cast::<PyInt>() {
        if let Ok(v) = i.extract::<i64>() {
            Ok(v.into())
        } else {
            Ok(i.extract::<u64>()
                .map_err(|_| bad("integer out of range"))?
                .into())
        }
    } else if let Ok(f) = obj.cast::<PyFloat>() {
        serde_json::Number::from_f64(f.value())
            .map(Value::Number)
            .ok_or_else(|| bad("not a finite number"))
    } else if let Ok(s) = obj.cast::<PyString>() {
        Ok(Value::String(s.extract()?))
    } else if let Ok(d) = obj.cast::<PyDict>() {
        let mut map = serde_json::Map::new();
        for (k, v) in d.iter() {
            let k: String = k.extract().map_err(|_| bad("keys must be strings"))?;
            let v = json_value(&v, &key(&k))?;
            map.insert(k, v);
        }
        Ok(Value::Object(map))
    } else if obj.cast::<PyList>().is_ok() || obj.cast::<PyTuple>().is_ok() {
        obj.try_iter()?
            .enumerate()
            .map(|(i, v)| json_value(&v?, &format!("{at}[{i}]")))
            .collect::<PyResult<Vec<_>>>()
            .map(Value::Array)
    } else if obj.hasattr("tolist")? && !obj.is_instance_of::<PyType>() {
        let plain = obj.call_method0("tolist")?;
        if plain.hasattr("tolist")? {
            return Err(bad("tolist() gave no plain value"));
        }
        json_value(&plain, at)
    } else {
        let ty = obj.get_type().name()?;
        Err(bad(&format!("{ty} is not a JSON value")))
    }
}

/// A reference point as a dict: p_m, v_m_s, a_m_s2, j_m_s3 (world) and yaw_rad, yaw_rate_rad_s.
pub fn reference_dict<'py>(py: Python<'py>, r: &TrajectoryPoint) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("p_m", PyArray1::from_slice(py, r.p_m.as_slice()))?;
    d.set_item("v_m_s", PyArray1::from_slice(py, r.v_m_s.as_slice()))?;
    d.set_item("a_m_s2", PyArray1::from_slice(py, r.a_m_s2.as_slice()))?;
    d.set_item("j_m_s3", PyArray1::from_slice(py, r.j_m_s3.as_slice()))?;
    d.set_item("yaw_rad", r.yaw_rad)?;
    d.set_item("yaw_rate_rad_s", r.yaw_rate_rad_s)?;
    Ok(d)
}

/// A validated scenario (the TOML files of scenarios/): duration, rates, seed, reference
/// trajectory, disturbance, effects, vehicle, sensors, start.
///
/// `Scenario.load(path)`, `Scenario.from_toml(text)` or `Scenario.from_dict(spec)`; `to_dict()`
/// gives the keys to edit. Fly it with `sitl.fly`, or step it with `sitl.Plant`. Scenarios
/// compare equal when every key, the name and the file are, and pickle.
#[pyclass(module = "hamflight._core", frozen, skip_from_py_object)]
#[derive(Clone)]
pub struct Scenario {
    pub s: HostScenario,
}

#[pymethods]
impl Scenario {
    /// Reads and validates a scenario file (ValueError naming the problem otherwise). A relative
    /// `scenarios/NAME.toml` (or `NAME.toml`, `NAME`) that does not exist is the package's copy
    /// (`hamflight.data`).
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let path = crate::packaged_or(py, path, "scenarios");
        Ok(Self {
            s: HostScenario::load(&path).map_err(err)?,
        })
    }

    /// Parses and validates scenario TOML text; `name` names it when the text has no `name`.
    #[staticmethod]
    #[pyo3(signature = (text, name="scenario"))]
    fn from_toml(text: &str, name: &str) -> PyResult<Self> {
        Ok(Self {
            s: HostScenario::from_toml_str(text, name, name).map_err(err)?,
        })
    }

    /// A scenario from a dict with the file's keys (as `to_dict` gives them), validated;
    /// `name` overrides the dict's. Floats are taken exactly; a bad key or value raises
    /// ValueError naming it.
    #[staticmethod]
    #[pyo3(signature = (spec, name=None))]
    fn from_dict(spec: &Bound<'_, PyAny>, name: Option<&str>) -> PyResult<Self> {
        let spec: ScenarioSpec = serde_json::from_value(json_value(spec, "")?)
            .map_err(|e| PyValueError::new_err(format!("bad scenario: {e}")))?;
        let name = name
            .map(str::to_owned)
            .or_else(|| spec.name.clone())
            .unwrap_or_else(|| "scenario".into());
        Ok(Self {
            s: HostScenario::from_spec(&name, spec).map_err(err)?,
        })
    }

    /// The scenario's keys as a dict (every default filled in); edit and pass to from_dict.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let text = serde_json::to_string(&self.s.spec)
            .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
        json_loads(py, &text)
    }

    /// The `name` key, else the file's stem (or the name given).
    #[getter]
    fn name(&self) -> &str {
        &self.s.name
    }
    /// The flight's length (s).
    #[getter]
    fn duration_s(&self) -> f64 {
        self.s.spec.duration_s
    }
    /// The control rate (Hz).
    #[getter]
    fn control_hz(&self) -> f64 {
        self.s.spec.control_hz
    }

    /// The reference at time t: dict of p_m, v_m_s, a_m_s2, j_m_s3 (world) and yaw_rad,
    /// yaw_rate_rad_s.
    fn reference<'py>(&self, py: Python<'py>, t_s: f64) -> PyResult<Bound<'py, PyDict>> {
        reference_dict(py, &self.s.reference(t_s))
    }

    /// Pickling (and `copy`, multiprocessing, Ray): the name, the file it was read from (the
    /// flight's report names it) and the keys as `to_dict` gives them, validated again on
    /// unpickling; the copy flies exactly as the original.
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        let restore = py.import("hamflight._core")?.getattr("_restore_scenario")?;
        let args = (
            self.s.name.as_str(),
            self.s.path.as_deref(),
            self.to_dict(py)?,
        )
            .into_pyobject(py)?;
        PyTuple::new(py, [restore, args.into_any()])
    }

    /// Equal when every key, the name and the file are (floats compared exactly).
    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other
            .cast::<Scenario>()
            .map(|o| o.get().s == self.s)
            .unwrap_or(false)
    }

    fn __hash__(&self) -> u64 {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        self.s.name.hash(&mut h);
        h.finish()
    }

    fn __repr__(&self) -> String {
        format!(
            "Scenario(name={:?}, duration_s={}, control_hz={})",
            self.s.name, self.s.spec.duration_s, self.s.spec.control_hz
        )
    }
}

/// Unpickles a `Scenario` (`Scenario.__reduce__`).
#[pyfunction]
pub fn _restore_scenario(
    name: &str,
    path: Option<PathBuf>,
    spec: &Bound<'_, PyAny>,
) -> PyResult<Scenario> {
    let mut s = Scenario::from_dict(spec, Some(name))?;
    s.s.path = path;
    Ok(s)
}

fn scenario_arg(obj: &Bound<'_, PyAny>) -> PyResult<HostScenario> {
    if let Ok(s) = obj.cast::<Scenario>() {
        return Ok(s.get().s.clone());
    }
    let path: PathBuf = obj.extract().map_err(|_| {
        PyTypeError::new_err("scenario: expected a hamflight.sitl.Scenario or a path")
    })?;
    let path = crate::packaged_or(obj.py(), path, "scenarios");
    HostScenario::load(&path).map_err(err)
}

/// What to fly: a name of the registry, or a copy of a Python controller.
enum Pilot {
    Baseline(String),
    Core(String, AnyModel, Box<hamflight::Gains>),
}

/// One flight, without the GIL.
fn fly_one(scenario: &HostScenario, pilot: &Pilot) -> anyhow::Result<(FlightLog, StateLog)> {
    let mut ctrl: Box<dyn HostController> = match pilot {
        Pilot::Baseline(name) => host_train::control::baseline_by_name(name, scenario)?,
        Pilot::Core(name, model, gains) => {
            Box::new(CoreController::new(name, model.clone(), **gains))
        }
    };
    Ok(fly_with_states(scenario, ctrl.as_mut()))
}

/// A flown SITL flight: per-tick numpy arrays and report.json's scores.
///
/// t_s (n,), p_m and p_ref_m (n, 3), err_m (n,), rpm (n, 4), adaptation (n, 6) or (n, 0); the
/// true state rpy_rad, v_world_m_s, w_body_rad_s (n, 3); the state the controller flew on
/// est_p_m, est_v_world_m_s, est_rpy_rad, est_w_body_rad_s (n, 3): with a `[sensors]` section
/// the estimator's output (and the filtered gyro), else the truth plus the scenario's noise (the
/// truth itself without noise). Row i is tick t_s[i]. `report` is the dict `host-train eval`
/// writes as report.json, `rmse_m` and `crashed` two of its scores.
#[pyclass(module = "hamflight._core", frozen)]
pub struct FlightResult {
    /// Tick times (s), (n,).
    #[pyo3(get)]
    t_s: Py<PyArray1<f64>>,
    /// Flown (true) position (m, world), (n, 3).
    #[pyo3(get)]
    p_m: Py<PyArray2<f64>>,
    /// Desired position (m, world), (n, 3).
    #[pyo3(get)]
    p_ref_m: Py<PyArray2<f64>>,
    /// |p − p*| (m), (n,).
    #[pyo3(get)]
    err_m: Py<PyArray1<f64>>,
    /// Rotor commands (rpm), (n, 4).
    #[pyo3(get)]
    rpm: Py<PyArray2<f64>>,
    /// The adaptation estimate a, (n, 6); (n, 0) for a controller that does not adapt.
    #[pyo3(get)]
    adaptation: Py<PyArray2<f64>>,
    /// True attitude as roll, pitch, yaw (rad, Z-Y-X: R = Rz(yaw) Ry(pitch) Rx(roll)), (n, 3).
    #[pyo3(get)]
    rpy_rad: Py<PyArray2<f64>>,
    /// True velocity (m/s, world), (n, 3).
    #[pyo3(get)]
    v_world_m_s: Py<PyArray2<f64>>,
    /// True body rates ω (rad/s, body frame), (n, 3).
    #[pyo3(get)]
    w_body_rad_s: Py<PyArray2<f64>>,
    /// The position the controller was given (m, world), (n, 3): the estimator's with a
    /// `[sensors]` section, else the true one plus the scenario's noise.
    #[pyo3(get)]
    est_p_m: Py<PyArray2<f64>>,
    /// The velocity the controller was given (m/s, world), (n, 3).
    #[pyo3(get)]
    est_v_world_m_s: Py<PyArray2<f64>>,
    /// The attitude the controller was given, roll, pitch, yaw (rad, as rpy_rad), (n, 3).
    #[pyo3(get)]
    est_rpy_rad: Py<PyArray2<f64>>,
    /// The body rates the controller was given (rad/s, body frame; the filtered gyro with a
    /// `[sensors]` section), (n, 3).
    #[pyo3(get)]
    est_w_body_rad_s: Py<PyArray2<f64>>,
    /// The scores (the keys of `host-train eval`'s report.json).
    #[pyo3(get)]
    report: Py<PyAny>,
}

#[pymethods]
impl FlightResult {
    /// Position RMSE over t ≥ 5 s (m), None if the flight ended before.
    #[getter]
    fn rmse_m(&self, py: Python<'_>) -> PyResult<Option<f64>> {
        self.report
            .bind(py)
            .get_item("rmse_pos_window_m")?
            .extract()
    }
    /// The error exceeded 1 m, z went below 0 or the state became non-finite.
    #[getter]
    fn crashed(&self, py: Python<'_>) -> PyResult<bool> {
        self.report.bind(py).get_item("crashed")?.extract()
    }
    fn __repr__(&self, py: Python<'_>) -> String {
        // The scores as Python spells them (None, True), not as Rust does (Some(true)).
        let score = |key: &str| {
            self.report
                .bind(py)
                .get_item(key)
                .and_then(|v| v.repr())
                .map(|r| r.to_string())
                .unwrap_or_else(|_| "None".into())
        };
        format!(
            "FlightResult(ticks={}, rmse_m={}, crashed={})",
            numpy::PyUntypedArrayMethods::len(self.t_s.bind(py).as_untyped()),
            score("rmse_pos_window_m"),
            score("crashed")
        )
    }
}

fn rows<const K: usize>(py: Python<'_>, v: &[[f64; K]]) -> PyResult<Py<PyArray2<f64>>> {
    let flat: Vec<f64> = v.iter().flatten().copied().collect();
    Ok(PyArray1::from_vec(py, flat).reshape([v.len(), K])?.unbind())
}

fn result(
    py: Python<'_>,
    (log, st): &(FlightLog, StateLog),
    scenario: &HostScenario,
) -> PyResult<FlightResult> {
    let report = Report::from_flight(log, scenario, scenario.path.as_deref());
    let text =
        serde_json::to_string(&report).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    let k = log.adaptation.iter().map(Vec::len).max().unwrap_or(0);
    let mut adapt = Vec::with_capacity(k * log.adaptation.len());
    for a in &log.adaptation {
        adapt.extend((0..k).map(|j| a.get(j).copied().unwrap_or(f64::NAN)));
    }
    Ok(FlightResult {
        t_s: PyArray1::from_slice(py, &log.t_s).unbind(),
        p_m: rows(py, &log.p_m)?,
        p_ref_m: rows(py, &log.p_ref_m)?,
        err_m: PyArray1::from_slice(py, &log.err_m).unbind(),
        rpm: rows(py, &log.rpm)?,
        adaptation: PyArray1::from_vec(py, adapt)
            .reshape([log.adaptation.len(), k])?
            .unbind(),
        rpy_rad: rows(py, &log.rpy_rad)?,
        v_world_m_s: rows(py, &st.v_world_m_s)?,
        w_body_rad_s: rows(py, &st.w_body_rad_s)?,
        est_p_m: rows(py, &st.est_p_m)?,
        est_v_world_m_s: rows(py, &st.est_v_world_m_s)?,
        est_rpy_rad: rows(py, &st.est_rpy_rad)?,
        est_w_body_rad_s: rows(py, &st.est_w_body_rad_s)?,
        report: json_loads(py, &text)?.unbind(),
    })
}

/// Flies `scenario` (a Scenario or a path) with `controller`; returns a FlightResult.
///
/// `controller`: a name (the core's, `pid`, `geometric`; `controllers()` lists them; default
/// "adaptive") or a hamflight.Controller (a copy flies; its estimate starts from zero).
/// `weights` (a blob, its path or bytes) replaces the shipped blob for the learned names. The
/// GIL is released during the flight.
#[pyfunction]
#[pyo3(signature = (scenario, controller=None, weights=None))]
pub fn fly(
    py: Python<'_>,
    scenario: &Bound<'_, PyAny>,
    controller: Option<&Bound<'_, PyAny>>,
    weights: Option<&Bound<'_, PyAny>>,
) -> PyResult<FlightResult> {
    let sc = scenario_arg(scenario)?;
    let default = pyo3::types::PyString::new(py, "adaptive").into_any();
    let controller = controller.unwrap_or(&default);
    let pilot = if let Ok(c) = controller.cast::<Controller>() {
        let c = c.borrow();
        Pilot::Core(
            c.name.clone(),
            c.inner.model().clone(),
            Box::new(c.inner.gains),
        )
    } else {
        let name: String = controller.extract().map_err(|_| {
            PyTypeError::new_err("controller: expected a name or a hamflight.Controller")
        })?;
        if core_names().contains(&name.as_str()) {
            let (model, gains) = named(&name, weights)?;
            Pilot::Core(name, model, Box::new(gains))
        } else {
            Pilot::Baseline(name)
        }
    };
    let flown = py.detach(|| fly_one(&sc, &pilot)).map_err(err)?;
    result(py, &flown, &sc)
}

/// The registry's controllers as (name, description) pairs: the core's (`CONTROLLER_NAMES`),
/// `pid` and `geometric`.
#[pyfunction]
pub fn controllers() -> Vec<(String, String)> {
    host_train::control::controllers()
        .map(|(n, d)| (n.to_string(), d.to_string()))
        .collect()
}

/// `text` (a JSON object) as the job `T`, the error a `ValueError` naming the bad key: an
/// unknown key's lists the valid ones; a mistyped value's names its key. `required` are the keys
/// the command line requires (the Python functions always pass them).
fn job<T: serde::de::DeserializeOwned>(
    command: &str,
    text: &str,
    required: &[&str],
) -> PyResult<T> {
    let bad = |m: String| PyValueError::new_err(format!("{command}: {m}"));
    let value: serde_json::Value = serde_json::from_str(text)
        .map_err(|e| bad(format!("the configuration is not JSON: {e}")))?;
    let Some(map) = value.as_object() else {
        return Err(bad("the configuration is not a JSON object".into()));
    };
    if let Some(key) = required.iter().find(|k| !map.contains_key(**k)) {
        return Err(bad(format!("missing `{key}`")));
    }
    serde_json::from_value(value.clone()).map_err(|e| {
        let msg = e.to_string();
        if msg.starts_with("unknown field") {
            return bad(msg);
        }
        // Name the key: the first that fails on its own (with the required ones).
        let alone = |k: &String| {
            let mut one: serde_json::Map<String, serde_json::Value> = required
                .iter()
                .filter_map(|r| map.get(*r).map(|v| ((*r).to_owned(), v.clone())))
                .collect();
            one.insert(k.clone(), map[k].clone());
            serde_json::from_value::<T>(serde_json::Value::Object(one)).is_err()
        };
        match map.keys().find(|k| alone(k)) {
            Some(k) => bad(format!("`{k}`: {msg}")),
            None => bad(msg),
        }
    })
}

/// Runs `host-train collect|import|train` on `json_config`, a JSON object with the flags' names
/// (`out`, `epochs`, ...; a key left out takes the flag's default): it becomes the typed job
/// (`host_train::data::CollectJob`, `host_train::data::ImportJob`,
/// `host_train::train::TrainJob`) and runs through the function the command line calls.
/// Returns the command's summary as JSON text. The GIL is released while it runs.
#[pyfunction]
pub fn run_tool(py: Python<'_>, command: &str, json_config: &str) -> PyResult<String> {
    use host_train::data::{CollectJob, ImportJob};
    use host_train::train::TrainJob;
    enum Job {
        Collect(CollectJob),
        Import(ImportJob),
        Train(TrainJob),
    }
    let job = match command {
        "collect" => Job::Collect(job(command, json_config, &["out"])?),
        "import" => Job::Import(job(command, json_config, &["out"])?),
        "train" => Job::Train(job(command, json_config, &["data", "out"])?),
        _ => {
            return Err(PyValueError::new_err(format!(
                "unknown command {command:?}: expected collect, import or train"
            )))
        }
    };
    py.detach(|| -> anyhow::Result<String> {
        Ok(match job {
            Job::Collect(a) => serde_json::to_string(&host_train::data::run_collect(&a)?)?,
            Job::Import(a) => serde_json::to_string(&host_train::data::run_import(&a)?)?,
            // `quiet`: the command line's summary is not printed either (the report is returned).
            Job::Train(a) if a.quiet => serde_json::to_string(&host_train::pipeline::run_train(
                &a.config(),
                &a.data,
                &a.out,
                true,
            )?)?,
            Job::Train(a) => serde_json::to_string(&host_train::pipeline::run_train_cli(&a)?)?,
        })
    })
    .map_err(err)
}
