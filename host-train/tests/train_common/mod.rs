//! Shared helpers of the training tests: random states and a synthetic dataset written in the
//! `hamflight-dataset-v1` format from a known model.
#![allow(dead_code)]

use hamflight::model::{rk4_step, HamiltonianModel, State, FEATURES, GRAVITY_M_S2, MASS_KG};
use nalgebra::{Vector3, Vector4};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::fmt::Write as _;
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

/// Writes a dataset of `windows` windows per entry of `a` (one realization each), integrated
/// with `model`'s RK4 at 240 Hz under d = W a_j. The manifest's wind holds a_j[0..3] (exact for
/// the nominal features) and efficiencies 1.
pub fn write_dataset<M: HamiltonianModel>(
    dir: &Path,
    model: &M,
    a: &[[f32; FEATURES]],
    windows: usize,
    seed: u64,
) {
    std::fs::create_dir_all(dir).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let dt = 1.0 / 240.0;
    let mut reals = Vec::new();
    for (j, aj) in a.iter().enumerate() {
        let file = format!("realization_{j:02}.csv");
        let mut csv = String::from("window,step,t_s,px,py,pz,r11,r12,r13,r21,r22,r23,r31,r32,r33,vx,vy,vz,wx,wy,wz,f_n,tau_x_nm,tau_y_nm,tau_z_nm,rpm1,rpm2,rpm3,rpm4\n");
        for w in 0..windows {
            let mut s = random_state(&mut rng, 0.3);
            let u = random_control(&mut rng);
            for step in 0..5 {
                let r = &s.rot;
                writeln!(
                    csv,
                    "{w},{step},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},0,0,0,0",
                    step as f32 * dt,
                    s.p_m.x, s.p_m.y, s.p_m.z,
                    r.m11, r.m12, r.m13, r.m21, r.m22, r.m23, r.m31, r.m32, r.m33,
                    s.v_body_m_s.x, s.v_body_m_s.y, s.v_body_m_s.z,
                    s.w_body_rad_s.x, s.w_body_rad_s.y, s.w_body_rad_s.z,
                    u.x, u.y, u.z, u.w
                )
                .unwrap();
                s = rk4_step(model, &s, &u, aj, dt);
            }
        }
        std::fs::write(dir.join(&file), csv).unwrap();
        reals.push(serde_json::json!({
            "file": file,
            "wind_m_s2": [aj[0], aj[1], aj[2]],
            "rotor_efficiency": [1.0, 1.0, 1.0, 1.0],
            "windows": windows,
        }));
    }
    let manifest = serde_json::json!({
        "format": "hamflight-dataset-v1",
        "sample_hz": 240.0,
        "window_len": 5,
        "mass_kg": MASS_KG,
        "gravity_m_s2": GRAVITY_M_S2,
        "seed": seed,
        "realizations": reals,
    });
    std::fs::write(
        dir.join("manifest.json"),
        serde_json::to_string_pretty(&manifest).unwrap(),
    )
    .unwrap();
}

/// A fresh scratch directory under the target dir.
pub fn scratch(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("hamflight-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}
