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

use crate::control::{adapter, registry};
use anyhow::{Context, Result};
use clap::Args;
use hamflight::Faults;
use serde::Serialize;
use std::io::{BufRead, Write};
use std::path::PathBuf;

mod wire;
pub use wire::{parse_request, Request};

/// Arguments of `host-train bridge`.
#[derive(Args, Debug, Clone)]
pub struct BridgeArgs {
    /// Weight blob of the learned model (for `adaptive` and `learned`).
    #[arg(long, value_name = "FILE", default_value = "weights/default.hfw")]
    pub weights: PathBuf,
    /// Core controller to run.
    #[arg(long, value_name = "NAME", default_value = "adaptive",
          value_parser = crate::control::spec::core_parser())]
    pub controller: String,
    /// Tick length (s) assumed for the first request.
    #[arg(long, default_value_t = 0.002)]
    pub dt: f64,
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
    /// Collective thrust to command (N): the wrench a thrust-and-moment simulator should be given.
    pub thrust_n: f32,
    /// Body torques to command (N·m): the law's, with the motor-lag lead the attitude gains assume.
    pub torque_nm: [f32; 3],
    /// Disturbance-weight estimate a.
    pub a: Vec<f32>,
    /// Faults and conditions.
    pub faults: FaultsMsg,
}

/// Serve requests from `input` until end of file, writing replies to `output`.
pub fn serve(
    ctrl: &mut dyn adapter::CoreStep,
    first_dt_s: f64,
    input: impl BufRead,
    mut output: impl Write,
) -> Result<()> {
    let mut last_t: Option<f64> = None;
    // Lines as bytes: a line that is not UTF-8 gets an error reply like any other bad line
    // (`BufRead::lines` would end the stream on it).
    for (n, line) in input.split(b'\n').enumerate() {
        let bytes = line.context("cannot read stdin")?;
        let bytes = bytes.strip_suffix(b"\r").unwrap_or(&bytes);
        let line = match std::str::from_utf8(bytes) {
            Ok(line) => line,
            Err(e) => {
                let msg = format!("line {}: not UTF-8 ({e})", n + 1);
                writeln!(output, "{}", serde_json::json!({ "error": msg }))
                    .context("cannot write stdout")?;
                output.flush().context("cannot write stdout")?;
                continue;
            }
        };
        if line.trim().is_empty() {
            continue;
        }
        let text = match parse_request(line) {
            Ok(req) => {
                let dt = last_t.map_or(first_dt_s, |t0| req.t - t0);
                last_t = Some(req.t);
                let (state, sp) = req.to_core();
                let out = ctrl.core_step(&state, &sp, &req.measurement(), dt as f32);
                serde_json::to_string(&Reply {
                    t: req.t,
                    rpm: out.rotors.rpm,
                    rotor_thrust_n: out.rotors.thrust_n,
                    thrust_n: out.command.thrust_n,
                    torque_nm: out.command.torque_nm.into(),
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
    let mut ctrl = registry::core_by_name(&args.controller, Some(&args.weights))?;
    let stdin = std::io::stdin();
    let stdout = std::io::stdout();
    serve(ctrl.as_mut(), args.dt, stdin.lock(), stdout.lock())
}
