//! A short training run on a small dataset collected from the SITL plant (`collect`, paper
//! Sec. 4, scaled down) lowers the held-out loss by a large factor. Run in release:
//! `cargo test --release -p host-train --test train_collected`.

use host_train::collect::{CollectArgs, CollectConfig};
use host_train::train::{run, TrainConfig};

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
    host_train::collect::run(&args).expect("collect");
    let cfg = TrainConfig {
        epochs: 15,
        batch: 64,
        ..TrainConfig::default()
    };
    let out = dir.join("small.hfw");
    let r = run(&cfg, &dir, &out, true).expect("train");
    eprintln!(
        "held-out loss {:.3e} -> {:.3e} ({:.1} s)",
        r.initial_val_loss, r.final_val_loss, r.train_time_s
    );
    assert!(r.final_val_loss < r.initial_val_loss / 10.0);
    // Better than the nominal model (which lacks the disturbances) on held-out velocity.
    let last = |v: &[f64]| v.last().copied().unwrap_or(f64::NAN);
    assert!(last(&r.heldout_learned.vel_m_s) < last(&r.heldout_nominal.vel_m_s));
    assert!(out.exists());
    let _ = std::fs::remove_dir_all(&dir);
}
