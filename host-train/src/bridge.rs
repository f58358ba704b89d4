//! `host-train bridge`: lets an external simulator (RotorPy, gym-pybullet-drones, a ROS node)
//! drive the core controller over stdin/stdout, one JSON object per line.
//!
//! Request (one line per control tick):
//! ```json
//! {"t": 0.002, "p": [0, 0, 0.5], "R": [[1,0,0],[0,1,0],[0,0,1]], "v": [0,0,0], "w": [0,0,0],
//!  "setpoint": {"p": [0.5, 0, 0.5], "v": [0,0,0], "a": [0,0,0], "j": [0,0,0], "yaw": 0, "yaw_rate": 0}}
//! ```
//! `t` in s; `p` world position (m); `R` body→world rotation, row-major; `v`, `w` body-frame
//! linear (m/s) and angular (rad/s) velocity. In the setpoint only `p` is required; `v`, `a`,
//! `j` (world m/s, m/s², m/s³), `yaw` (rad) and `yaw_rate` (rad/s) default to 0.
//!
//! Reply (one line per request, in order):
//! ```json
//! {"t": 0.002, "rpm": [..4], "rotor_thrust_n": [..4], "thrust_n": 0.26, "torque_nm": [..3],
//!  "a": [..p], "faults": {"fault": false, "bad_state": false, ...}}
//! ```
//! The tick length is the difference of successive `t` (the first tick uses `--dt`). A line that
//! does not parse gets `{"error": "..."}` and the controller is not stepped.

use crate::flight;
use anyhow::{Context, Result};
use clap::Args;
use hamflight::{Faults, Setpoint, State};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};
use std::io::{BufRead, Write};
use std::path::PathBuf;

/// Arguments of `host-train bridge`.
#[derive(Args, Debug, Clone)]
pub struct BridgeArgs {
    /// Weight blob of the learned model (for `adaptive` and `learned`).
    #[arg(long, value_name = "FILE", default_value = "weights/default.hfw")]
    pub weights: PathBuf,
    /// Core controller to run: adaptive, learned, geometric-adaptive or ida-pbc.
    #[arg(long, value_name = "NAME", default_value = "adaptive")]
    pub controller: String,
    /// Tick length (s) assumed for the first request.
    #[arg(long, default_value_t = 0.002)]
    pub dt: f64,
}

/// The setpoint part of a request.
#[derive(Deserialize, Debug, Clone)]
#[serde(deny_unknown_fields)]
pub struct SetpointMsg {
    /// Desired position (m, world).
    pub p: [f64; 3],
    /// Desired velocity (m/s, world).
    #[serde(default)]
    pub v: [f64; 3],
    /// Desired acceleration (m/s², world).
    #[serde(default)]
    pub a: [f64; 3],
    /// Desired jerk (m/s³, world).
    #[serde(default)]
    pub j: [f64; 3],
    /// Desired yaw (rad).
    #[serde(default)]
    pub yaw: f64,
    /// Desired yaw rate (rad/s).
    #[serde(default)]
    pub yaw_rate: f64,
}

/// One request line.
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
    pub setpoint: SetpointMsg,
}

/// Fault flags in a reply.
#[derive(Serialize, Debug, Clone, PartialEq)]
pub struct FaultsMsg {
    /// The output was forced to motors off.
    pub fault: bool,
    /// Non-finite state.
    pub bad_state: bool,
    /// Non-finite setpoint.
    pub bad_setpoint: bool,
    /// Tick length not in (0, 0.1] s.
    pub bad_dt: bool,
    /// Non-finite or singular value inside the law.
    pub numeric: bool,
    /// The mixer saturated.
    pub saturated: bool,
    /// The tilt limit shaped the desired attitude.
    pub tilt_limited: bool,
}

impl From<&Faults> for FaultsMsg {
    fn from(f: &Faults) -> Self {
        Self {
            fault: f.is_fault(),
            bad_state: f.bad_state,
            bad_setpoint: f.bad_setpoint,
            bad_dt: f.bad_dt,
            numeric: f.numeric,
            saturated: f.saturation.any(),
            tilt_limited: f.tilt_limited,
        }
    }
}

/// One reply line.
#[derive(Serialize, Debug, Clone)]
pub struct Reply {
    /// Echo of the request's time (s).
    pub t: f64,
    /// Rotor speed commands, rotors 1..4 (rpm).
    pub rpm: [f32; 4],
    /// Rotor thrusts (N).
    pub rotor_thrust_n: [f32; 4],
    /// Collective thrust asked by the law (N).
    pub thrust_n: f32,
    /// Body torques asked by the law (N·m).
    pub torque_nm: [f32; 3],
    /// Disturbance-weight estimate a.
    pub a: Vec<f32>,
    /// Faults and conditions.
    pub faults: FaultsMsg,
}

impl Request {
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
        let s = &self.setpoint;
        (
            State {
                p_m: v3(self.p),
                rot: r,
                v_body_m_s: v3(self.v),
                w_body_rad_s: v3(self.w),
            },
            Setpoint {
                p_m: v3(s.p),
                v_m_s: v3(s.v),
                a_m_s2: v3(s.a),
                j_m_s3: v3(s.j),
                yaw_rad: s.yaw as f32,
                yaw_rate_rad_s: s.yaw_rate as f32,
            },
        )
    }
}

/// Serve requests from `input` until end of file, writing replies to `output`.
pub fn serve(
    ctrl: &mut dyn flight::CoreStep,
    first_dt_s: f64,
    input: impl BufRead,
    mut output: impl Write,
) -> Result<()> {
    let mut last_t: Option<f64> = None;
    for (n, line) in input.lines().enumerate() {
        let line = line.context("cannot read stdin")?;
        if line.trim().is_empty() {
            continue;
        }
        let text = match serde_json::from_str::<Request>(&line) {
            Ok(req) => {
                let dt = last_t.map_or(first_dt_s, |t0| req.t - t0);
                last_t = Some(req.t);
                let (state, sp) = req.to_core();
                let out = ctrl.core_step(&state, &sp, dt as f32);
                serde_json::to_string(&Reply {
                    t: req.t,
                    rpm: out.rotors.rpm,
                    rotor_thrust_n: out.rotors.thrust_n,
                    thrust_n: out.wrench.thrust_n,
                    torque_nm: out.wrench.torque_nm.into(),
                    a: out.a.iter().copied().collect(),
                    faults: (&out.faults).into(),
                })?
            }
            Err(e) => serde_json::json!({ "error": format!("line {}: {e}", n + 1) }).to_string(),
        };
        writeln!(output, "{text}").context("cannot write stdout")?;
        output.flush().context("cannot write stdout")?;
    }
    Ok(())
}

/// Run `host-train bridge` on stdin/stdout.
pub fn run(args: &BridgeArgs) -> Result<()> {
    let mut ctrl = flight::core_by_name(&args.controller, Some(&args.weights))?;
    let stdin = std::io::stdin();
    let stdout = std::io::stdout();
    serve(ctrl.as_mut(), args.dt, stdin.lock(), stdout.lock())
}
