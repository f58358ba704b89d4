//! Baseline controllers and the controller registry.

pub mod geometric;
pub mod pid;

use anyhow::{bail, Result};

use crate::controller::Controller;
use crate::scenario::Scenario;

pub use geometric::{Geometric, GeometricGains};
pub use pid::{DslPid, DslPidGains};

/// Names accepted by [`by_name`], with a one-line description each.
pub const CONTROLLERS: &[(&str, &str)] = &[
    (
        "pid",
        "DSL PID of gym-pybullet-drones (the paper's data-collection controller)",
    ),
    (
        "geometric",
        "Lee-Leok-McClamroch SE(3) controller on the true constants, no adaptation",
    ),
];

/// Build a baseline controller by name for a scenario's vehicle. Other modules extend the
/// registry by matching their own names first and falling back to this function.
pub fn by_name(name: &str, scenario: &Scenario) -> Result<Box<dyn Controller>> {
    match name {
        "pid" => Ok(Box::new(DslPid::new(scenario.vehicle.clone()))),
        "geometric" => Ok(Box::new(Geometric::new(scenario.vehicle.clone()))),
        _ => {
            let names: Vec<&str> = CONTROLLERS.iter().map(|(n, _)| *n).collect();
            bail!(
                "unknown controller `{name}`: expected one of {}",
                names.join(", ")
            )
        }
    }
}
