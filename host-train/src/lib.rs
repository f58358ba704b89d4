//! # host-train
//!
//! The host side of hamflight (std, f64): the SITL quadrotor plant, baseline controllers,
//! scenario files, data collection and dataset I/O, training, closed-loop evaluation with
//! reports and plots.
//!
//! ## The front door
//!
//! A handful of names carry a whole job; the layers below are reached through them:
//!
//! - [`Scenario`]: a flight (vehicle, reference, wind, faults, sensors) as a typed value;
//!   [`Scenario::load`] reads the TOML file format.
//! - [`ControllerSpec`]: the one place where a name such as `adaptive-composite` becomes a
//!   controller (model source, law, adaptation switch); [`control::by_name`] builds it for a
//!   scenario's vehicle as a [`Controller`].
//! - [`fly_scenario`]: the one simulator loop; [`fly_stage`] is the same loop with a [`Stage`]
//!   (sensing, control and actuation from outside: the Crazyflie's chain, Bitcraze's C code, a
//!   QEMU link) in place of the sensors and the controller. [`Report`] scores the log.
//! - [`TrainJob`]: a typed training configuration (serde) that the CLI and Python both build
//!   and run through [`pipeline::run_train`] (with a printed summary: [`pipeline::run_train_cli`]).
//!
//! ```no_run
//! use host_train::{control::by_name, fly_scenario, Report, Scenario};
//!
//! let scenario = Scenario::load("scenarios/paper-spiral.toml")?;
//! let mut controller = by_name("adaptive", &scenario, None)?;
//! let log = fly_scenario(&scenario, controller.as_mut());
//! let report = Report::from_flight(&log, &scenario, None);
//! println!("RMSE {:.3} cm", report.rmse_pos_m * 100.0);
//! # Ok::<(), anyhow::Error>(())
//! ```
//!
//! `examples/fly_one.rs` is this program with arguments.
//!
//! ## The layers
//!
//! The modules are layers; each imports only from its own or lower layers
//! (`tools/layers.py` checks it):
//!
//! 1. [`sim`]: the simulation — the rigid-body CF2X plant ([`sim::plant`]), scenario files
//!    ([`sim::scenario`]), the reference ([`sim::trajectory`]), the Crazyflie's sensor chain
//!    ([`sim::sensors`]) and its error-state EKF ([`sim::ekf`]);
//!    [`io`]: files — atomic writing ([`io::files`]), the per-tick flight log
//!    ([`io::flightlog`]), the Bitcraze uSD-card deck log ([`io::usdlog`]) and the dataset
//!    format with its training windows ([`io::dataset`]);
//! 2. [`control`]: the [`control::controller::Controller`] trait, the baselines
//!    ([`control::baselines`]), the core's controller behind it ([`control::adapter`]) and the
//!    one name registry ([`control::registry`]); [`report`]: SVG figures ([`report::plot`]);
//! 3. [`data`]: `host-train collect` ([`data::collect`]) and `host-train import`
//!    ([`data::import`]); [`train`]: the Hamiltonian model's training, flight-free;
//!    [`fly`]: the SITL loop and `report.json` ([`fly::eval`]), scores around events
//!    ([`fly::events`]), the adaptation's tracking and bandwidth ([`fly::track`]), stability
//!    margins ([`fly::margins`]), a SITL flight as a uSD log ([`fly::usdrecord`]);
//! 4. [`pipeline`]: the commands that combine them — training with its flight check
//!    ([`pipeline::train`]), `bench-train` ([`pipeline::bench`]), `demo` ([`pipeline::demo`]),
//!    `vehicle-study` ([`pipeline::vehicle_study`]); [`bridge`]: the JSON-lines bridge for
//!    external simulators.
//!
//! Code outside `host-train/src` (its tests and examples, the Python module, `tools/`) imports
//! from the crate root and the layers only, by what each layer re-exports (its front door), never
//! from a layer's submodules (`tools/front-door.py` checks it).
#![warn(missing_docs)]

pub mod bridge;
pub mod control;
pub mod data;
pub mod fly;
pub mod io;
pub mod pipeline;
pub mod report;
pub mod sim;
pub mod train;

pub use control::controller::Controller;
pub use control::spec::{ControllerSpec, ModelSource};
pub use fly::{fly_scenario, fly_stage, Report, Stage};
pub use sim::plant::{Plant, PlantState, VehicleParams};
pub use sim::scenario::Scenario;
pub use sim::trajectory::TrajectoryPoint;
pub use train::TrainJob;
