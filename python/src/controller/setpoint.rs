//! `hamflight.Setpoint` and the setpoint arguments `step` takes.

use hamflight::Setpoint as CoreSetpoint;
use nalgebra::Vector3;
use numpy::PyArray1;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays::read3;

/// Desired position p* (m), velocity (m/s), acceleration (m/s^2), jerk (m/s^3), all world
/// frame, and yaw (rad) and yaw rate (rad/s).
///
/// The derivatives left out are zero. `Controller.step` also takes a position (3,) (held at yaw
/// 0) or a dict with the bridge's keys (`p`, `v`, `a`, `j`, `yaw`, `yaw_rate`) in its place.
#[pyclass(module = "hamflight._core", frozen, skip_from_py_object)]
#[derive(Clone)]
pub struct Setpoint {
    pub sp: CoreSetpoint,
}

pub(super) fn v3f(a: [f64; 3]) -> Vector3<f32> {
    Vector3::new(a[0] as f32, a[1] as f32, a[2] as f32)
}

pub(super) fn opt3(obj: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Vector3<f32>> {
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

    /// Desired position (m, world), float32 (3,).
    #[getter]
    fn p_m<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, self.sp.p_m.as_slice())
    }
    /// Desired velocity (m/s, world), float32 (3,).
    #[getter]
    fn v_m_s<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, self.sp.v_m_s.as_slice())
    }
    /// Desired acceleration (m/s^2, world), float32 (3,).
    #[getter]
    fn a_m_s2<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, self.sp.a_m_s2.as_slice())
    }
    /// Desired jerk (m/s^3, world), float32 (3,).
    #[getter]
    fn j_m_s3<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, self.sp.j_m_s3.as_slice())
    }
    /// Desired yaw (rad).
    #[getter]
    fn yaw_rad(&self) -> f32 {
        self.sp.yaw_rad
    }
    /// Desired yaw rate (rad/s).
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
pub(super) fn setpoint_arg(obj: &Bound<'_, PyAny>) -> PyResult<CoreSetpoint> {
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
