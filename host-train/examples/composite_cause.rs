//! Why a learned blob can crash the composite adaptation law: each candidate cause, switched off
//! one at a time in the same blob, flown on the same scenarios (`docs/vehicles.md`).
//!
//! `cargo run --release -p host-train --example composite_cause -- BLOB [SCENARIO.toml ...]`
//!
//! Variants (all `adaptive-composite`, the blob's own mass):
//! - `as trained`: the blob as it is, the prediction assuming the blob's motor lag;
//! - `lag 50 ms` / `lag = vehicle's`: the prediction's assumed motor lag forced;
//! - `g: no x/y force`: the g head's body x and y force rows zeroed (no input makes them);
//! - `g: no torque→force`: the torque columns of the three force rows zeroed;
//! - `g: thrust along z only`: both (the force rows take only thrust, along body z);
//! - `J := true`: the J⁻¹ head replaced by the first scenario's true (constant, diagonal) J;
//! - `J_z := true`: the same with the learned J_x, J_y at hover and the true J_z;
//! - `J := true, g torque rows := true`: also g's torque rows set to the identity pattern;
//! - `nominal, true m and J`: the nominal model told the true mass and inertia (the prediction's
//!   row scaling for a non-stock vehicle, with an exact g).
//!
//! Also printed: the blob's g at hover (force rows), and the gradient law on the same blob.

use hamflight::model::{HamiltonianModel, LearnedModel, ModelWeights, NominalModel};
use hamflight::{AdaptationLaw, Gains, VehicleFacts};
use host_train::control::{load_learned, CoreController};
use host_train::fly::{fly_scenario, Report};
use host_train::sim::Scenario;
use nalgebra::{Matrix3, Vector3};
use std::path::PathBuf;

fn zero_gain_outputs(w: &ModelWeights, keep: impl Fn(usize, usize) -> bool) -> ModelWeights {
    let mut out = *w;
    for n in 0..24 {
        let (i, k) = (n / 4, n % 4);
        if !keep(i, k) {
            out.gain.l2.weight[n] = [0.0; hamflight::model::HIDDEN];
            out.gain.l2.bias[n] = 0.0;
        }
    }
    out
}

/// `w` with the J⁻¹ head constant at the diagonal inertia `j` (kg·m²).
fn with_inertia(w: &ModelWeights, j: &Vector3<f32>) -> ModelWeights {
    let mut out = *w;
    out.inertia.l2.weight = [[0.0; hamflight::model::HIDDEN]; hamflight::model::JINV_OUT];
    out.inertia.l2.bias = hamflight::model::learned::l_for_diagonal_inertia(j);
    out
}

/// `w` with g's torque rows (3..6) constant at the true pattern.
fn with_true_torque_rows(w: &ModelWeights) -> ModelWeights {
    let mut out = *w;
    let t = hamflight::model::learned::true_gain_output();
    let rows = out
        .gain
        .l2
        .weight
        .iter_mut()
        .zip(out.gain.l2.bias.iter_mut());
    for ((w, b), t) in rows.zip(t).skip(12) {
        *w = [0.0; hamflight::model::HIDDEN];
        *b = t;
    }
    out
}

fn score<M: HamiltonianModel>(sc: &Scenario, model: M, gains: Gains) -> String {
    let mut c = CoreController::new("cause", model, gains);
    let r = Report::from_log(&fly_scenario(sc, &mut c), None);
    match (r.crash_time_s, r.rmse_pos_window_m) {
        (Some(t), _) => format!("crash {t:.2} s"),
        (None, Some(x)) => format!("{:.3}", 100.0 * x),
        _ => "—".into(),
    }
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let blob = PathBuf::from(args.next().unwrap_or_else(|| "weights/default.hfw".into()));
    let scenarios: Vec<PathBuf> = args.map(PathBuf::from).collect();
    let scenarios = if scenarios.is_empty() {
        vec![
            PathBuf::from("scenarios/mismatch-calm-spiral.toml"),
            PathBuf::from("scenarios/mismatch-paper-spiral.toml"),
        ]
    } else {
        scenarios
    };
    let model = load_learned(&blob)?;
    let w = model.weights;
    let g = model.gain(&Matrix3::identity());
    println!(
        "blob {}: mass {} kg, motor τ {} s",
        blob.display(),
        w.mass_kg,
        model.motor_tau_s()
    );
    for i in 0..3 {
        println!(
            "  g at hover, force row {i}: [{:.4}, {:.3}, {:.3}, {:.3}]",
            g[(i, 0)],
            g[(i, 1)],
            g[(i, 2)],
            g[(i, 3)]
        );
    }
    let composite = |m: &LearnedModel| Gains {
        law: AdaptationLaw::Composite,
        ..Gains::for_vehicle(&VehicleFacts::of(m))
    };
    let j_true = match scenarios.first() {
        Some(s) => Vector3::from(Scenario::load(s)?.vehicle.inertia_kg_m2.map(|x| x as f32)),
        None => Vector3::new(1.4e-5, 1.4e-5, 2.17e-5),
    };
    let j_learned = VehicleFacts::of(&model).inertia_kg_m2;
    let j_learned_z_true = Vector3::new(j_learned.x, j_learned.y, j_true.z);
    let tau = model.motor_tau_s();
    let relag = |w: ModelWeights| LearnedModel::new(w).with_motor_tau_s(tau);
    let variants: Vec<(&str, LearnedModel)> = vec![
        ("as trained", model),
        ("J := true", relag(with_inertia(&w, &j_true))),
        (
            "J_z := true (J_x, J_y as learned)",
            relag(with_inertia(&w, &j_learned_z_true)),
        ),
        (
            "J := true, g torque rows := true",
            relag(with_true_torque_rows(&with_inertia(&w, &j_true))),
        ),
        (
            "g: no x/y force",
            LearnedModel::new(zero_gain_outputs(&w, |i, _| i >= 2)),
        ),
        (
            "g: no torque→force",
            LearnedModel::new(zero_gain_outputs(&w, |i, k| i >= 3 || k == 0)),
        ),
        (
            "g: thrust along z only",
            LearnedModel::new(zero_gain_outputs(&w, |i, k| i >= 3 || (i == 2 && k == 0))),
        ),
    ];
    print!("| variant |");
    for s in &scenarios {
        print!(" {} |", s.file_stem().unwrap_or_default().to_string_lossy());
    }
    println!();
    for (name, m) in &variants {
        print!("| {name} |");
        for s in &scenarios {
            let sc = Scenario::load(s)?;
            print!(" {} |", score(&sc, *m, composite(m)));
        }
        println!();
    }
    for (name, tau) in [("lag 50 ms", Some(0.05f32)), ("lag = vehicle's", None)] {
        print!("| as trained, {name} |");
        for s in &scenarios {
            let sc = Scenario::load(s)?;
            let mut gains = composite(&model);
            gains.composite.motor_tau_s = tau.unwrap_or(sc.spec.effects.motor_tau_s as f32);
            print!(" {} |", score(&sc, model, gains));
        }
        println!();
    }
    print!("| nominal, true m and J, composite |");
    for s in &scenarios {
        let sc = Scenario::load(s)?;
        let j = Vector3::from(sc.vehicle.inertia_kg_m2.map(|x| x as f32));
        let nominal = NominalModel::new(sc.vehicle.mass_kg as f32, Matrix3::from_diagonal(&j));
        let gains = Gains {
            law: AdaptationLaw::Composite,
            ..Gains::for_vehicle(&VehicleFacts::of(&nominal))
        };
        print!(" {} |", score(&sc, nominal, gains));
    }
    println!();
    print!("| as trained, gradient law |");
    for s in &scenarios {
        let sc = Scenario::load(s)?;
        let gains = Gains::for_vehicle(&VehicleFacts::of(&model));
        print!(" {} |", score(&sc, model, gains));
    }
    println!();
    Ok(())
}
