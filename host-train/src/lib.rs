//! # host-train
//!
//! The host side of hamflight (std, f64): the SITL quadrotor plant, baseline controllers,
//! scenario files, data collection and dataset I/O, closed-loop evaluation with reports and plots.
//!
//! - [`plant`]: rigid-body CF2X on SE(3) with wind, rotor efficiency and optional effects;
//! - [`controller`]: the [`controller::Controller`] trait and [`controller::TrajectoryPoint`];
//! - [`baselines`]: the DSL PID and the geometric controller, and [`baselines::by_name`];
//! - [`scenario`]: TOML scenario files;
//! - [`dataset`]: `collect` (paper Sec. 4) and the dataset format with its loader;
//! - [`eval`]: closed-loop flights, `report.json`;
//! - [`events`]: scores around rotor faults and wind steps;
//! - [`estimator`]: the adaptation's bandwidth against a sinusoidal wind;
//! - [`plot`]: SVG figures;
//! - [`flight`]: the core's controller behind the host interface, and the full registry;
//! - [`bridge`]: the JSON-lines bridge for external simulators;
//! - [`demo`]: collect, train, fly every controller on paper-spiral, report.
#![warn(missing_docs)]

pub mod baselines;
pub mod bridge;
pub mod controller;
pub mod dataset;
pub mod demo;
pub mod estimator;
pub mod eval;
pub mod events;
pub mod flight;
pub mod plant;
pub mod plot;
pub mod scenario;
pub mod train;

pub use controller::{Controller, TrajectoryPoint};
pub use plant::{Plant, PlantState, VehicleParams};
pub use scenario::Scenario;
