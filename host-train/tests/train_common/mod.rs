//! Shared helpers of the training tests: random states and a synthetic dataset written through
//! `host_train::io::dataset` (format `hamflight-dataset-v2`) from a known model.
#![allow(dead_code)]

use hamflight::model::{rk4_step, HamiltonianModel, State, FEATURES, GRAVITY_M_S2, MASS_KG};
use host_train::io::{
    realization_file, save_dataset, Dataset, Flight, Realization, RealizationMeta, Sample,
};
use host_train::sim::PlantState;
use nalgebra::{Vector3, Vector4};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;

/// A random state: any attitude within `tilt_rad` of level, moderate velocities and rates.
pub fn random_state(rng: &mut impl Rng, tilt_rad: f32) -> State {
    let mut v3 = |s: f32| {
        Vector3::new(
            rng.gen_range(-s..s),
            rng.gen_range(-s..s),
            rng.gen_range(-s..s),
        )
    };
    let axis = v3(tilt_rad);
    let yaw = Vector3::new(0.0, 0.0, 1.0) * axis.z * 10.0;
    State {
        p_m: v3(1.0),
        rot: hamflight::lie::exp(&yaw) * hamflight::lie::exp(&Vector3::new(axis.x, axis.y, 0.0)),
        v_body_m_s: v3(0.5),
        w_body_rad_s: v3(2.0),
    }
}

/// A random control near hover: thrust m g (1 ± 15 %), torques ±5e-5 N·m.
pub fn random_control(rng: &mut impl Rng) -> Vector4<f32> {
    Vector4::new(
        MASS_KG * GRAVITY_M_S2 * rng.gen_range(0.85..1.15),
        rng.gen_range(-5e-5..5e-5),
        rng.gen_range(-5e-5..5e-5),
        rng.gen_range(-2e-5..2e-5),
    )
}

/// Writes a dataset of `windows` windows per entry of `a` (one realization each; each window a
/// flight of 5 states), integrated with `model`'s RK4 at 240 Hz under d = W a_j and a random
/// command held over the window, through the crate's one dataset writer. The manifest's wind
/// holds a_j[0..3] (exact for the nominal features) and efficiencies 1.
pub fn write_dataset<M: HamiltonianModel>(
    dir: &Path,
    model: &M,
    a: &[[f32; FEATURES]],
    windows: usize,
    seed: u64,
) {
    write_dataset_with(dir, model, a, windows, seed, false);
}

/// [`write_dataset`], with a new random command at every step if `per_step`.
pub fn write_dataset_with<M: HamiltonianModel>(
    dir: &Path,
    model: &M,
    a: &[[f32; FEATURES]],
    windows: usize,
    seed: u64,
    per_step: bool,
) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let dt = 1.0 / 240.0;
    let mut ds = Dataset::new(
        240.0,
        f64::from(MASS_KG),
        f64::from(GRAVITY_M_S2),
        "collect",
    );
    ds.manifest.seed = Some(seed);
    for (j, aj) in a.iter().enumerate() {
        let mut flights = Vec::with_capacity(windows);
        for _ in 0..windows {
            let mut s = random_state(&mut rng, 0.3);
            let mut u = random_control(&mut rng);
            let mut samples = Vec::with_capacity(5);
            for step in 0..5 {
                if per_step && step > 0 {
                    u = random_control(&mut rng);
                }
                samples.push(Sample {
                    t_s: f64::from(step) / 240.0,
                    state: PlantState {
                        p_m: s.p_m.cast(),
                        rot: s.rot.cast(),
                        v_body_m_s: s.v_body_m_s.cast(),
                        w_body_rad_s: s.w_body_rad_s.cast(),
                    },
                    wrench: [u.x, u.y, u.z, u.w].map(f64::from),
                    rpm: None,
                    acc_body_m_s2: None,
                });
                s = rk4_step(model, &s, &u, aj, dt);
            }
            flights.push(Flight { samples });
        }
        ds.realizations.push(Realization {
            meta: RealizationMeta {
                file: realization_file(j),
                source_file: None,
                wind_m_s2: Some([aj[0], aj[1], aj[2]].map(f64::from)),
                rotor_efficiency: Some([1.0; 4]),
                disturbance_free: false,
                flights: 0,
                samples: 0,
            },
            flights,
        });
    }
    save_dataset(dir, &ds).unwrap();
}

/// A fresh scratch directory under the target dir.
pub fn scratch(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("hamflight-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}
