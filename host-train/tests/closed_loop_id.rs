//! Closed-loop identification on synthetic vehicles flown by the same onboard controller
//! (the closed-loop identification's acceptance): a plant with a known weak torque gain and one with a known
//! flapping moment are told apart by the closed-loop replay and recovered by the closed-loop
//! fit within 10 % per term, while the open-loop one-step regression on the same logs, with
//! the logged rotor speeds as noisy as the benchmark's, is biased toward zero.
//!
//! `cargo test --release -p host-train --test closed_loop_id -- --nocapture`

use host_train::control::OnboardConfig;
use host_train::io::LoopFlight;
use host_train::pipeline::{
    fit_loop, fit_open_loop, fly_log, score_windows, AccelSource, PlantTerms, ReplayConfig,
    ReplayOptions, RotorMap, SyntheticLog, BENCHMARK_MAP,
};
use host_train::sim::Trajectory;
use host_train::Scenario;

/// Legs of 1.5 s: brisk (about 0.5 m/s, 1.5 m/s²) yet short of saturating the motors, where a
/// 100 Hz log no longer pins the controller down between rows.
const SEGMENT_S: f64 = 1.5;

const BASE: &str = "scenarios/bl-calm-spiral.toml";

/// The benchmark's vehicle flying a brisk diamond: the benchmark's references move 0.3-0.5 m
/// with speeds near 1 m/s, which a slow circle does not (the controller then cancels any
/// torque gain and the logs cannot tell plants apart).
fn base() -> Scenario {
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

fn cfg(map: RotorMap) -> ReplayConfig {
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
fn log_of(truth: &PlantTerms, seed: u64) -> LoopFlight {
    let opt = SyntheticLog {
        duration_s: 20.0,
        rpm_noise_frac: 0.05,
        seed,
        ..SyntheticLog::default()
    };
    fly_log(
        &truth.apply(&base()),
        &OnboardConfig::cf21bl_2025_09(),
        &BENCHMARK_MAP,
        &opt,
    )
}

fn pos_rmse(f: &LoopFlight, plant: &PlantTerms) -> f64 {
    score_windows(&[f], &plant.apply(&base()), &cfg(BENCHMARK_MAP), 100, 100).pos_rmse_m()
}

const WEAK: PlantTerms = PlantTerms {
    torque_gain: [0.3, 0.3, 1.0],
    flap_rad_s2_per_m_s: 0.0,
};
const FLAP: PlantTerms = PlantTerms {
    torque_gain: [1.0, 1.0, 1.0],
    flap_rad_s2_per_m_s: 20.0,
};

fn within(name: &str, got: f64, want: f64, tol: f64) {
    assert!(
        (got - want).abs() <= tol,
        "{name}: fitted {got:.4}, true {want:.4} (tolerance {tol:.4})"
    );
}

/// Per term within 10 % of the truth (for a zero flapping term, within 10 % of the other
/// plant's flapping moment).
fn check_fit(label: &str, got: &PlantTerms, truth: &PlantTerms) {
    for ax in 0..2 {
        let g = truth.torque_gain[ax];
        within(
            &format!("{label} torque gain {ax}"),
            got.torque_gain[ax],
            g,
            0.1 * g,
        );
    }
    within(
        &format!("{label} flapping"),
        got.flap_rad_s2_per_m_s,
        truth.flap_rad_s2_per_m_s,
        0.1 * FLAP.flap_rad_s2_per_m_s,
    );
}

#[test]
fn the_replay_tells_weak_torque_from_flapping_and_the_loop_fit_recovers_both() {
    let weak = log_of(&WEAK, 1);
    let flap = log_of(&FLAP, 2);

    // Told apart: each log replays best on its own plant, by a wide margin over the other.
    let (ww, wf) = (pos_rmse(&weak, &WEAK), pos_rmse(&weak, &FLAP));
    let (fw, ff) = (pos_rmse(&flap, &WEAK), pos_rmse(&flap, &FLAP));
    println!("weak log: weak plant {ww:.4} m, flapping plant {wf:.4} m");
    println!("flapping log: weak plant {fw:.4} m, flapping plant {ff:.4} m");
    assert!(ww < 0.5 * wf, "the weak log does not pick the weak plant");
    assert!(
        ff < 0.5 * fw,
        "the flapping log does not pick the flapping plant"
    );

    // Recovered by the closed-loop fit, from the rigid body.
    let b = base();
    let c = cfg(BENCHMARK_MAP);
    for (label, log, truth) in [("weak", &weak, &WEAK), ("flapping", &flap, &FLAP)] {
        let fit = fit_loop(&[log], &b, &c, 100, 100, 320);
        let t = fit.terms;
        println!(
            "{label}: loop fit {:.3} / {:.3} / {:.3}, flapping {:.3} (objective {:.4}, {} evaluations)",
            t.torque_gain[0],
            t.torque_gain[1],
            t.torque_gain[2],
            t.flap_rad_s2_per_m_s,
            fit.objective,
            fit.evaluations
        );
        check_fit(label, &t, truth);

        // The open-loop regression on the same log: biased toward zero by the speeds' noise.
        let o = fit_open_loop(&[log], &b);
        println!(
            "{label}: open-loop fit {:.3} / {:.3} / {:.3}, flapping {:.3}",
            o.torque_gain[0], o.torque_gain[1], o.torque_gain[2], o.flap_rad_s2_per_m_s
        );
        for ax in 0..2 {
            let g = truth.torque_gain[ax];
            assert!(
                o.torque_gain[ax] < 0.8 * g,
                "{label}: the open-loop gain {ax} ({:.3}) is not biased low against {g}",
                o.torque_gain[ax]
            );
            // And it misses by more than the loop fit does.
            assert!(
                (o.torque_gain[ax] - g).abs() > 2.0 * (t.torque_gain[ax] - g).abs(),
                "{label}: the open-loop gain {ax} is as good as the loop fit's"
            );
        }
    }
}
