//! `hamflight.Controller`, `ControllerBatch`, `Setpoint`, `StepResult`, `Faults`.

use std::sync::Arc;

use hamflight::model::{
    HamiltonianModel, LearnedModel, ModelTerms, NominalModel, StateDerivative, FEATURES,
};
use hamflight::{
    AdaptationLaw, FlightController, Gains, Measurement, Output, Setpoint as CoreSetpoint, State,
    VehicleFacts,
};
use nalgebra::{Matrix3, Vector3, Vector4};
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::arrays::{leading_dim, read3, read33, read_vec};
use crate::blob::{model_from_weights, Blob};
use host_train::{ControllerSpec, ModelSource};

/// The learned model (shared, about 10 KB) or the nominal one.
#[derive(Clone, Debug)]
pub enum AnyModel {
    /// From a weight blob.
    Learned(Arc<LearnedModel>),
    /// The nominal CF2X with the hand-chosen features.
    Nominal(NominalModel),
}

impl HamiltonianModel for AnyModel {
    #[inline]
    fn terms(&self, state: &State) -> ModelTerms {
        match self {
            Self::Learned(m) => m.terms(state),
            Self::Nominal(m) => m.terms(state),
        }
    }
    fn mass_kg(&self) -> f32 {
        match self {
            Self::Learned(m) => m.mass_kg(),
            Self::Nominal(m) => m.mass_kg(),
        }
    }
    fn motor_tau_s(&self) -> f32 {
        match self {
            Self::Learned(m) => m.motor_tau_s(),
            Self::Nominal(m) => m.motor_tau_s(),
        }
    }
    fn dynamics(&self, state: &State, u: &Vector4<f32>, a: &[f32; FEATURES]) -> StateDerivative {
        match self {
            Self::Learned(m) => m.dynamics(state, u, a),
            Self::Nominal(m) => m.dynamics(state, u, a),
        }
    }
}

/// The gains a model flies with unless told otherwise: the core's, from the vehicle facts the
/// model carries (its mass and motor lag), with the core's default law (the composite one).
pub fn default_gains(model: &AnyModel) -> Gains {
    Gains::for_vehicle(&VehicleFacts::of(model))
}

fn parse_law(law: &str) -> PyResult<AdaptationLaw> {
    match law {
        "gradient" => Ok(AdaptationLaw::Gradient),
        "composite" => Ok(AdaptationLaw::Composite),
        _ => Err(PyValueError::new_err(format!(
            "law: expected \"gradient\" or \"composite\", got {law:?}"
        ))),
    }
}

fn law_name(law: AdaptationLaw) -> &'static str {
    match law {
        AdaptationLaw::Gradient => "gradient",
        AdaptationLaw::Composite => "composite",
    }
}

/// The keyword names of the gains, in the order `Controller.gains` lists them.
pub const GAIN_KEYS: &[&str] = &[
    "k_p_n_per_m",
    "k_v_n_s_per_m",
    "k_r_nm_per_rad",
    "k_w_nm_s_per_rad",
    "max_tilt_rad",
    "shaping_omega_rad_s",
    "c_p",
    "c_v",
    "c_r",
    "c_w",
    "a_max",
    "motor_tau_s",
];

fn gain_slot<'a>(g: &'a mut Gains, key: &str) -> Option<&'a mut f32> {
    Some(match key {
        "k_p_n_per_m" => &mut g.k_p,
        "k_v_n_s_per_m" => &mut g.k_v,
        "k_r_nm_per_rad" => &mut g.k_r,
        "k_w_nm_s_per_rad" => &mut g.k_w,
        "max_tilt_rad" => &mut g.max_tilt_rad,
        "shaping_omega_rad_s" => &mut g.shaping_omega_rad_s,
        "c_p" => &mut g.rates.c_p,
        "c_v" => &mut g.rates.c_v,
        "c_r" => &mut g.rates.c_r,
        "c_w" => &mut g.rates.c_w,
        "a_max" => &mut g.rates.a_max,
        "motor_tau_s" => &mut g.composite.motor_tau_s,
        _ => return None,
    })
}

/// Applies `law`, `adapt` and the gain keywords to `base`.
pub fn gains_from_kwargs(
    mut g: Gains,
    law: Option<&str>,
    adapt: Option<bool>,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<Gains> {
    if let Some(law) = law {
        g.law = parse_law(law)?;
    }
    if let Some(a) = adapt {
        g.adapt = a;
    }
    if let Some(kw) = kwargs {
        for (k, v) in kw.iter() {
            let key: String = k.extract()?;
            let value: f64 = v.extract().map_err(|_| {
                PyTypeError::new_err(format!("{key}: expected a number, got {}", v.get_type()))
            })?;
            let Some(slot) = gain_slot(&mut g, &key) else {
                return Err(PyTypeError::new_err(format!(
                    "unexpected keyword argument {key:?}; the gains are law, adapt, {}",
                    GAIN_KEYS.join(", ")
                )));
            };
            *slot = value as f32;
        }
    }
    Ok(g)
}

fn gains_dict<'py>(py: Python<'py>, g: &Gains) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("law", law_name(g.law))?;
    d.set_item("adapt", g.adapt)?;
    let mut g = *g;
    for k in GAIN_KEYS {
        if let Some(v) = gain_slot(&mut g, k) {
            d.set_item(*k, f64::from(*v))?;
        }
    }
    Ok(d)
}

/// The model `weights` names: None is the nominal model; a path, bytes or a Blob a learned one.
pub fn model_from_arg(weights: Option<&Bound<'_, PyAny>>) -> PyResult<AnyModel> {
    match weights {
        None => Ok(AnyModel::Nominal(NominalModel::default())),
        Some(w) if w.is_none() => Ok(AnyModel::Nominal(NominalModel::default())),
        Some(w) => {
            if let Ok(b) = w.cast::<Blob>() {
                return Ok(AnyModel::Learned(b.borrow().model.clone()));
            }
            Ok(AnyModel::Learned(Arc::new(model_from_weights(w)?)))
        }
    }
}

/// A controller's model and gains by the bridge's and `host-train eval`'s names.
pub fn named(name: &str, weights: Option<&Bound<'_, PyAny>>) -> PyResult<(AnyModel, Gains)> {
    let learned = || -> PyResult<AnyModel> {
        match weights {
            Some(w) if !w.is_none() => model_from_arg(Some(w)),
            _ => Ok(AnyModel::Learned(crate::blob::default_model()?)),
        }
    };
    let spec =
        ControllerSpec::parse_core(name).map_err(|e| PyValueError::new_err(e.to_string()))?;
    let model = match spec.model() {
        Some(ModelSource::Learned) => learned()?,
        _ => AnyModel::Nominal(NominalModel::default()),
    };
    let gains = spec.gains(default_gains(&model));
    Ok((model, gains))
}

/// The names [`named`] knows: the host registry's core controllers
/// ([`ControllerSpec::ALL`]).
pub fn core_names() -> Vec<&'static str> {
    host_train::control::core_names()
}

/// A setpoint: desired position and its derivatives (world frame) and yaw.
#[pyclass(module = "hamflight._core", frozen, skip_from_py_object)]
#[derive(Clone)]
pub struct Setpoint {
    pub sp: CoreSetpoint,
}

fn v3f(a: [f64; 3]) -> Vector3<f32> {
    Vector3::new(a[0] as f32, a[1] as f32, a[2] as f32)
}

fn opt3(obj: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Vector3<f32>> {
    match obj {
        Some(o) if !o.is_none() => Ok(v3f(read3(o, name)?)),
        _ => Ok(Vector3::zeros()),
    }
}

#[pymethods]
impl Setpoint {
    #[new]
    #[pyo3(signature = (p_m, v_m_s=None, a_m_s2=None, j_m_s3=None, yaw_rad=0.0, yaw_rate_rad_s=0.0))]
    fn new(
        p_m: &Bound<'_, PyAny>,
        v_m_s: Option<&Bound<'_, PyAny>>,
        a_m_s2: Option<&Bound<'_, PyAny>>,
        j_m_s3: Option<&Bound<'_, PyAny>>,
        yaw_rad: f64,
        yaw_rate_rad_s: f64,
    ) -> PyResult<Self> {
        Ok(Self {
            sp: CoreSetpoint {
                p_m: v3f(read3(p_m, "p_m")?),
                v_m_s: opt3(v_m_s, "v_m_s")?,
                a_m_s2: opt3(a_m_s2, "a_m_s2")?,
                j_m_s3: opt3(j_m_s3, "j_m_s3")?,
                yaw_rad: yaw_rad as f32,
                yaw_rate_rad_s: yaw_rate_rad_s as f32,
            },
        })
    }

    #[getter]
    fn p_m<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, self.sp.p_m.as_slice())
    }
    #[getter]
    fn v_m_s<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, self.sp.v_m_s.as_slice())
    }
    #[getter]
    fn a_m_s2<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, self.sp.a_m_s2.as_slice())
    }
    #[getter]
    fn j_m_s3<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, self.sp.j_m_s3.as_slice())
    }
    #[getter]
    fn yaw_rad(&self) -> f32 {
        self.sp.yaw_rad
    }
    #[getter]
    fn yaw_rate_rad_s(&self) -> f32 {
        self.sp.yaw_rate_rad_s
    }

    fn __repr__(&self) -> String {
        let s = &self.sp;
        format!(
            "Setpoint(p_m={:?}, v_m_s={:?}, a_m_s2={:?}, j_m_s3={:?}, yaw_rad={}, yaw_rate_rad_s={})",
            s.p_m.as_slice(),
            s.v_m_s.as_slice(),
            s.a_m_s2.as_slice(),
            s.j_m_s3.as_slice(),
            s.yaw_rad,
            s.yaw_rate_rad_s
        )
    }
}

/// A `Setpoint`, a position (3,) held at yaw 0, or a dict with the bridge's keys.
fn setpoint_arg(obj: &Bound<'_, PyAny>) -> PyResult<CoreSetpoint> {
    if let Ok(s) = obj.cast::<Setpoint>() {
        return Ok(s.get().sp);
    }
    if let Ok(d) = obj.cast::<PyDict>() {
        let mut sp = CoreSetpoint::default();
        let mut have_p = false;
        for (k, v) in d.iter() {
            let key: String = k.extract()?;
            match key.as_str() {
                "p" => {
                    sp.p_m = v3f(read3(&v, "setpoint['p']")?);
                    have_p = true;
                }
                "v" => sp.v_m_s = v3f(read3(&v, "setpoint['v']")?),
                "a" => sp.a_m_s2 = v3f(read3(&v, "setpoint['a']")?),
                "j" => sp.j_m_s3 = v3f(read3(&v, "setpoint['j']")?),
                "yaw" => sp.yaw_rad = v.extract::<f64>()? as f32,
                "yaw_rate" => sp.yaw_rate_rad_s = v.extract::<f64>()? as f32,
                _ => {
                    return Err(PyValueError::new_err(format!(
                        "setpoint: unknown key {key:?} (keys: p, v, a, j, yaw, yaw_rate)"
                    )))
                }
            }
        }
        if !have_p {
            return Err(PyValueError::new_err("setpoint: the key 'p' is required"));
        }
        return Ok(sp);
    }
    Ok(CoreSetpoint::hover(v3f(read3(obj, "setpoint")?), 0.0))
}

/// Faults and conditions of one step.
#[pyclass(module = "hamflight._core", frozen, skip_from_py_object)]
#[derive(Clone, Copy)]
pub struct Faults {
    f: hamflight::Faults,
}

#[pymethods]
impl Faults {
    /// The output was forced to motors off (any of bad_state, bad_setpoint, bad_dt, numeric).
    #[getter]
    fn fault(&self) -> bool {
        self.f.is_fault()
    }
    #[getter]
    fn bad_state(&self) -> bool {
        self.f.bad_state
    }
    #[getter]
    fn bad_setpoint(&self) -> bool {
        self.f.bad_setpoint
    }
    #[getter]
    fn bad_dt(&self) -> bool {
        self.f.bad_dt
    }
    #[getter]
    fn numeric(&self) -> bool {
        self.f.numeric
    }
    #[getter]
    fn saturated(&self) -> bool {
        self.f.saturation.any()
    }
    #[getter]
    fn saturated_yaw(&self) -> bool {
        self.f.saturation.yaw
    }
    #[getter]
    fn saturated_roll_pitch(&self) -> bool {
        self.f.saturation.roll_pitch
    }
    #[getter]
    fn saturated_thrust(&self) -> bool {
        self.f.saturation.thrust
    }
    #[getter]
    fn tilt_limited(&self) -> bool {
        self.f.tilt_limited
    }
    /// The bridge's `faults` object.
    #[allow(clippy::wrong_self_convention)]
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("fault", self.fault())?;
        d.set_item("bad_state", self.f.bad_state)?;
        d.set_item("bad_setpoint", self.f.bad_setpoint)?;
        d.set_item("bad_dt", self.f.bad_dt)?;
        d.set_item("numeric", self.f.numeric)?;
        d.set_item("saturated", self.saturated())?;
        d.set_item("tilt_limited", self.f.tilt_limited)?;
        Ok(d)
    }
    fn __bool__(&self) -> bool {
        self.f.is_fault()
    }
    fn __repr__(&self) -> String {
        let f = &self.f;
        format!(
            "Faults(fault={}, bad_state={}, bad_setpoint={}, bad_dt={}, numeric={}, saturated={}, tilt_limited={})",
            py_bool(f.is_fault()),
            py_bool(f.bad_state),
            py_bool(f.bad_setpoint),
            py_bool(f.bad_dt),
            py_bool(f.numeric),
            py_bool(f.saturation.any()),
            py_bool(f.tilt_limited)
        )
    }
}

fn py_bool(b: bool) -> &'static str {
    if b {
        "True"
    } else {
        "False"
    }
}

/// What one `Controller.step` gives: the wrench, the rotor commands, a and the faults (f32).
#[pyclass(module = "hamflight._core", frozen)]
pub struct StepResult {
    out: Output,
}

#[pymethods]
impl StepResult {
    /// Rotor speed commands, rotors 1..4 (rpm), float32 (4,).
    #[getter]
    fn rpm<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, &self.out.rotors.rpm)
    }
    /// Rotor thrust commands (N), float32 (4,).
    #[getter]
    fn rotor_thrust_n<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, &self.out.rotors.thrust_n)
    }
    /// Collective thrust to command (N): the wrench a mixer should be handed.
    #[getter]
    fn thrust_n(&self) -> f32 {
        self.out.command.thrust_n
    }
    /// Body torques to command (N·m), float32 (3,): the law's, with the motor-lag lead the
    /// attitude gains assume (what `rotor_thrust_n` mixes).
    #[getter]
    fn torque_nm<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, self.out.command.torque_nm.as_slice())
    }
    /// [thrust (N), τx, τy, τz (N·m)] to command, float32 (4,).
    #[getter]
    fn wrench<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        let w = &self.out.command;
        PyArray1::from_slice(
            py,
            &[w.thrust_n, w.torque_nm.x, w.torque_nm.y, w.torque_nm.z],
        )
    }
    /// The disturbance-weight estimate a, float32 (6,).
    #[getter]
    fn a<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, self.out.a.as_slice())
    }
    /// Position error Rᵀ(p − p*) (m, body), float32 (3,).
    #[getter]
    fn e_p<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, self.out.errors.e_p.as_slice())
    }
    #[getter]
    fn faults(&self) -> Faults {
        Faults { f: self.out.faults }
    }
    fn __repr__(&self) -> String {
        let o = &self.out;
        format!(
            "StepResult(rpm={:?}, thrust_n={}, torque_nm={:?}, fault={})",
            o.rotors.rpm,
            o.wrench.thrust_n,
            o.wrench.torque_nm.as_slice(),
            py_bool(o.faults.is_fault())
        )
    }
}

/// The core's state from f64 inputs, cast to f32 as the bridge casts them.
fn core_state(p: [f64; 3], r: [f64; 9], v: [f64; 3], w: [f64; 3]) -> State {
    State {
        p_m: v3f(p),
        rot: Matrix3::from_fn(|i, j| r[3 * i + j] as f32),
        v_body_m_s: v3f(v),
        w_body_rad_s: v3f(w),
    }
}

fn measurement(acc: Option<&Bound<'_, PyAny>>) -> PyResult<Measurement> {
    Ok(Measurement {
        acc_body_m_s2: match acc {
            Some(a) if !a.is_none() => Some(v3f(read3(a, "acc")?)),
            _ => None,
        },
    })
}

/// The exact f32 flight core: learned or nominal model, IDA-PBC law, adaptation, mixer.
#[pyclass(module = "hamflight._core")]
pub struct Controller {
    pub inner: FlightController<AnyModel>,
    pub name: String,
}

#[pymethods]
impl Controller {
    #[new]
    #[pyo3(signature = (weights=None, *, law="composite", adapt=true, **gains))]
    fn new(
        weights: Option<&Bound<'_, PyAny>>,
        law: &str,
        adapt: bool,
        gains: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let model = model_from_arg(weights)?;
        let name = match (&model, adapt) {
            (AnyModel::Learned(_), true) => "adaptive",
            (AnyModel::Learned(_), false) => "learned",
            (AnyModel::Nominal(_), true) => "geometric-adaptive",
            (AnyModel::Nominal(_), false) => "ida-pbc",
        };
        let g = gains_from_kwargs(default_gains(&model), Some(law), Some(adapt), gains)?;
        let name = format!("{name}-{}", law_name(g.law));
        Ok(Self {
            inner: FlightController::new(model, g),
            name,
        })
    }

    /// The controller `host-train bridge --controller NAME` runs (the shipped weights unless
    /// `weights` is given for the learned ones), with optional gain overrides.
    #[staticmethod]
    #[pyo3(signature = (name, weights=None, **gains))]
    fn named(
        name: &str,
        weights: Option<&Bound<'_, PyAny>>,
        gains: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let (model, g) = named(name, weights)?;
        let g = gains_from_kwargs(g, None, None, gains)?;
        Ok(Self {
            inner: FlightController::new(model, g),
            name: name.to_owned(),
        })
    }

    /// One control step.
    #[pyo3(signature = (p, R, v_body, w_body, setpoint, dt, acc=None))]
    #[allow(non_snake_case, clippy::too_many_arguments)]
    fn step(
        &mut self,
        p: &Bound<'_, PyAny>,
        R: &Bound<'_, PyAny>,
        v_body: &Bound<'_, PyAny>,
        w_body: &Bound<'_, PyAny>,
        setpoint: &Bound<'_, PyAny>,
        dt: f64,
        acc: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<StepResult> {
        let state = core_state(
            read3(p, "p")?,
            read33(R, "R")?,
            read3(v_body, "v_body")?,
            read3(w_body, "w_body")?,
        );
        let sp = setpoint_arg(setpoint)?;
        let meas = measurement(acc)?;
        let out = self.inner.step_measured(&state, &sp, &meas, dt as f32);
        Ok(StepResult { out })
    }

    /// Clears the adaptation estimate and the filters (the model and gains stay).
    fn reset(&mut self) {
        self.inner.reset();
    }

    /// The disturbance-weight estimate a, float32 (6,).
    #[getter]
    fn a<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, self.inner.estimate().as_slice())
    }

    /// The gains, keyword names as the constructor takes them.
    #[getter]
    fn gains<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        gains_dict(py, &self.inner.gains)
    }

    /// Changes gains in place (the same keywords as the constructor); the estimate stays.
    #[pyo3(signature = (*, law=None, adapt=None, **gains))]
    fn set_gains(
        &mut self,
        law: Option<&str>,
        adapt: Option<bool>,
        gains: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<()> {
        self.inner.gains = gains_from_kwargs(self.inner.gains, law, adapt, gains)?;
        Ok(())
    }

    /// The vehicle mass the model carries (kg).
    #[getter]
    fn mass_kg(&self) -> f32 {
        self.inner.model().mass_kg()
    }

    /// "learned" or "nominal".
    #[getter]
    fn model(&self) -> &'static str {
        match self.inner.model() {
            AnyModel::Learned(_) => "learned",
            AnyModel::Nominal(_) => "nominal",
        }
    }

    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    fn __repr__(&self) -> String {
        format!(
            "Controller(name={:?}, model={:?}, law={:?}, adapt={}, mass_kg={})",
            self.name,
            self.model(),
            law_name(self.inner.gains.law),
            py_bool(self.inner.gains.adapt),
            self.mass_kg()
        )
    }
}

/// The outputs of one batched step, one row per vehicle.
#[pyclass(module = "hamflight._core", frozen)]
pub struct BatchResult {
    #[pyo3(get)]
    rpm: Py<PyArray2<f32>>,
    #[pyo3(get)]
    rotor_thrust_n: Py<PyArray2<f32>>,
    #[pyo3(get)]
    thrust_n: Py<PyArray1<f32>>,
    #[pyo3(get)]
    torque_nm: Py<PyArray2<f32>>,
    #[pyo3(get)]
    a: Py<PyArray2<f32>>,
    #[pyo3(get)]
    fault: Py<PyArray1<bool>>,
    #[pyo3(get)]
    saturated: Py<PyArray1<bool>>,
    #[pyo3(get)]
    tilt_limited: Py<PyArray1<bool>>,
}

#[pymethods]
impl BatchResult {
    fn __repr__(&self, py: Python<'_>) -> String {
        format!(
            "BatchResult(n={})",
            numpy::PyUntypedArrayMethods::len(self.thrust_n.bind(py).as_untyped())
        )
    }
}

/// N independent controllers stepped by one call on arrays of N states.
#[pyclass(module = "hamflight._core")]
pub struct ControllerBatch {
    ctrls: Vec<FlightController<AnyModel>>,
}

enum BatchSetpoint {
    One(CoreSetpoint),
    Many(Vec<CoreSetpoint>),
}

fn batch_setpoint(obj: &Bound<'_, PyAny>, n: usize) -> PyResult<BatchSetpoint> {
    if let Ok(s) = obj.cast::<Setpoint>() {
        return Ok(BatchSetpoint::One(s.get().sp));
    }
    let col = |v: &Bound<'_, PyAny>, name: &str| read_vec(v, name, &[n, 3]);
    let mut sps = vec![CoreSetpoint::default(); n];
    let set3 = |sps: &mut Vec<CoreSetpoint>,
                data: &[f64],
                f: fn(&mut CoreSetpoint) -> &mut Vector3<f32>| {
        for (i, sp) in sps.iter_mut().enumerate() {
            *f(sp) = v3f([data[3 * i], data[3 * i + 1], data[3 * i + 2]]);
        }
    };
    if let Ok(d) = obj.cast::<PyDict>() {
        let mut have_p = false;
        for (k, v) in d.iter() {
            let key: String = k.extract()?;
            match key.as_str() {
                "p" => {
                    set3(&mut sps, &col(&v, "setpoint['p']")?, |s| &mut s.p_m);
                    have_p = true;
                }
                "v" => set3(&mut sps, &col(&v, "setpoint['v']")?, |s| &mut s.v_m_s),
                "a" => set3(&mut sps, &col(&v, "setpoint['a']")?, |s| &mut s.a_m_s2),
                "j" => set3(&mut sps, &col(&v, "setpoint['j']")?, |s| &mut s.j_m_s3),
                "yaw" | "yaw_rate" => {
                    let y = read_vec(&v, &format!("setpoint['{key}']"), &[n])?;
                    for (sp, y) in sps.iter_mut().zip(y) {
                        if key == "yaw" {
                            sp.yaw_rad = y as f32;
                        } else {
                            sp.yaw_rate_rad_s = y as f32;
                        }
                    }
                }
                _ => {
                    return Err(PyValueError::new_err(format!(
                        "setpoint: unknown key {key:?} (keys: p, v, a, j, yaw, yaw_rate)"
                    )))
                }
            }
        }
        if !have_p {
            return Err(PyValueError::new_err("setpoint: the key 'p' is required"));
        }
        return Ok(BatchSetpoint::Many(sps));
    }
    set3(&mut sps, &col(obj, "setpoint")?, |s| &mut s.p_m);
    Ok(BatchSetpoint::Many(sps))
}

#[pymethods]
impl ControllerBatch {
    /// `n` controllers on the same model and gains (the constructor of `Controller`), or
    /// copies of the given controllers (`controllers=[...]`, their estimates included).
    #[new]
    #[pyo3(signature = (n=None, weights=None, *, controllers=None, law="composite", adapt=true, **gains))]
    fn new(
        n: Option<usize>,
        weights: Option<&Bound<'_, PyAny>>,
        controllers: Option<&Bound<'_, PyAny>>,
        law: &str,
        adapt: bool,
        gains: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        if let Some(list) = controllers {
            let mut ctrls = Vec::new();
            for c in list.try_iter()? {
                let c = c?;
                let c = c.cast::<Controller>().map_err(|_| {
                    PyTypeError::new_err("controllers: expected a sequence of hamflight.Controller")
                })?;
                ctrls.push(c.borrow().inner.clone());
            }
            return Ok(Self { ctrls });
        }
        let n = n.ok_or_else(|| PyTypeError::new_err("give n (or controllers=[...])"))?;
        let model = model_from_arg(weights)?;
        let g = gains_from_kwargs(default_gains(&model), Some(law), Some(adapt), gains)?;
        Ok(Self {
            ctrls: vec![FlightController::new(model, g); n],
        })
    }

    fn __len__(&self) -> usize {
        self.ctrls.len()
    }

    /// One step of every controller: p (N, 3), R (N, 3, 3), v_body (N, 3), w_body (N, 3);
    /// setpoint one `Setpoint` for all, positions (N, 3) or a dict of arrays with the bridge's
    /// keys (p (N, 3), v, a, j, yaw (N,), yaw_rate); dt a float or (N,); acc None or (N, 3).
    #[pyo3(signature = (p, R, v_body, w_body, setpoint, dt, acc=None))]
    #[allow(non_snake_case, clippy::too_many_arguments)]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        p: &Bound<'py, PyAny>,
        R: &Bound<'py, PyAny>,
        v_body: &Bound<'py, PyAny>,
        w_body: &Bound<'py, PyAny>,
        setpoint: &Bound<'py, PyAny>,
        dt: &Bound<'py, PyAny>,
        acc: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<BatchResult> {
        let n = self.ctrls.len();
        let got = leading_dim(p, "p", &[3])?;
        if got != n {
            return Err(PyValueError::new_err(format!(
                "p: expected shape ({n}, 3) for this batch of {n}, got ({got}, 3)"
            )));
        }
        let p = read_vec(p, "p", &[n, 3])?;
        let r = read_vec(R, "R", &[n, 3, 3])?;
        let v = read_vec(v_body, "v_body", &[n, 3])?;
        let w = read_vec(w_body, "w_body", &[n, 3])?;
        let sps = batch_setpoint(setpoint, n)?;
        let dts: Vec<f32> = match dt.extract::<f64>() {
            Ok(d) => vec![d as f32; n],
            Err(_) => read_vec(dt, "dt", &[n])?
                .into_iter()
                .map(|d| d as f32)
                .collect(),
        };
        let acc = match acc {
            Some(a) if !a.is_none() => Some(read_vec(a, "acc", &[n, 3])?),
            _ => None,
        };
        let mut rpm = vec![0f32; 4 * n];
        let mut rotor = vec![0f32; 4 * n];
        let mut thrust = vec![0f32; n];
        let mut torque = vec![0f32; 3 * n];
        let mut a = vec![0f32; FEATURES * n];
        let mut fault = vec![false; n];
        let mut sat = vec![false; n];
        let mut tilt = vec![false; n];
        for (i, c) in self.ctrls.iter_mut().enumerate() {
            let t3 = |x: &[f64]| [x[3 * i], x[3 * i + 1], x[3 * i + 2]];
            let mut rr = [0.0; 9];
            rr.copy_from_slice(&r[9 * i..9 * i + 9]);
            let state = core_state(t3(&p), rr, t3(&v), t3(&w));
            let sp = match &sps {
                BatchSetpoint::One(s) => *s,
                BatchSetpoint::Many(s) => s[i],
            };
            let meas = Measurement {
                acc_body_m_s2: acc.as_ref().map(|x| v3f(t3(x))),
            };
            let out = c.step_measured(&state, &sp, &meas, dts[i]);
            rpm[4 * i..4 * i + 4].copy_from_slice(&out.rotors.rpm);
            rotor[4 * i..4 * i + 4].copy_from_slice(&out.rotors.thrust_n);
            thrust[i] = out.wrench.thrust_n;
            torque[3 * i..3 * i + 3].copy_from_slice(out.wrench.torque_nm.as_slice());
            a[FEATURES * i..FEATURES * (i + 1)].copy_from_slice(out.a.as_slice());
            fault[i] = out.faults.is_fault();
            sat[i] = out.faults.saturation.any();
            tilt[i] = out.faults.tilt_limited;
        }
        let m2 = |data: Vec<f32>, k: usize| -> PyResult<Py<PyArray2<f32>>> {
            Ok(PyArray1::from_vec(py, data).reshape([n, k])?.unbind())
        };
        Ok(BatchResult {
            rpm: m2(rpm, 4)?,
            rotor_thrust_n: m2(rotor, 4)?,
            thrust_n: PyArray1::from_vec(py, thrust).unbind(),
            torque_nm: m2(torque, 3)?,
            a: m2(a, FEATURES)?,
            fault: PyArray1::from_vec(py, fault).unbind(),
            saturated: PyArray1::from_vec(py, sat).unbind(),
            tilt_limited: PyArray1::from_vec(py, tilt).unbind(),
        })
    }

    /// Resets every controller, or only those whose indices are given.
    #[pyo3(signature = (*indices))]
    fn reset(&mut self, indices: &Bound<'_, PyTuple>) -> PyResult<()> {
        if indices.is_empty() {
            self.ctrls.iter_mut().for_each(FlightController::reset);
            return Ok(());
        }
        for i in indices.iter() {
            let i: usize = i.extract()?;
            let n = self.ctrls.len();
            self.ctrls
                .get_mut(i)
                .ok_or_else(|| PyValueError::new_err(format!("index {i} out of range for {n}")))?
                .reset();
        }
        Ok(())
    }

    /// The estimates a, float32 (N, 6).
    #[getter]
    fn a<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let n = self.ctrls.len();
        let v: Vec<f32> = self
            .ctrls
            .iter()
            .flat_map(|c| c.estimate().iter().copied().collect::<Vec<_>>())
            .collect();
        PyArray1::from_vec(py, v).reshape([n, FEATURES])
    }
}
