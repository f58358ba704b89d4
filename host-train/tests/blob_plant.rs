//! A weight blob's learned model as the closed-loop replay's plant (`host-train replay
//! --plant-blob`): on synthetic logs flown by the onboard controller, a blob whose model is the
//! rigid body replays the rigid vehicle's log as the rigid scenario plant does, and a blob whose
//! torque gains are 0.3 picks the weak vehicle's log; each is far worse on the other log. So a
//! blob reading is judged by the same closed loop as a scenario reading.
//!
//! `cargo test --release -p host-train --test blob_plant -- --nocapture`

mod loop_common;

use hamflight::model::{LearnedModel, ModelWeights, PortTerms};
use host_train::io::LoopFlight;
use host_train::pipeline::{score_windows, BlobPlant, PlantTerms, Replayable, BENCHMARK_MAP};
use host_train::Scenario;
use loop_common::{diamond_base, replay_cfg};

/// The benchmark's vehicle on the brisk diamond, without the rotor drag a blob's model does not
/// carry: the rigid blob then describes the vehicle exactly.
fn base() -> Scenario {
    let mut s = diamond_base();
    s.spec.effects.rotor_drag = false;
    s
}

fn log_of(truth: &PlantTerms, seed: u64) -> LoopFlight {
    loop_common::log_of(&base(), truth, seed)
}

/// The untrained prior on the base vehicle's mass and inertia, with torque gains `gain`.
fn blob(gain: [f32; 3]) -> BlobPlant {
    let b = base();
    let j = b.vehicle.inertia_kg_m2.map(|x| x as f32);
    let mut w = ModelWeights::prior_with_inertia(&nalgebra::Vector3::from(j));
    w.mass_kg = b.vehicle.mass_kg as f32;
    let mut model = LearnedModel::new(w);
    model.set_port(PortTerms {
        torque_gain_offset: gain.map(|g| g - 1.0),
        ..PortTerms::IDENTITY
    });
    BlobPlant::new(model, &b)
}

#[test]
fn a_blob_plant_replays_like_the_vehicle_it_describes() {
    const RIGID: PlantTerms = PlantTerms {
        torque_gain: [1.0, 1.0, 1.0],
        flap_rad_s2_per_m_s: 0.0,
    };
    const WEAK: PlantTerms = PlantTerms {
        torque_gain: [0.3, 0.3, 1.0],
        flap_rad_s2_per_m_s: 0.0,
    };
    let (rigid_log, weak_log) = (log_of(&RIGID, 1), log_of(&WEAK, 2));
    let c = replay_cfg(BENCHMARK_MAP);
    let e = |f: &LoopFlight, p: &dyn Replayable| score_windows(&[f], p, &c, 100, 100).pos_rmse_m();
    let (rigid_blob, weak_blob) = (blob([1.0; 3]), blob([0.3, 0.3, 1.0]));
    let scenario_rigid = e(&rigid_log, &RIGID.apply(&base()));
    let (rr, rw) = (e(&rigid_log, &rigid_blob), e(&rigid_log, &weak_blob));
    let (wr, ww) = (e(&weak_log, &rigid_blob), e(&weak_log, &weak_blob));
    println!("rigid log: scenario plant {scenario_rigid:.4} m, rigid blob {rr:.4} m, weak blob {rw:.4} m");
    println!("weak log: rigid blob {wr:.4} m, weak blob {ww:.4} m");
    // The same vehicle in f32, by RK4 at the replay's sub-step.
    assert!(
        rr < 1.5 * scenario_rigid + 0.0005,
        "the rigid blob replays the rigid log at {rr} m, the scenario plant at {scenario_rigid} m"
    );
    assert!(rr < 0.5 * rw, "the rigid log does not pick the rigid blob");
    assert!(ww < 0.5 * wr, "the weak log does not pick the weak blob");
}
