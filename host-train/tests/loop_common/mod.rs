//! Shared set-up of the closed-loop replay tests: the benchmark's vehicle on a brisk diamond,
//! the replay's configuration, and a synthetic log flown by the onboard controller.
#![allow(dead_code)]

use host_train::control::OnboardConfig;
use host_train::io::LoopFlight;
use host_train::pipeline::{
    fly_log, AccelSource, PlantTerms, ReplayConfig, ReplayOptions, RotorMap, SyntheticLog,
    BENCHMARK_MAP,
};
use host_train::sim::Trajectory;
use host_train::Scenario;

/// Legs of 1.5 s: brisk (about 0.5 m/s, 1.5 m/s²) yet short of saturating the motors, where a
/// 100 Hz log no longer pins the controller down between rows.
pub const SEGMENT_S: f64 = 1.5;

/// The benchmark's vehicle.
pub const BASE: &str = "scenarios/bl-calm-spiral.toml";

/// The benchmark's vehicle flying a brisk diamond: the benchmark's references move 0.3-0.5 m
/// with speeds near 1 m/s, which a slow circle does not (the controller then cancels any
/// torque gain and the logs cannot tell plants apart).
pub fn diamond_base() -> Scenario {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut s = Scenario::load(root.join(BASE)).expect("loading the base scenario");
    s.spec.trajectory = Trajectory::Diamond {
        waypoints_m: vec![
            [0.0, 0.0, 0.6],
            [0.5, 0.3, 0.8],
            [0.0, 0.6, 0.6],
            [-0.5, 0.3, 0.4],
        ],
        segment_s: SEGMENT_S,
        hold_s: 0.0,
    };
    s
}

/// The replay of the synthetic logs, with the command map `map`.
pub fn replay_cfg(map: RotorMap) -> ReplayConfig {
    ReplayConfig {
        controller: OnboardConfig::cf21bl_2025_09(),
        map,
        options: ReplayOptions {
            substeps: 5,
            accel: AccelSource::Diff,
            // The synthetic log's reference velocity is exact, so the tightest difference is
            // the acceleration the vehicle flew (the real logs' want ±10 rows: `--accel-span`).
            accel_span: 1,
            smooth_rows: 0,
        },
        // From the start of the flight: the position integrators hold the whole flight.
        warmup_rows: 100_000,
    }
}

/// A log of `truth` on `base`, flown by the onboard controller, speeds with 5 % noise.
pub fn log_of(base: &Scenario, truth: &PlantTerms, seed: u64) -> LoopFlight {
    let opt = SyntheticLog {
        duration_s: 20.0,
        rpm_noise_frac: 0.05,
        seed,
        ..SyntheticLog::default()
    };
    fly_log(
        &truth.apply(base),
        &OnboardConfig::cf21bl_2025_09(),
        &BENCHMARK_MAP,
        &opt,
    )
}
