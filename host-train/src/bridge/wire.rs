//! The bridge's request line: its JSON form, the parser and the conversion to the core's types.
//!
//! Self-contained (only `hamflight`, `nalgebra`, `serde`, `serde_json`), so that the fuzz target
//! `fuzz/fuzz_targets/bridge_line.rs` compiles this very file (`#[path]`) without the host crate.

use hamflight::{Measurement, Setpoint, State};
use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;

/// One request line.
///
/// The setpoint is the core's [`Setpoint`] itself (its `serde` feature keeps the bridge's names
/// `p`, `v`, `a`, `j`, `yaw`, `yaw_rate`, the defaults and the refusal of unknown names; serde_json
/// reads its numbers straight to f32). The state's fields stay inline, not a nested
/// core [`State`]: the documented line is flat (`p`, `R`, `v`, `w` beside `t`), with R row-major
/// as nested rows, and serde cannot flatten into a struct that refuses unknown fields.
/// [`Request::to_core`] is the one conversion.
#[derive(Deserialize, Debug, Clone)]
#[serde(deny_unknown_fields)]
pub struct Request {
    /// Time (s).
    pub t: f64,
    /// Position (m, world).
    pub p: [f64; 3],
    /// Rotation body→world, row-major.
    #[serde(rename = "R")]
    pub r: [[f64; 3]; 3],
    /// Linear velocity (m/s, body frame).
    pub v: [f64; 3],
    /// Angular velocity (rad/s, body frame).
    pub w: [f64; 3],
    /// The setpoint.
    pub setpoint: Setpoint,
    /// Optional accelerometer: the specific force (m/s², body frame; +9.8 along body z at
    /// hover). The composite adaptation law uses it; without it, it differences the velocity.
    #[serde(default)]
    pub acc: Option<[f64; 3]>,
}

/// Parses one request line (JSON; unknown fields are errors).
///
/// # Errors
/// serde_json's error, with the column where the line stops making sense.
pub fn parse_request(line: &str) -> Result<Request, serde_json::Error> {
    serde_json::from_str(line)
}

impl Request {
    /// The sensor measurement for the core (the accelerometer, when sent).
    pub fn measurement(&self) -> Measurement {
        Measurement {
            acc_body_m_s2: self
                .acc
                .map(|a| Vector3::new(a[0] as f32, a[1] as f32, a[2] as f32)),
        }
    }

    /// The core's state and setpoint.
    pub fn to_core(&self) -> (State, Setpoint) {
        let v3 = |a: [f64; 3]| Vector3::new(a[0] as f32, a[1] as f32, a[2] as f32);
        let r = Matrix3::from_fn(|i, j| {
            self.r
                .get(i)
                .and_then(|row| row.get(j))
                .copied()
                .unwrap_or(f64::NAN) as f32
        });
        (
            State {
                p_m: v3(self.p),
                rot: r,
                v_body_m_s: v3(self.v),
                w_body_rad_s: v3(self.w),
            },
            self.setpoint,
        )
    }
}
