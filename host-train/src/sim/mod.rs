//! The simulation (layer 1): the plant, scenarios, the reference, the sensor chain and its EKF.
//!
//! Front door: code outside `host-train/src` imports these from here, never from a submodule
//! (`tools/front-door.py` checks it): [`Plant`], [`PlantState`], [`VehicleParams`],
//! [`Disturbance`], [`Effects`], [`StateNoise`], [`gaussian`], [`rot_from_rpy`], [`so3_exp`]
//! (the plant); [`Scenario`], [`ScenarioSpec`]; [`SensorSpec`] (a scenario's `[sensors]`);
//! [`TrajectoryPoint`]; [`VehicleFile`], [`RPM_PER_RAD_S`] (vehicle descriptions).

pub mod ekf;
pub mod plant;
pub mod scenario;
pub mod sensors;
pub mod trajectory;
pub mod vehicle;

// The layer's front door: what code outside host-train/src uses, by these names.
pub use plant::{
    gaussian, rot_from_rpy, so3_exp, Disturbance, Effects, Plant, PlantState, StateNoise,
    VehicleParams,
};
pub use scenario::{figure_eight, Scenario, ScenarioSpec, Trajectory};
pub use sensors::SensorSpec;
pub use trajectory::TrajectoryPoint;
pub use vehicle::{VehicleFile, RPM_PER_RAD_S};
