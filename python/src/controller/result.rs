//! `hamflight.StepResult` and `hamflight.Faults`: what one step gives.

use hamflight::Output;
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Faults and conditions of one step; any of the first four forces motors off.
///
/// bad_state, bad_setpoint, bad_dt and numeric are faults: the output is motors off and `fault`
/// (also `bool(faults)`) is set. saturated (the mixer's saturated_yaw, saturated_roll_pitch,
/// saturated_thrust) and tilt_limited are conditions: the output is still used. `to_dict()` is
/// the bridge's `faults` object.
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
    /// The state had a NaN or infinite component, or its R is not a rotation.
    #[getter]
    fn bad_state(&self) -> bool {
        self.f.bad_state
    }
    /// The setpoint had a NaN or infinite component.
    #[getter]
    fn bad_setpoint(&self) -> bool {
        self.f.bad_setpoint
    }
    /// dt was not in (0, 0.1] s.
    #[getter]
    fn bad_dt(&self) -> bool {
        self.f.bad_dt
    }
    /// The model or the law produced a non-finite or singular value.
    #[getter]
    fn numeric(&self) -> bool {
        self.f.numeric
    }
    /// The mixer saturated (any of the three below; a condition, the output is still used).
    #[getter]
    fn saturated(&self) -> bool {
        self.f.saturation.any()
    }
    /// The yaw torque was scaled down to keep roll/pitch authority.
    #[getter]
    fn saturated_yaw(&self) -> bool {
        self.f.saturation.yaw
    }
    /// The roll/pitch torques were scaled down (not even they fit).
    #[getter]
    fn saturated_roll_pitch(&self) -> bool {
        self.f.saturation.roll_pitch
    }
    /// The collective thrust was shifted to fit the torques between the limits.
    #[getter]
    fn saturated_thrust(&self) -> bool {
        self.f.saturation.thrust
    }
    /// The tilt limit shaped the desired attitude (a condition).
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
    /// `fault`.
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

pub(super) fn py_bool(b: bool) -> &'static str {
    if b {
        "True"
    } else {
        "False"
    }
}

/// One step's output (float32, as the core computes it): what `Controller.step` returns.
///
/// The rotor commands (`rpm`, `rotor_thrust_n`), the wrench to command (`thrust_n`,
/// `torque_nm`, `wrench`), the disturbance-weight estimate `a`, the position error `e_p` and
/// the `faults`.
#[pyclass(module = "hamflight._core", frozen)]
pub struct StepResult {
    pub(super) out: Output,
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
    /// Collective thrust to command (N): what a mixer should be handed.
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
    /// The step's faults and conditions.
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
