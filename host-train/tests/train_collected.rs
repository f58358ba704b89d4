//! A short training run on a small dataset collected from the SITL plant (`collect`, paper
//! Sec. 4, scaled down) lowers the held-out loss by a large factor. Run in release:
//! `cargo test --release -p host-train --test train_collected`.

use host_train::data::{CollectArgs, CollectConfig};
use host_train::pipeline::run_train;
use host_train::train::TrainConfig;

#[test]
fn short_training_on_collected_data_lowers_heldout_loss() {
    let dir = std::env::temp_dir().join(format!("hamflight-collected-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let args = CollectArgs {
        out: dir.clone(),
        config: CollectConfig {
            realizations: 2,
            windows: 180,
            ..CollectConfig::default()
        },
    };
    host_train::data::run_collect(&args).expect("collect");
    let cfg = TrainConfig {
        epochs: 15,
        batch: 64,
        ..TrainConfig::default()
    };
    let out = dir.join("small.hfw");
    let r = run_train(&cfg, &dir, &out, true).expect("train");
    eprintln!(
        "held-out loss {:.3e} -> {:.3e} ({:.1} s)",
        r.initial_val_loss, r.final_val_loss, r.train_time_s
    );
    assert!(r.final_val_loss < r.initial_val_loss / 10.0);
    // Better than the nominal model (which lacks the disturbances) on held-out velocity.
    let last = |v: &[f64]| v.last().copied().unwrap_or(f64::NAN);
    assert!(last(&r.heldout_learned.vel_m_s) < last(&r.heldout_nominal.vel_m_s));
    assert!(out.exists());
    // Each flight's rotor gains (docs/training.md) find its weak rotors; the calm flight's are
    // pinned at 1, and the shared thrust gain is the undisturbed vehicle's.
    for (j, real) in r.realizations.iter().enumerate() {
        let learned = real.learned_rotor_efficiency.expect("rotor gains learned");
        let truth = real
            .true_rotor_efficiency
            .expect("collect records the rotors");
        eprintln!("flight {j}: rotor efficiency learned {learned:?}, true {truth:?}");
        // A loose bar for this short run; the full default run matches far closer
        // (docs/training.md, "Calm air").
        for (l, t) in learned.iter().zip(truth) {
            assert!(
                (l - t).abs() < 0.03,
                "flight {j}: learned {learned:?}, true {truth:?}"
            );
        }
        if !real.disturbance_free {
            // collect weakens rotors 1 and 2 only.
            assert!(
                learned[0].max(learned[1]) < learned[2].min(learned[3]),
                "{learned:?}"
            );
        }
    }
    assert!(r.realizations.iter().any(|x| x.disturbance_free));
    // The calm flight's held-out windows, where the nominal model is exact, are reported apart.
    let calm = r
        .heldout_calm
        .as_ref()
        .expect("a calm flight is held out too");
    eprintln!(
        "calm held-out: {} windows, rate error learned {:.2e}, nominal {:.2e} rad/s",
        calm.windows,
        last(&calm.learned.rate_rad_s),
        last(&calm.nominal.rate_rad_s)
    );
    assert!(calm.windows > 0);
    assert!(
        last(&calm.nominal.rate_rad_s) < 1e-5,
        "nominal is exact on calm flights"
    );
    assert!(last(&calm.learned.rate_rad_s) < 0.5 * last(&r.heldout_nominal.rate_rad_s));
    // The training model with the flights' rotor gains predicts the held-out windows better
    // than the flying model (shared g, W a_j), which cannot bend g to one flight's rotors.
    let with_gains = r
        .heldout_learned_rotor_gains
        .as_ref()
        .expect("rotor gains learned");
    eprintln!(
        "held-out rate error: with rotor gains {:.2e}, flying model {:.2e} rad/s",
        last(&with_gains.rate_rad_s),
        last(&r.heldout_learned.rate_rad_s)
    );
    assert!(last(&with_gains.rate_rad_s) < last(&r.heldout_learned.rate_rad_s));
    let g_f = r.learned_gain_hover[2][0];
    eprintln!("thrust gain at hover {g_f}");
    assert!((g_f - 1.0).abs() < 0.005, "thrust gain at hover {g_f}");
    let _ = std::fs::remove_dir_all(&dir);
}
