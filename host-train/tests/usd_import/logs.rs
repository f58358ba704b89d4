//! The uSD test's logs: SITL flights recorded as uSD logs, a small hand-made log, the CRC fixed
//! after a mutation, a flight as import CSV, and the scratch directories and import arguments.

use std::path::{Path, PathBuf};

use host_train::data::ImportArgs;
use host_train::fly::UsdRecorder;
use host_train::io::{crc32, EventType, UsdWriter, Var, VarType, FIXED_FREQUENCY_ID};
use host_train::sim::Scenario;

pub fn tmpdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hamflight-usd-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn scenario(name: &str, duration_s: f64) -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenarios")
        .join(format!("{name}.toml"));
    let mut s = Scenario::load(path).unwrap();
    s.spec.duration_s = duration_s;
    s
}

/// Flies `name` for `duration_s` with the geometric controller and returns the uSD log and the
/// values the recorder logged.
pub fn sitl_log(name: &str, duration_s: f64) -> (Vec<u8>, Vec<(u64, [f64; 20])>) {
    let sc = scenario(name, duration_s);
    let mut ctrl = host_train::control::by_name("geometric", &sc, None).unwrap();
    let mut rec = UsdRecorder::new(ctrl.as_mut(), sc.plant().params.clone());
    let log = host_train::fly::fly_scenario(&sc, &mut rec);
    assert!(log.crash_time_s.is_none());
    let rows = rec.rows.clone();
    (rec.finish(), rows)
}

pub fn args(out: &Path) -> ImportArgs {
    ImportArgs::new(out.to_path_buf(), 0.027)
}

pub fn small_log() -> Vec<u8> {
    let mut w = UsdWriter::new(vec![
        EventType {
            id: FIXED_FREQUENCY_ID,
            name: "fixedFrequency".into(),
            vars: vec![
                Var {
                    name: "a.f".into(),
                    ty: VarType::F32,
                },
                Var {
                    name: "a.i".into(),
                    ty: VarType::I16,
                },
                Var {
                    name: "a.u".into(),
                    ty: VarType::U8,
                },
            ],
        },
        EventType {
            id: 7,
            name: "takeoff".into(),
            vars: vec![Var {
                name: "h".into(),
                ty: VarType::U32,
            }],
        },
    ]);
    for k in 0..6u64 {
        w.event(0, 1000 * k, &[k as f64 * 0.5, -(k as f64), 200.0]);
        if k == 2 {
            w.event(1, 1000 * k + 1, &[42.0]);
        }
    }
    w.finish()
}

/// Recomputes the trailing CRC so that a mutated file reaches the event decoder.
pub fn fix_crc(b: &mut [u8]) {
    if b.len() >= 4 {
        let n = b.len() - 4;
        let crc = crc32(&b[..n]).to_le_bytes();
        b[n..].copy_from_slice(&crc);
    }
}

pub fn csv_of(rows: &[(u64, [f64; 20])]) -> String {
    let mut s = String::from(
        "t_s,px_m,py_m,pz_m,qw,qx,qy,qz,vx_world_m_s,vy_world_m_s,vz_world_m_s,wx_rad_s,wy_rad_s,wz_rad_s,f_n,tau_x_nm,tau_y_nm,tau_z_nm\n",
    );
    let deg = std::f64::consts::PI / 180.0;
    for (k, (t, v)) in rows.iter().enumerate() {
        // Commands logged at half the state rate: every other row leaves them empty.
        let cmd = if k % 2 == 0 {
            format!("{},{},{},{}", v[13], v[14], v[15], v[16])
        } else {
            ",,,".into()
        };
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{cmd}\n",
            *t as f64 * 1e-6,
            v[0],
            v[1],
            v[2],
            v[9],
            v[6],
            v[7],
            v[8],
            v[3],
            v[4],
            v[5],
            v[10] * deg,
            v[11] * deg,
            v[12] * deg
        ));
    }
    s
}
