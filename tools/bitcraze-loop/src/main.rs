//! `bitcraze-loop`: hamflight's controllers and Bitcraze's own, flown on the SITL plant behind
//! Bitcraze's real sensor filters, Kalman estimator and power distribution.
//!
//! Everyone sees the state Bitcraze's Kalman core makes of our IMU and motion-capture models,
//! and every controller's output goes through Bitcraze's power distribution and capping (ours
//! as the Crazyflie app hands it over: a force-torque command). The plant is the scenario's
//! vehicle with the Crazyflie's published rotor geometry (Bitcraze's `ARM_LENGTH` and
//! `THRUST2TORQUE`), so that the power distribution's mixing is the plant's. See
//! `docs/crazyflie-chain.md` for the command and the table.
//!
//! Needs a crazyflie-firmware checkout at build time (`$CRAZYFLIE_BASE`, configured with `make
//! cf2_defconfig && make prepare`); without one the binary says how to get it.

#[cfg(bitcraze)]
mod ffi;
#[cfg(bitcraze)]
mod mellinger_ref;
#[cfg(bitcraze)]
mod study;

use clap::Parser;
use std::path::PathBuf;

/// The scenarios flown by default: hover, a calm spiral, the paper's disturbance, a mid-flight
/// rotor loss and a steady wind, each with the chain's sensor models and a 50 ms motor lag.
pub const DEFAULT_SCENARIOS: [&str; 6] = [
    "scenarios/cf-hover-lag50.toml",
    "scenarios/cf-calm-spiral.toml",
    "scenarios/cf-paper-spiral.toml",
    "scenarios/cf-rotor-loss.toml",
    "scenarios/cf-hover-wind.toml",
    "scenarios/gust-spiral.toml",
];

/// Ours (the default law, the composite law, the nominal model) and Bitcraze's four.
pub const DEFAULT_CONTROLLERS: [&str; 7] = [
    "adaptive",
    "adaptive-composite",
    "geometric-adaptive",
    "bc-pid",
    "bc-mellinger",
    "bc-lee",
    "bc-brescianini",
];

/// Fly hamflight's controllers beside Bitcraze's, behind Bitcraze's own estimator and power
/// distribution (compiled from a crazyflie-firmware checkout), on hamflight's SITL plant.
///
/// Build (from the repository root; the workspace build keeps one set of compiled dependencies):
///
///   cd $CRAZYFLIE_BASE && make cf2_defconfig && make prepare && cd -
///   CRAZYFLIE_BASE=/path/to/crazyflie-firmware cargo build --release --workspace --all-targets
///   ./target/release/bitcraze-loop --out /tmp/bc
#[derive(Parser, Debug)]
#[command(version, verbatim_doc_comment)]
pub struct Args {
    /// Scenario files to fly, comma-separated. Their [sensors] table sets the IMU noise and
    /// filter cutoffs and the pose source (the estimator is always Bitcraze's here); scenarios
    /// without one use the chain's defaults.
    #[arg(long, value_delimiter = ',', default_values_t = DEFAULT_SCENARIOS.map(String::from))]
    pub scenarios: Vec<String>,
    /// Controllers, comma-separated: any core controller of `host-train eval` (adaptive,
    /// adaptive-composite, geometric-adaptive, learned, ...) and Bitcraze's bc-pid,
    /// bc-mellinger, bc-lee, bc-brescianini.
    #[arg(long, value_delimiter = ',', default_values_t = DEFAULT_CONTROLLERS.map(String::from))]
    pub controllers: Vec<String>,
    /// Weight blob for the learned controllers.
    #[arg(long, default_value = host_train::control::DEFAULT_WEIGHTS)]
    pub weights: PathBuf,
    /// The state every controller is given: `kalman` (Bitcraze's estimate of our sensor models)
    /// or `truth` (the true position, velocity and attitude; body rates and acceleration still
    /// through Bitcraze's filters), to tell the estimator's part from the filters'.
    #[arg(long, value_enum, default_value_t = StateSource::Kalman)]
    pub state: StateSource,
    /// Write report.json (every flight's scores) and table.md here (created if missing).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Also write the flights' scores as JSON here (no wall-clock times, so the same build and
    /// checkout always write the same file): the source of the docs' Bitcraze tables,
    /// `docs/data/bitcraze-loop.json` (and `bitcraze-loop-truth.json` with `--state truth`),
    /// which `tools/bitcraze-loop/doc-data.sh` regenerates.
    #[arg(long, value_name = "FILE")]
    pub scores: Option<PathBuf>,
    /// Instead of flying: feed Bitcraze's Mellinger (the C) and hamflight's port
    /// (host-train's control::onboard) the same synthetic inputs, 600 steps at 500 Hz, write
    /// the inputs and the C's motor commands to FILE (the fixture
    /// host-train/tests/data/mellinger_c_reference.csv) and print the largest difference.
    #[arg(long, value_name = "FILE")]
    pub mellinger_reference: Option<PathBuf>,
}

/// Where the controllers' position, velocity and attitude come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum StateSource {
    /// Bitcraze's Kalman estimate.
    Kalman,
    /// The plant's true state.
    Truth,
}

#[cfg(bitcraze)]
fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    if let Some(path) = &args.mellinger_reference {
        let worst = mellinger_ref::run(path)?;
        println!(
            "wrote {} ({} rows); largest |C - port| = {worst} PWM counts",
            path.display(),
            mellinger_ref::ROWS
        );
        return Ok(());
    }
    study::run(&args)
}

#[cfg(not(bitcraze))]
fn main() {
    let _ = Args::parse();
    eprintln!(
        "bitcraze-loop was built without Bitcraze's code.\n\
         It compiles it from a crazyflie-firmware checkout named by CRAZYFLIE_BASE at build time:\n\n  \
         git clone --recursive https://github.com/bitcraze/crazyflie-firmware\n  \
         (cd crazyflie-firmware && make cf2_defconfig && make prepare)\n  \
         CRAZYFLIE_BASE=$PWD/crazyflie-firmware cargo build --release --workspace --all-targets\n  \
         ./target/release/bitcraze-loop --help\n"
    );
    std::process::exit(2);
}
