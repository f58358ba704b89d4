//! # host-train
//!
//! The host side of hamflight (std, f64): the SITL quadrotor plant, baseline controllers,
//! scenario files, data collection and dataset I/O, closed-loop evaluation with reports and plots.
//!
//! - [`plant`]: rigid-body CF2X on SE(3) with wind, rotor efficiency and optional effects;
//! - [`controller`]: the [`controller::Controller`] trait and [`controller::TrajectoryPoint`];
//! - [`baselines`]: the DSL PID and the geometric controller, and [`baselines::by_name`];
//! - [`scenario`]: TOML scenario files;
//! - [`collect`]: `host-train collect`, training data as in the paper's Sec. 4;
//! - [`dataset`]: the dataset format (the one reader and writer) and the training windows;
//! - [`import`]: `host-train import`, flight logs (uSD deck, CSV) to a dataset;
//! - [`usdlog`]: the Bitcraze uSD-card deck log format (reader, version-2 writer);
//! - [`usdrecord`]: a SITL flight recorded as a uSD log (`eval --log-usd`);
//! - [`eval`]: closed-loop flights, `report.json`;
//! - [`flightlog`]: the per-tick log of one flight;
//! - [`fsutil`]: atomic file writing;
//! - [`events`]: scores around rotor faults and wind steps;
//! - [`estimator`]: the adaptation's bandwidth against a sinusoidal wind;
//! - [`sensors`]: the Crazyflie's IMU, filters, pose source and estimator in the loop;
//! - [`ekf`]: the error-state EKF of the sensor chain;
//! - [`margins`]: stability margins measured by loop breaking in SITL;
//! - [`plot`]: SVG figures;
//! - [`flight`]: the core's controller behind the host interface, and the full registry;
//! - [`bridge`]: the JSON-lines bridge for external simulators;
//! - [`demo`]: collect, train, fly every controller on paper-spiral, report;
//! - [`vehicle_study`]: log, import, train and fly a vehicle the nominal model does not know.
#![warn(missing_docs)]

pub mod baselines;
pub mod bridge;
pub mod collect;
pub mod controller;
pub mod dataset;
pub mod demo;
pub mod ekf;
pub mod estimator;
pub mod eval;
pub mod events;
pub mod flight;
pub mod flightlog;
pub mod fsutil;
pub mod import;
pub mod margins;
pub mod plant;
pub mod plot;
pub mod scenario;
pub mod sensors;
pub mod train;
pub mod usdlog;
pub mod usdrecord;
pub mod vehicle_study;

pub use controller::{Controller, TrajectoryPoint};
pub use plant::{Plant, PlantState, VehicleParams};
pub use scenario::Scenario;
