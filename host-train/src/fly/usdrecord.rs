//! A flight of the SITL logged as the Crazyflie's uSD-card deck would log it (`host-train eval
//! --log-usd FILE`): a controller wrapper that records, at every control tick, what the vehicle's
//! estimator gives the controller (the scenario's state noise included) and the wrench the
//! controller commands, in Bitcraze's variables and units (the 20 variables of
//! `tools/usd/config.txt`), then writes a version-2 log whole.
//!
//! - `stateEstimate.x/y/z` (m), `stateEstimate.vx/vy/vz` (m/s, world), `stateEstimate.qx/qy/qz/qw`
//!   (body → world): the measured state;
//! - `gyro.x/y/z` (deg/s): the measured body rate;
//! - `ctrlLee.thrustSi` (N), `ctrlLee.torquex/y/z` (N·m): the nominal wrench of the clamped rotor
//!   command (whatever controller flies; named as the Lee controller's log so that the default
//!   import reads it). With motor lag the realized wrench trails it, as on a real vehicle;
//! - `acc.x/y/z` (g): body specific force, the backward difference of the measured world
//!   velocity over the tick plus gravity, rotated into the body (0 on the first tick).
//!
//! Timestamps are the tick times in µs.

use std::path::Path;

use anyhow::Result;
use nalgebra::{Rotation3, UnitQuaternion, Vector3};

use crate::control::controller::Controller;

use crate::io::files::write_atomic;
use crate::io::usdlog::UsdWriter;
use crate::io::usdlog::{G0_M_S2, LEE_COMMAND_VARS, USD_ACC_VARS, USD_STATE_VARS};
use crate::sim::plant::{PlantState, VehicleParams};
use crate::sim::trajectory::TrajectoryPoint;

/// The variables in the order they are logged: state, command, acc (20).
pub fn logged_vars() -> Vec<&'static str> {
    USD_STATE_VARS
        .iter()
        .chain(LEE_COMMAND_VARS.iter())
        .chain(USD_ACC_VARS.iter())
        .copied()
        .collect()
}

/// One tick's values in [`logged_vars`] order, as the deck stores them (f32).
pub fn tick_values(
    s: &PlantState,
    wrench: [f64; 4],
    prev_v_world: Option<Vector3<f64>>,
    dt_s: f64,
    gravity_m_s2: f64,
) -> [f64; 20] {
    let v_world = s.rot * s.v_body_m_s;
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(s.rot));
    let deg = 180.0 / std::f64::consts::PI;
    let acc_body = match prev_v_world {
        Some(pv) if dt_s > 0.0 => {
            let a_world = (v_world - pv) / dt_s + Vector3::new(0.0, 0.0, gravity_m_s2);
            s.rot.transpose() * a_world / G0_M_S2
        }
        _ => Vector3::zeros(),
    };
    let v = [
        s.p_m.x,
        s.p_m.y,
        s.p_m.z,
        v_world.x,
        v_world.y,
        v_world.z,
        q.i,
        q.j,
        q.k,
        q.w,
        s.w_body_rad_s.x * deg,
        s.w_body_rad_s.y * deg,
        s.w_body_rad_s.z * deg,
        wrench[0],
        wrench[1],
        wrench[2],
        wrench[3],
        acc_body.x,
        acc_body.y,
        acc_body.z,
    ];
    v.map(|x| f64::from(x as f32))
}

/// Wraps a controller and records each step as a uSD `fixedFrequency` event.
pub struct UsdRecorder<'a> {
    inner: &'a mut dyn Controller,
    params: VehicleParams,
    writer: UsdWriter,
    prev: Option<(f64, Vector3<f64>)>,
    /// The recorded values, one row per tick (what the log holds, as f64).
    pub rows: Vec<(u64, [f64; 20])>,
}

impl<'a> UsdRecorder<'a> {
    /// Records `inner`'s steps; `params` converts its rotor commands to the nominal wrench.
    pub fn new(inner: &'a mut dyn Controller, params: VehicleParams) -> Self {
        Self {
            inner,
            params,
            writer: UsdWriter::fixed_frequency(&logged_vars()),
            prev: None,
            rows: Vec::new(),
        }
    }

    /// The finished log's bytes.
    pub fn finish(self) -> Vec<u8> {
        self.writer.finish()
    }

    /// Writes the finished log to `path` whole.
    ///
    /// # Errors
    /// Any I/O failure, naming the file.
    pub fn write(self, path: &Path) -> Result<()> {
        write_atomic(path, &self.finish())
    }
}

impl Controller for UsdRecorder<'_> {
    fn name(&self) -> &str {
        self.inner.name()
    }

    fn reset(&mut self) {
        self.inner.reset();
    }

    fn step(
        &mut self,
        t_s: f64,
        state: &PlantState,
        reference: &TrajectoryPoint,
        dt_s: f64,
    ) -> [f64; 4] {
        let cmd = self.inner.step(t_s, state, reference, dt_s);
        let wrench = self.params.nominal_wrench(self.params.clamp_rpm(cmd));
        let prev_v = self.prev.map(|(_, v)| v);
        let dt = self.prev.map_or(0.0, |(t, _)| t_s - t);
        let values = tick_values(state, wrench, prev_v, dt, self.params.gravity_m_s2);
        let t_us = (t_s * 1e6).round().max(0.0) as u64;
        self.writer.event(0, t_us, &values);
        self.rows.push((t_us, values));
        self.prev = Some((t_s, state.rot * state.v_body_m_s));
        cmd
    }

    fn adaptation_estimate(&self) -> Option<Vec<f64>> {
        self.inner.adaptation_estimate()
    }
}
