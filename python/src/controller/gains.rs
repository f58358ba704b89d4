//! The gains' keywords, and the models and gains the constructors start from.

use super::AnyModel;
use std::sync::Arc;

use hamflight::model::NominalModel;
use hamflight::{AdaptationLaw, Gains, VehicleFacts};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::blob::{model_from_weights, Blob};
use host_train::{ControllerSpec, ModelSource};

/// The gains a model flies with unless told otherwise: the core's, from the vehicle facts the
/// model carries (its mass and motor lag), with the core's default law (the composite one).
pub fn default_gains(model: &AnyModel) -> Gains {
    Gains::for_vehicle(&VehicleFacts::of(model))
}

pub(super) fn parse_law(law: &str) -> PyResult<AdaptationLaw> {
    match law {
        "gradient" => Ok(AdaptationLaw::Gradient),
        "composite" => Ok(AdaptationLaw::Composite),
        _ => Err(PyValueError::new_err(format!(
            "law: expected \"gradient\" or \"composite\", got {law:?}"
        ))),
    }
}

pub(super) fn law_name(law: AdaptationLaw) -> &'static str {
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

pub(super) fn gain_slot<'a>(g: &'a mut Gains, key: &str) -> Option<&'a mut f32> {
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
            // Every gain is a rate, a bound or a time constant: finite (as f32 too) and ≥ 0.
            if !(value >= 0.0 && (value as f32).is_finite()) {
                return Err(PyValueError::new_err(format!(
                    "{key}: expected a finite number >= 0, got {value}"
                )));
            }
            *slot = value as f32;
        }
    }
    Ok(g)
}

pub(super) fn gains_dict<'py>(py: Python<'py>, g: &Gains) -> PyResult<Bound<'py, PyDict>> {
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
