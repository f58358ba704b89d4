//! `host-train score` against the training report: on the report's own held-out windows it
//! gives the same N-step errors, and on a dataset made by the nominal model the nominal row is
//! exact while the kinematic baselines are not.
//! `cargo test --release -p host-train --test score`.

mod train_common;

use hamflight::model::{LearnedModel, NominalModel, FEATURES, MASS_KG};
use host_train::pipeline::{run_score, score_table, ScoreArgs};
use host_train::train::{load_windows, model_errors, split_windows, TrainConfig};
use nalgebra::{Matrix3, Vector3};

fn close(a: &[f64], b: &[f64], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}");
    for (k, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= 1e-9 + 1e-6 * y.abs(),
            "{what} step {}: score {x} vs report {y}",
            k + 1
        );
    }
}

#[test]
fn score_reproduces_the_training_reports_heldout_errors() {
    let model = NominalModel::new(
        MASS_KG,
        Matrix3::from_diagonal(&Vector3::new(1.7e-5, 1.2e-5, 2.5e-5)),
    );
    let a: Vec<[f32; FEATURES]> = vec![[0.0; FEATURES]; 2];
    let dir = train_common::scratch("score");
    train_common::write_dataset(&dir, &model, &a, 120, 3);
    let cfg = TrainConfig {
        epochs: 2,
        feature_epochs: 0,
        flight_check: false,
        ..TrainConfig::default()
    };
    let out = dir.join("s.hfw");
    let report = host_train::pipeline::run_train(&cfg, &dir, &out, true).expect("trains");

    // The report's held-out windows, rebuilt as `train` cuts and splits them.
    let windows = load_windows(&dir, cfg.window).expect("loads");
    let (_, heldout) = split_windows(&windows, cfg.heldout_frac, cfg.seed);
    let learned: LearnedModel = host_train::control::load_learned(&out).expect("blob");
    let e = model_errors(&learned, &windows, &heldout);
    let r = &report.heldout_learned_no_disturbance;
    close(&e.pos_rmse_m, &r.pos_m, "position");
    close(&e.att_rmse_rad, &r.rot_rad, "attitude");
    close(&e.vel_body_rmse_m_s, &r.vel_m_s, "body velocity");
    close(&e.rate_rmse_rad_s, &r.rate_rad_s, "body rate");
    assert!(e.pos_mae_m.iter().zip(&e.pos_rmse_m).all(|(m, r)| m <= r));

    // The command on the whole dataset: every window, and the nominal model (the data's own
    // generator, given its inertia) is exact where the baselines are not.
    let vf = dir.join("vehicle.toml");
    std::fs::write(
        &vf,
        format!(
            "mass_kg = {MASS_KG}\ninertia_kg_m2 = [1.7e-5, 1.2e-5, 2.5e-5]\narm_xy_m = 0.028\n\
             kf_n_per_rad_s2 = 2.88e-8\nkm_nm_per_rad_s2 = 7.2e-11\nthrust_to_weight = 2.25\n"
        ),
    )
    .expect("vehicle");
    let args = ScoreArgs {
        weights: out,
        data: dir.clone(),
        horizon: 4,
        stride: 4,
        vehicle: Some(vf),
        out: Some(dir.join("score")),
        response: None,
        history_s: None,
    };
    let s = run_score(&args).expect("scores");
    assert_eq!(s.windows, windows.windows.len());
    let row = |n: &str| &s.predictors.iter().find(|p| p.name == n).expect(n).errors;
    let last = |v: &[f64]| *v.last().expect("steps");
    assert!(
        last(&row("nominal").rate_mae_rad_s) < 1e-3,
        "{:?}",
        row("nominal")
    );
    assert!(last(&row("hold").rate_mae_rad_s) > 10.0 * last(&row("nominal").rate_mae_rad_s));
    assert!(last(&row("zero-order").pos_mae_m) > last(&row("hold").pos_mae_m));
    // The SITL's log is kinematically consistent: its velocities integrate to its positions
    // far better than holding the first velocity does.
    let floor = last(&s.logged_velocity_pos_mae_m);
    assert_eq!(s.logged_velocity_pos_mae_m.len(), 4);
    assert!(
        floor < 0.1 * last(&row("hold").pos_mae_m),
        "∫ logged v {floor} m against hold {} m",
        last(&row("hold").pos_mae_m)
    );
    let json = std::fs::read_to_string(dir.join("score").join("score.json")).expect("json");
    assert!(json.contains("\"rate_mae_rad_s\""));
    assert!(json.contains("\"logged_velocity_pos_mae_m\""));
    let svg = std::fs::read_to_string(dir.join("score").join("score.svg")).expect("svg");
    assert!(svg.starts_with("<svg"));
    print!("{}", score_table(&s));
    assert!(score_table(&s).contains("zero-order"));
}
