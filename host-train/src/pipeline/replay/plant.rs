//! What a replay flies: a scenario's vehicle (the rigid-body simulator with its effects), or a
//! weight blob's learned model behind the real motors.
//!
//! **A blob as the plant.** The blob was trained on the measured rotor speeds, so its model maps
//! those speeds to motion: the description's wrench of the speeds, the blob's own input lags
//! ([`hamflight::model::ActuatorLag`]), then its Hamiltonian dynamics with a = 0, by RK4 as
//! `host-train score` rolls it out. Between the onboard controller's commands and the measured
//! speeds sit the motors, which the blob does not model: their first-order lag and speed limits
//! come from the rotor scenario (the data's vehicle, e.g. `bl-calm-spiral`).

use crate::sim::plant::{Plant, PlantState, VehicleParams};
use crate::sim::scenario::Scenario;
use hamflight::model::{rk4_step, ActuatorLag, HamiltonianModel, LearnedModel, FEATURES};
use nalgebra::{Rotation3, Vector4};

/// A plant a replay can fly: it starts at a state with its rotors at a speed.
pub trait Replayable: Sync {
    /// A plant in state `s` with its rotors at `rpm`.
    fn start(&self, s: PlantState, rpm: [f64; 4]) -> Stepper<'_>;
}

impl Replayable for Scenario {
    fn start(&self, s: PlantState, rpm: [f64; 4]) -> Stepper<'_> {
        let mut p = self.plant();
        p.set_state(s);
        p.set_rotor_rpm(rpm);
        Stepper::Vehicle(Box::new(p))
    }
}

/// A blob's learned model as the plant, behind the motors of a rotor scenario.
#[derive(Clone, Debug)]
pub struct BlobPlant {
    /// The learned model.
    pub model: LearnedModel,
    /// The rotors: the description's thrust and drag coefficients, arm and speed limits.
    pub rotors: VehicleParams,
    /// The motors' first-order lag (s) from command to speed; 0: none.
    pub motor_tau_s: f64,
}

impl BlobPlant {
    /// `model` behind the motors of `rotors` (its vehicle and its `[effects] motor_tau_s`).
    pub fn new(model: LearnedModel, rotors: &Scenario) -> Self {
        Self {
            model,
            rotors: rotors.vehicle.clone(),
            motor_tau_s: rotors.spec.effects.motor_tau_s.max(0.0),
        }
    }
}

impl Replayable for BlobPlant {
    fn start(&self, s: PlantState, rpm: [f64; 4]) -> Stepper<'_> {
        let rpm = self.rotors.clamp_rpm(rpm);
        let u = wrench_f32(&self.rotors, &rpm);
        Stepper::Blob(BlobRun {
            plant: self,
            state: s,
            rpm,
            lag: ActuatorLag::settled_at(&u),
        })
    }
}

fn wrench_f32(p: &VehicleParams, rpm: &[f64; 4]) -> Vector4<f32> {
    let u = p.nominal_wrench(*rpm);
    Vector4::new(u[0] as f32, u[1] as f32, u[2] as f32, u[3] as f32)
}

/// A blob plant in flight.
#[derive(Clone, Debug)]
pub struct BlobRun<'a> {
    plant: &'a BlobPlant,
    state: PlantState,
    rpm: [f64; 4],
    lag: ActuatorLag,
}

impl BlobRun<'_> {
    fn step(&mut self, cmd_rpm: [f64; 4], dt_s: f64) {
        let p = self.plant;
        let cmd = p.rotors.clamp_rpm(cmd_rpm);
        let alpha = if p.motor_tau_s > 0.0 {
            1.0 - (-dt_s / p.motor_tau_s).exp()
        } else {
            1.0
        };
        for (r, c) in self.rpm.iter_mut().zip(cmd) {
            *r += (c - *r) * alpha;
        }
        let u = wrench_f32(&p.rotors, &self.rpm);
        let u = self.lag.step(p.model.port(), &u, dt_s as f32);
        let s = hamflight::State::from(&self.state);
        let next = rk4_step(&p.model, &s, &u, &[0.0; FEATURES], dt_s as f32);
        // RK4 on the matrix leaves SO(3) slowly; the replay's windows run 1,500 sub-steps.
        let rot = Rotation3::from_matrix(&next.rot.cast::<f64>()).into_inner();
        self.state = PlantState {
            p_m: next.p_m.cast(),
            rot,
            v_body_m_s: next.v_body_m_s.cast(),
            w_body_rad_s: next.w_body_rad_s.cast(),
        };
    }
}

/// One plant in flight: step it with rotor commands, read its state.
#[derive(Clone, Debug)]
pub enum Stepper<'a> {
    /// The simulator.
    Vehicle(Box<Plant>),
    /// A blob's model.
    Blob(BlobRun<'a>),
}

impl Stepper<'_> {
    /// One step of `dt_s` (s) with the rotor commands `cmd_rpm` (rpm) held.
    pub fn step(&mut self, cmd_rpm: [f64; 4], dt_s: f64) {
        match self {
            Self::Vehicle(p) => p.step(cmd_rpm, dt_s),
            Self::Blob(b) => b.step(cmd_rpm, dt_s),
        }
    }

    /// The state now.
    pub fn state(&self) -> &PlantState {
        match self {
            Self::Vehicle(p) => p.state(),
            Self::Blob(b) => &b.state,
        }
    }
}
