//! Flying (layer 3): the one SITL loop and its scores, events, adaptation tracking, margins and uSD recording.
//!
//! Front door: code outside `host-train/src` imports these from here, never from a submodule
//! (`tools/front-door.py` checks it): [`fly_scenario`] (`eval::fly`), [`run_eval`]
//! (`host-train eval`), [`Report`], [`FlightLog`], [`EvalArgs`], [`CRASH_ERR_M`];
//! [`fly_with_states`] (`fly_scenario` with the velocity, body rates and estimate per tick),
//! [`StateLog`]; [`fly_stage`], [`Stage`], [`Actuation`] (the loop with an outside sensing,
//! control and actuation stage in place of the sensors and a controller: bitcraze-loop's);
//! [`event_metrics`], [`EventMetrics`], [`RECOVERED_ERR_M`]; [`measure_point`], [`margins_of`],
//! [`LoopPoint`]; [`run_track`], [`TrackArgs`], [`measure_bandwidth_point`] (`track::measure`),
//! [`estimate_std`], [`BANDWIDTH_FREQUENCIES_HZ`] (`track::FREQUENCIES_HZ`); [`UsdRecorder`],
//! [`usd_logged_vars`] (`usdrecord::logged_vars`).

pub mod eval;
pub mod events;
pub mod margins;
pub mod report;
pub mod track;
pub mod usdrecord;

// The layer's front door: what code outside host-train/src uses, by these names.
pub use eval::{fly as fly_scenario, run as run_eval};
pub use eval::{fly_stage, Actuation, Stage};
pub use eval::{fly_with_states, EvalArgs, FlightLog, Report, StateLog, CRASH_ERR_M};
pub use events::{event_metrics, EventMetrics, RECOVERED_ERR_M};
pub use margins::{margins_of, measure_point, LoopPoint};
pub use track::FREQUENCIES_HZ as BANDWIDTH_FREQUENCIES_HZ;
pub use track::{estimate_std, measure as measure_bandwidth_point, run_track, TrackArgs};
pub use usdrecord::{logged_vars as usd_logged_vars, UsdRecorder};
