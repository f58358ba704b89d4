//! The core's [`hamflight::FlightController`] behind the host [`Controller`] interface, so the
//! SITL plant flies the exact f32 code the firmware runs.
//!
//! Names in `host-train eval --controller`:
//! - `adaptive`: learned model + adaptation (the paper's controller; the default law is the
//!   composite one, see [`hamflight::adapt`]);
//! - `learned`: learned model, adaptation off (the paper's "without adaptation");
//! - `geometric-adaptive`: nominal model with hand-chosen features (a constant world force and
//!   a constant body torque) + adaptation — the classic adaptive baseline;
//! - `ida-pbc`: nominal model, no adaptation (the energy-based law on the true constants);
//! - `adaptive-gradient`, `adaptive-composite`, `geometric-adaptive-gradient`,
//!   `geometric-adaptive-composite`: the two adaptive controllers with the adaptation law named
//!   (the paper's gradient law or the composite law of [`hamflight::adapt`]); the plain names use
//!   the default law ([`Gains::default`]).

use crate::controller::{Controller, TrajectoryPoint};
use crate::plant::PlantState;
use crate::scenario::Scenario;
use anyhow::{bail, Context, Result};
use hamflight::model::{HamiltonianModel, LearnedModel, NominalModel};
use hamflight::{
    AdaptationLaw, FlightController, Gains, Measurement, Output, Setpoint, State, VehicleFacts,
};
use std::path::Path;

/// The weight blob `adaptive` and `learned` use when none is given.
pub const DEFAULT_WEIGHTS: &str = "weights/default.hfw";

/// Names of the core controllers, with a one-line description each.
pub const CORE_CONTROLLERS: &[(&str, &str)] = &[
    (
        "adaptive",
        "learned Hamiltonian model + adaptation (the paper's controller; the paper's gradient law)",
    ),
    (
        "learned",
        "learned Hamiltonian model, adaptation off (the paper's \"without adaptation\")",
    ),
    (
        "geometric-adaptive",
        "nominal model + adaptation on a constant world force and body torque (gradient law)",
    ),
    (
        "ida-pbc",
        "the energy-based law on the nominal model, no adaptation",
    ),
    (
        "adaptive-gradient",
        "adaptive with the paper's gradient adaptation law",
    ),
    (
        "adaptive-composite",
        "adaptive with the composite (prediction-error) adaptation law",
    ),
    (
        "geometric-adaptive-gradient",
        "geometric-adaptive with the paper's gradient adaptation law",
    ),
    (
        "geometric-adaptive-composite",
        "geometric-adaptive with the composite (prediction-error) adaptation law",
    ),
];

/// The stock vehicle's gains ([`Gains::default`]) with the adaptation law `law`.
pub fn gains_with(law: AdaptationLaw) -> Gains {
    Gains {
        law,
        ..Gains::default()
    }
}

/// A host controller that is the core's: it also gives the core's full [`Output`].
pub trait CoreStep: Controller {
    /// One core step on f32 state, setpoint and sensor measurement.
    fn core_step(&mut self, state: &State, sp: &Setpoint, meas: &Measurement, dt_s: f32) -> Output;
}

impl<M: HamiltonianModel> CoreStep for CoreController<M> {
    fn core_step(&mut self, state: &State, sp: &Setpoint, meas: &Measurement, dt_s: f32) -> Output {
        let out = self.inner.step_measured(state, sp, meas, dt_s);
        self.last = Some(out);
        out
    }
}

/// Loads a learned model from a weight blob, with the file named in any error.
pub fn load_learned(path: &Path) -> Result<LearnedModel> {
    let bytes = std::fs::read(path)
        .with_context(|| format!("cannot read weight blob `{}`", path.display()))?;
    LearnedModel::from_blob(&bytes)
        .map_err(|e| anyhow::anyhow!("weight blob `{}`: {e}", path.display()))
}

/// The adaptation law a controller name selects: `…-composite`, else the paper's gradient law.
fn law_in_name(name: &str) -> AdaptationLaw {
    if name.ends_with("-composite") {
        AdaptationLaw::Composite
    } else {
        AdaptationLaw::Gradient
    }
}

/// The gains a learned model flies with: those of the vehicle its blob describes (mass, hover
/// inertia, motor lag; [`Gains::for_vehicle`]).
pub fn gains_for(model: &LearnedModel) -> Gains {
    Gains::for_vehicle(&VehicleFacts::of(model))
}

/// A core controller by name; `weights` (default [`DEFAULT_WEIGHTS`]) for the learned ones. A
/// learned model flies with the gains for the vehicle its blob carries ([`gains_for`]).
pub fn core_by_name(name: &str, weights: Option<&Path>) -> Result<Box<dyn CoreStep>> {
    let weights = weights.unwrap_or(Path::new(DEFAULT_WEIGHTS));
    let learned = |gains: &dyn Fn(Gains) -> Gains| -> Result<Box<dyn CoreStep>> {
        let model = load_learned(weights)?;
        let g = gains(gains_for(&model));
        Ok(Box::new(CoreController::new(name, model, g)))
    };
    Ok(match name {
        "adaptive" => learned(&|g| g)?,
        "learned" => learned(&|g| Gains { adapt: false, ..g })?,
        "adaptive-gradient" | "adaptive-composite" => learned(&|g| Gains {
            law: law_in_name(name),
            ..g
        })?,
        "geometric-adaptive" => Box::new(geometric_adaptive()),
        "geometric-adaptive-gradient" | "geometric-adaptive-composite" => {
            let law = law_in_name(name);
            Box::new(CoreController::new(
                name,
                NominalModel::default(),
                gains_with(law),
            ))
        }
        "ida-pbc" => Box::new(ida_pbc()),
        _ => {
            let names: Vec<&str> = CORE_CONTROLLERS.iter().map(|(n, _)| *n).collect();
            bail!(
                "unknown core controller `{name}`: expected one of {}",
                names.join(", ")
            )
        }
    })
}

/// Any controller by name: the core's ([`CORE_CONTROLLERS`]) or a baseline (`pid`, `geometric`).
pub fn by_name(
    name: &str,
    scenario: &Scenario,
    weights: Option<&Path>,
) -> Result<Box<dyn Controller>> {
    if CORE_CONTROLLERS.iter().any(|(n, _)| *n == name) {
        let c = core_by_name(name, weights)?;
        let c: Box<dyn Controller> = c;
        return Ok(c);
    }
    crate::baselines::by_name(name, scenario).map_err(|e| {
        let core: Vec<&str> = CORE_CONTROLLERS.iter().map(|(n, _)| *n).collect();
        anyhow::anyhow!("{e}, {}", core.join(", "))
    })
}

/// Adapts a core [`FlightController`] to the host [`Controller`] trait.
pub struct CoreController<M> {
    name: String,
    inner: FlightController<M>,
    last: Option<Output>,
}

impl<M: HamiltonianModel> CoreController<M> {
    /// Wraps a controller on `model` with `gains` under `name`.
    pub fn new(name: &str, model: M, gains: Gains) -> Self {
        Self {
            name: name.to_owned(),
            inner: FlightController::new(model, gains),
            last: None,
        }
    }

    /// The wrapped core controller.
    pub fn inner(&self) -> &FlightController<M> {
        &self.inner
    }

    /// The output of the last step, if any.
    pub fn last_output(&self) -> Option<&Output> {
        self.last.as_ref()
    }
}

impl<M: HamiltonianModel> Controller for CoreController<M> {
    fn name(&self) -> &str {
        &self.name
    }

    fn reset(&mut self) {
        self.inner.reset();
        self.last = None;
    }

    fn step(
        &mut self,
        t_s: f64,
        state: &PlantState,
        reference: &TrajectoryPoint,
        dt_s: f64,
    ) -> [f64; 4] {
        self.step_measured(t_s, state, None, reference, dt_s)
    }

    fn step_measured(
        &mut self,
        _t_s: f64,
        state: &PlantState,
        acc_body_m_s2: Option<&nalgebra::Vector3<f64>>,
        reference: &TrajectoryPoint,
        dt_s: f64,
    ) -> [f64; 4] {
        let meas = Measurement {
            acc_body_m_s2: acc_body_m_s2.map(|a| a.cast::<f32>()),
        };
        let out = self
            .inner
            .step_measured(&state.into(), &reference.into(), &meas, dt_s as f32);
        self.last = Some(out);
        out.rotors.rpm.map(f64::from)
    }

    fn adaptation_estimate(&self) -> Option<Vec<f64>> {
        self.inner.gains.adapt.then(|| {
            self.inner
                .estimate()
                .iter()
                .map(|v| f64::from(*v))
                .collect()
        })
    }
}

/// The classic adaptive baseline: nominal model, hand-chosen features, adaptation on.
pub fn geometric_adaptive() -> CoreController<NominalModel> {
    CoreController::new(
        "geometric-adaptive",
        NominalModel::default(),
        Gains::default(),
    )
}

/// The energy-based law on the nominal model without adaptation.
pub fn ida_pbc() -> CoreController<NominalModel> {
    let gains = Gains {
        adapt: false,
        ..Gains::default()
    };
    CoreController::new("ida-pbc", NominalModel::default(), gains)
}
