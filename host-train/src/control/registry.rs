//! The controller registry: every name the command line, the bridge and the Python package know
//! (the one list), and the controller each builds.
//!
//! Names in `host-train eval --controller`:
//! - `pid`, `geometric`: the baselines ([`BASELINES`]);
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

use crate::control::adapter::{
    gains_for, gains_with, geometric_adaptive, ida_pbc, load_learned, other_airframe,
    CoreController, CoreStep,
};
use crate::control::baselines::{DslPid, Geometric};
use crate::control::controller::Controller;
use crate::sim::scenario::Scenario;
use anyhow::{bail, Result};
use hamflight::model::NominalModel;
use hamflight::{AdaptationLaw, Gains};
use std::path::Path;

/// The weight blob `adaptive` and `learned` use when none is given.
pub const DEFAULT_WEIGHTS: &str = "weights/default.hfw";

/// Names of the core controllers, with a one-line description each.
pub const CORE_CONTROLLERS: &[(&str, &str)] = &[
    (
        "adaptive",
        "learned Hamiltonian model + adaptation (the paper's controller; the composite law, the default)",
    ),
    (
        "learned",
        "learned Hamiltonian model, adaptation off (the paper's \"without adaptation\")",
    ),
    (
        "geometric-adaptive",
        "nominal model + adaptation on a constant world force and body torque (composite law)",
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

/// Names of the baseline controllers ([`baseline_by_name`]), with a one-line description each.
pub const BASELINES: &[(&str, &str)] = &[
    (
        "pid",
        "DSL PID of gym-pybullet-drones (the paper's data-collection controller)",
    ),
    (
        "geometric",
        "Lee-Leok-McClamroch SE(3) controller on the true constants, no adaptation",
    ),
];

/// Every registered name with its description: the core's, then the baselines.
pub fn controllers() -> impl Iterator<Item = (&'static str, &'static str)> {
    CORE_CONTROLLERS.iter().chain(BASELINES).copied()
}

/// Every registered name ([`controllers`]).
pub fn names() -> Vec<&'static str> {
    controllers().map(|(n, _)| n).collect()
}

/// The adaptation law a name with a law suffix selects: `…-composite` the composite law, else
/// (`…-gradient`) the paper's. The plain names fly [`Gains::default`]'s law.
fn law_in_name(name: &str) -> AdaptationLaw {
    if name.ends_with("-composite") {
        AdaptationLaw::Composite
    } else {
        AdaptationLaw::Gradient
    }
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

/// Any controller by name: the core's ([`CORE_CONTROLLERS`]) or a baseline (`pid`, `geometric`),
/// mixing for the scenario's vehicle (its arm, rotor coefficients and top speed), as the
/// baselines, the trainer's flight check and Bitcraze's power distribution do.
pub fn by_name(
    name: &str,
    scenario: &Scenario,
    weights: Option<&Path>,
) -> Result<Box<dyn Controller>> {
    if CORE_CONTROLLERS.iter().any(|(n, _)| *n == name) {
        let mut c = core_by_name(name, weights)?;
        if let Some(af) = other_airframe(&scenario.vehicle) {
            c.set_core_airframe(af);
        }
        let c: Box<dyn Controller> = c;
        return Ok(c);
    }
    baseline_by_name(name, scenario).map_err(|e| {
        let core: Vec<&str> = CORE_CONTROLLERS.iter().map(|(n, _)| *n).collect();
        anyhow::anyhow!("{e}, {}", core.join(", "))
    })
}

/// A baseline controller ([`BASELINES`]) by name, for a scenario's vehicle.
pub fn baseline_by_name(name: &str, scenario: &Scenario) -> Result<Box<dyn Controller>> {
    match name {
        "pid" => Ok(Box::new(DslPid::new(scenario.vehicle.clone()))),
        "geometric" => Ok(Box::new(Geometric::new(scenario.vehicle.clone()))),
        _ => {
            let names: Vec<&str> = BASELINES.iter().map(|(n, _)| *n).collect();
            bail!(
                "unknown controller `{name}`: expected one of {}",
                names.join(", ")
            )
        }
    }
}
