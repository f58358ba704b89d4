//! Closed-loop identification on synthetic vehicles flown by the same onboard controller
//! (the closed-loop identification's acceptance): a plant with a known weak torque gain and one with a known
//! flapping moment are told apart by the closed-loop replay and recovered by the closed-loop
//! fit within 10 % per term, while the open-loop one-step regression on the same logs, with
//! the logged rotor speeds as noisy as the benchmark's, is biased toward zero.
//!
//! `cargo test --release -p host-train --test closed_loop_id -- --nocapture`

mod loop_common;

use host_train::io::LoopFlight;
use host_train::pipeline::{fit_loop, fit_open_loop, score_windows, PlantTerms, BENCHMARK_MAP};
use host_train::Scenario;
use loop_common::{diamond_base, replay_cfg as cfg};

fn base() -> Scenario {
    diamond_base()
}

fn log_of(truth: &PlantTerms, seed: u64) -> LoopFlight {
    loop_common::log_of(&base(), truth, seed)
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
