//! The trainer's windows carry the command of every step: on data made with a new command at
//! each step, the true model integrated with each step's command predicts the stored states to
//! f32 round-off, and holding the first command does not. Disturbance-free realizations are
//! flagged in the loaded windows.

mod train_common;

use hamflight::model::{NominalModel, FEATURES};
use host_train::io::WindowSpec;
use host_train::train::{batch_windows, load_windows, prediction_errors};

#[test]
fn each_step_is_integrated_with_its_own_command() {
    let model = NominalModel::default();
    let a: Vec<[f32; FEATURES]> = vec![[0.3, -0.2, 0.0, 0.1, 0.0, 0.0]];
    let dir = train_common::scratch("steps");
    train_common::write_dataset_with(&dir, &model, &a, 40, 3, true);
    let w = load_windows(&dir, WindowSpec::default()).unwrap();
    assert_eq!(w.windows.len(), 40);
    assert_eq!(w.window_len, 5);
    assert!(w.windows.iter().all(|x| x.u.len() == 4 && x.u[1] != x.u[0]));
    let ids: Vec<usize> = (0..w.windows.len()).collect();
    let b = batch_windows(&w, &ids, &burn::tensor::Device::flex());
    assert_eq!(b.u.len(), 4);
    let exact = prediction_errors(&model, &w, &ids, Some(&a));
    // The same windows with the first command held over all four steps.
    let mut held = w.clone();
    for x in &mut held.windows {
        let u0 = x.u[0];
        x.u.iter_mut().for_each(|u| *u = u0);
    }
    let wrong = prediction_errors(&model, &held, &ids, Some(&a));
    let last = |v: &[f64]| v.last().copied().unwrap_or(f64::NAN);
    eprintln!(
        "4-step rate error: per-step commands {:.2e}, first command held {:.2e} rad/s",
        last(&exact.rate_rad_s),
        last(&wrong.rate_rad_s)
    );
    // The per-step commands reproduce the data (the same RK4, to rounding); holding the first
    // command instead leaves a clear rate error, so the test sees which command is used.
    assert!(last(&exact.rate_rad_s) < 1e-6, "{exact:?}");
    assert!(last(&wrong.rate_rad_s) > 1.5e-2, "{wrong:?}");
    assert!(!w.realizations[0].disturbance_free);
    let _ = std::fs::remove_dir_all(&dir);
}
