//! `hamflight.Controller`, `ControllerBatch`, `Setpoint`, `StepResult`, `Faults`: the model
//! and the controller here, the gains in `gains`, the setpoint in `setpoint`, one step's
//! results in `result`, the batch in `batch`.

mod batch;
mod gains;
mod result;
mod setpoint;

pub use batch::{BatchResult, ControllerBatch};
pub use gains::{core_names, default_gains, gains_from_kwargs, model_from_arg, named, GAIN_KEYS};
pub use result::{Faults, StepResult};
pub use setpoint::Setpoint;

use gains::{gains_dict, law_name};
use result::py_bool;
use setpoint::{setpoint_arg, v3f};

use std::sync::Arc;

use hamflight::model::{
    HamiltonianModel, LearnedModel, ModelTerms, NominalModel, StateDerivative, FEATURES,
};
use hamflight::{FlightController, Measurement, State};
use nalgebra::{Matrix3, Vector4};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyTuple};

use crate::arrays::{read3, read33};

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

/// The core's state from f64 inputs, cast to f32 as the bridge casts them.
pub(super) fn core_state(p: [f64; 3], r: [f64; 9], v: [f64; 3], w: [f64; 3]) -> State {
    State {
        p_m: v3f(p),
        rot: Matrix3::from_fn(|i, j| r[3 * i + j] as f32),
        v_body_m_s: v3f(v),
        w_body_rad_s: v3f(w),
    }
}

pub(super) fn measurement(acc: Option<&Bound<'_, PyAny>>) -> PyResult<Measurement> {
    Ok(Measurement {
        acc_body_m_s2: match acc {
            Some(a) if !a.is_none() => Some(v3f(read3(a, "acc")?)),
            _ => None,
        },
    })
}

/// The exact f32 flight core: model, IDA-PBC law, adaptation, mixer.
///
/// `weights`: None for the nominal CF2X model (with its hand-chosen features), or a blob (path,
/// bytes or Blob) for the learned model. `law`: "composite" (the default) or "gradient" (the
/// paper's); `adapt=False` turns the adaptation off. Gains as keywords (see GAIN_KEYWORDS):
/// k_p_n_per_m, k_v_n_s_per_m, k_r_nm_per_rad, k_w_nm_s_per_rad, max_tilt_rad,
/// shaping_omega_rad_s, the adaptation rates c_p, c_v, c_r, c_w (feature units), a_max, and
/// motor_tau_s (the lag the composite law assumes); the ones left out are the core's for the
/// vehicle the model carries. A gain that is negative, NaN or infinite raises ValueError
/// naming it. `Controller.named(NAME)` gives the bridge's controllers.
#[pyclass(module = "hamflight._core")]
pub struct Controller {
    pub inner: FlightController<AnyModel>,
    pub name: String,
    /// Built by `Controller.named` (the registry's gains), not the constructor: what a pickle
    /// rebuilds it with.
    pub from_registry: bool,
}

impl Controller {
    /// A fresh controller on `weights` (blob bytes, or None for the nominal model) with the
    /// gains `gains` (as the `gains` getter gives them), built as `name` was
    /// ([`Controller::from_registry`]): what `__reduce__` pickles. The estimate starts at zero.
    fn restore(
        name: &str,
        from_registry: bool,
        weights: Option<&Bound<'_, PyAny>>,
        gains: &Bound<'_, PyDict>,
    ) -> PyResult<Self> {
        let gains = gains.copy()?;
        let law: Option<String> = gains.get_item("law")?.map(|v| v.extract()).transpose()?;
        let adapt: Option<bool> = gains.get_item("adapt")?.map(|v| v.extract()).transpose()?;
        gains.del_item("law").ok();
        gains.del_item("adapt").ok();
        let (model, base) = if from_registry {
            named(name, weights)?
        } else {
            let model = model_from_arg(weights)?;
            let g = default_gains(&model);
            (model, g)
        };
        let g = gains_from_kwargs(base, law.as_deref(), adapt, Some(&gains))?;
        Ok(Self {
            inner: FlightController::new(model, g),
            name: name.to_owned(),
            from_registry,
        })
    }
}

/// Unpickles a `Controller` (`Controller.__reduce__`).
#[pyfunction]
pub fn _restore_controller(
    name: &str,
    from_registry: bool,
    weights: Option<&Bound<'_, PyAny>>,
    gains: &Bound<'_, PyDict>,
) -> PyResult<Controller> {
    Controller::restore(name, from_registry, weights, gains)
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
            from_registry: false,
        })
    }

    /// The controller `host-train bridge --controller NAME` runs (CONTROLLER_NAMES; the shipped
    /// weights unless `weights` is given for the learned ones), with optional gain overrides as
    /// keywords.
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
            from_registry: true,
        })
    }

    /// Pickling (and `copy`, multiprocessing, Ray): the name, the model (its blob bytes,
    /// re-encoded by the core's encoder; None for the nominal model) and the gains. The
    /// adaptation estimate and the filters are not carried: the copy starts as after `reset()`.
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        let restore = py
            .import("hamflight._core")?
            .getattr("_restore_controller")?;
        let weights = match self.inner.model() {
            AnyModel::Learned(m) => Some(PyBytes::new(py, &hamflight::blob::encode_model(m))),
            AnyModel::Nominal(_) => None,
        };
        let args = (
            self.name.as_str(),
            self.from_registry,
            weights,
            gains_dict(py, &self.inner.gains)?,
        )
            .into_pyobject(py)?;
        PyTuple::new(py, [restore, args.into_any()])
    }

    /// One control step; returns a StepResult (rotor commands, wrench, estimate, faults).
    ///
    /// p (3,) m world; R (3, 3) body->world; v_body (3,) m/s and w_body (3,) rad/s in the body
    /// frame; setpoint a Setpoint, a position (3,) or a dict with the bridge's keys; dt s; acc
    /// the accelerometer's specific force (3,) m/s^2 body, or None. Arrays are float64,
    /// float32 or integer (or sequences), cast to f32 as the bridge casts them; another shape
    /// or dtype raises ValueError naming the argument. A bad state, setpoint or dt is not an
    /// exception: the motors go off and `faults.fault` is set.
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

    /// The model: "learned" (from a blob) or "nominal".
    #[getter]
    fn model(&self) -> &'static str {
        match self.inner.model() {
            AnyModel::Learned(_) => "learned",
            AnyModel::Nominal(_) => "nominal",
        }
    }

    /// The name: the registry's (`named`), else the model's and the law's (`adaptive-composite`).
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
