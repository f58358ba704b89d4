//! The controller registry: the controller each name of [`ControllerSpec::ALL`] (the one list
//! the command line, the bridge and the Python package know) builds.
//!
//! Names in `host-train eval --controller`:
//! - `pid`, `geometric`: the baselines ([`ControllerSpec::ALL`]);
//! - `adaptive`: learned model + adaptation (the paper's controller, with the default law: the
//!   composite one, see [`hamflight::adapt`]);
//! - `learned`: learned model, adaptation off (the paper's "without adaptation");
//! - `geometric-adaptive`: nominal model with hand-chosen features (a constant world force and
//!   a constant body torque) + adaptation — the classic adaptive baseline;
//! - `ida-pbc`: nominal model, no adaptation (the energy-based law on the true constants);
//! - `adaptive-gradient`, `adaptive-composite`, `geometric-adaptive-gradient`,
//!   `geometric-adaptive-composite`: the two adaptive controllers with the adaptation law named
//!   (the paper's gradient law or the composite law of [`hamflight::adapt`]); the plain names use
//!   the default law ([`Gains::default`]).

use crate::control::adapter::{gains_for, load_learned, other_airframe, CoreController, CoreStep};
use crate::control::baselines::{DslPid, Geometric};
use crate::control::controller::Controller;
pub use crate::control::spec::{ControllerKind, ControllerSpec, ModelSource};
use crate::sim::scenario::Scenario;
use anyhow::{bail, Result};
use hamflight::model::NominalModel;
use hamflight::Gains;
use std::path::Path;

/// The weight blob `adaptive` and `learned` use when none is given.
pub const DEFAULT_WEIGHTS: &str = "weights/default.hfw";

/// Every registered name with its description: the core's, then the baselines
/// ([`ControllerSpec::ALL`]).
pub fn controllers() -> impl Iterator<Item = (&'static str, &'static str)> {
    ControllerSpec::ALL.iter().map(|s| (s.name, s.about))
}

/// Every registered name ([`controllers`]).
pub fn names() -> Vec<&'static str> {
    controllers().map(|(n, _)| n).collect()
}

/// A core controller by name; `weights` (default [`DEFAULT_WEIGHTS`]) for the learned ones. A
/// learned model flies with the gains for the vehicle its blob carries ([`gains_for`]).
pub fn core_by_name(name: &str, weights: Option<&Path>) -> Result<Box<dyn CoreStep>> {
    core_by_spec(&ControllerSpec::parse_core(name)?, weights)
}

/// A core controller of a parsed name ([`core_by_name`]); a baseline's spec is an error.
pub fn core_by_spec(spec: &ControllerSpec, weights: Option<&Path>) -> Result<Box<dyn CoreStep>> {
    let name = spec.name;
    Ok(match spec.model() {
        Some(ModelSource::Learned) => {
            let model = load_learned(weights.unwrap_or(Path::new(DEFAULT_WEIGHTS)))?;
            let g = spec.gains(gains_for(&model));
            Box::new(CoreController::new(name, model, g))
        }
        Some(ModelSource::Nominal) => {
            let g = spec.gains(Gains::default());
            Box::new(CoreController::new(name, NominalModel::default(), g))
        }
        None => bail!("`{name}` is a baseline, not a core controller"),
    })
}

/// Any controller by name ([`ControllerSpec`]): the core's or a baseline (`pid`, `geometric`),
/// mixing for the scenario's vehicle (its arm, rotor coefficients and top speed), as the
/// baselines, the trainer's flight check and Bitcraze's power distribution do.
pub fn by_name(
    name: &str,
    scenario: &Scenario,
    weights: Option<&Path>,
) -> Result<Box<dyn Controller>> {
    let spec = ControllerSpec::parse(name)?;
    if spec.is_core() {
        let mut c = core_by_spec(&spec, weights)?;
        if let Some(af) = other_airframe(&scenario.vehicle) {
            c.set_core_airframe(af);
        }
        let c: Box<dyn Controller> = c;
        return Ok(c);
    }
    baseline_by_name(name, scenario)
}

/// A baseline controller (`pid`, `geometric`) by name, for a scenario's vehicle.
pub fn baseline_by_name(name: &str, scenario: &Scenario) -> Result<Box<dyn Controller>> {
    match ControllerSpec::parse(name)?.kind {
        ControllerKind::Pid => Ok(Box::new(DslPid::new(scenario.vehicle.clone()))),
        ControllerKind::Geometric => Ok(Box::new(Geometric::new(scenario.vehicle.clone()))),
        ControllerKind::Core { .. } => bail!("`{name}` is a core controller, not a baseline"),
    }
}
