//! Commands that combine the layers (layer 4): training with its flight check, the training benchmark, the demo and the vehicle study.
//!
//! Front door: code outside `host-train/src` imports these from here, never from a submodule
//! (`tools/front-door.py` checks it): [`run_train`] (`train::run`: training, the flight check,
//! the blob), [`run_train_cli`] (`train::run_cli`: `host-train train`); the flight check's
//! [`run_flight_check`], [`require_flight_check`], [`flight_check_scenario_spec`],
//! [`FLIGHT_CHECK_ADAPTIVE_MARGIN`] (`check::{run, require, scenario_spec, ADAPTIVE_MARGIN}`);
//! [`run_prior_check`], [`run_safety_check`], [`prior_of`]; [`run_score`], [`score_table`], [`ScoreArgs`]
//! (`score::{run, table}`); [`load_response`]; [`run_vehicle_study`], [`vehicle_study_table`],
//! [`VehicleStudyArgs`], [`StudyReport`], [`logging_controller`], [`TRUE_COMPOSITE`]
//! (`vehicle_study::{run, table, ..}`).

pub mod bench;
pub mod check;
pub mod demo;
pub mod fit_port;
pub mod fit_response;
pub mod onboard;
pub mod prior_check;
pub mod replay;
pub mod robustness;
pub mod score;
pub mod train;
pub mod vehicle_study;

// The layer's front door: what code outside host-train/src uses, by these names.
pub use check::{
    require as require_flight_check, run as run_flight_check,
    scenario_spec as flight_check_scenario_spec, ADAPTIVE_MARGIN as FLIGHT_CHECK_ADAPTIVE_MARGIN,
};
pub use fit_response::load_response;
pub use onboard::replay::{AccelSource, ReplayOptions};
pub use prior_check::{prior_of, run as run_prior_check, run_with_safety as run_safety_check};
pub use replay::closed_loop::{score_windows, ReplayConfig, RotorMap};
pub use replay::identify::{fit_loop, fit_open_loop, PlantTerms};
pub use replay::plant::{BlobPlant, Replayable, Stepper};
pub use replay::synthetic::{fly_log, SyntheticLog, BENCHMARK_MAP};
pub use robustness::{
    fly_cell as fly_robustness_cell, fly_cell_watched as fly_robustness_cell_watched,
    load_scenario as load_robustness_scenario, score as robustness_score,
};
pub use score::{run as run_score, table as score_table, ScoreArgs};
pub use train::{run as run_train, run_cli as run_train_cli};
pub use vehicle_study::{
    logging_controller, run as run_vehicle_study, table as vehicle_study_table, StudyReport,
    VehicleStudyArgs, TRUE_COMPOSITE,
};
