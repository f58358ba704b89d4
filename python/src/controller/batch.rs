//! `hamflight.ControllerBatch` and `BatchResult`: N controllers stepped by one call.

use super::{
    core_state, default_gains, gains_from_kwargs, model_from_arg, v3f, AnyModel, Controller,
    Setpoint,
};

use hamflight::model::FEATURES;
use hamflight::{FlightController, Measurement, Setpoint as CoreSetpoint};
use nalgebra::Vector3;
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::arrays::{leading_dim, read_vec};

/// One batched step, one row per vehicle (float32; bool for the flags).
///
/// Row i is what `Controller.step` gives vehicle i: rpm and rotor_thrust_n (N, 4), thrust_n
/// (N,), torque_nm (N, 3), a (N, 6), and the flags fault, saturated, tilt_limited (N,).
#[pyclass(module = "hamflight._core", frozen)]
pub struct BatchResult {
    /// Rotor speed commands, rotors 1..4 (rpm), float32 (N, 4).
    #[pyo3(get)]
    rpm: Py<PyArray2<f32>>,
    /// Rotor thrust commands (N), float32 (N, 4).
    #[pyo3(get)]
    rotor_thrust_n: Py<PyArray2<f32>>,
    /// Collective thrust to command (N), float32 (N,).
    #[pyo3(get)]
    thrust_n: Py<PyArray1<f32>>,
    /// Body torques to command (N·m), float32 (N, 3).
    #[pyo3(get)]
    torque_nm: Py<PyArray2<f32>>,
    /// The disturbance-weight estimates, float32 (N, 6).
    #[pyo3(get)]
    a: Py<PyArray2<f32>>,
    /// The output was forced to motors off (`Faults.fault`), bool (N,).
    #[pyo3(get)]
    fault: Py<PyArray1<bool>>,
    /// The mixer saturated (`Faults.saturated`), bool (N,).
    #[pyo3(get)]
    saturated: Py<PyArray1<bool>>,
    /// The tilt limit shaped the desired attitude (`Faults.tilt_limited`), bool (N,).
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
///
/// `ControllerBatch(n, weights, law=..., adapt=..., **gains)`: `n` controllers on the same
/// model and gains, as the `Controller` constructor takes them; or
/// `ControllerBatch(controllers=[...])`: copies of the given controllers, their estimates
/// included. Row i of a step equals what a `Controller` would give. `len(batch)` is N.
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

    /// N, the number of controllers.
    fn __len__(&self) -> usize {
        self.ctrls.len()
    }

    /// One step of every controller; returns a BatchResult.
    ///
    /// p (N, 3), R (N, 3, 3), v_body (N, 3), w_body (N, 3); setpoint one Setpoint for all,
    /// positions (N, 3) or a dict of arrays with the bridge's keys (p (N, 3), v, a, j, yaw (N,),
    /// yaw_rate); dt a float or (N,); acc None or (N, 3).
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
