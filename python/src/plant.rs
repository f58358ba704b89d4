//! `hamflight.Plant`: the SITL quadrotor of a scenario, stepped from Python one control interval
//! at a time (the plant `hamflight.fly` flies whole flights on), so a user flies their own
//! policy; `hamflight.env.QuadrotorEnv` wraps it as a Gymnasium-style environment.

use hamflight::mixer::Airframe;
use hamflight::Wrench;
use host_train::control::airframe_of;
use host_train::sim::{Plant as HostPlant, Scenario as HostScenario};
use nalgebra::Vector3;
use numpy::PyArray1;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::sitl::{reference_dict, Scenario};

/// The observation's length: position (m, world), velocity (m/s, world), R (body → world,
/// row-major), body rates (rad/s).
pub const OBSERVATION_LEN: usize = 18;

/// The SITL quadrotor of a scenario (its vehicle, wind, faults and effects), stepped by the
/// caller (`hamflight.env.QuadrotorEnv` wraps it).
///
/// `Plant(scenario)` starts at the scenario's initial state at t = 0. Observations are 18
/// floats: position (m, world), velocity (m/s, world), R (body -> world, row-major), body rates
/// (rad/s).
#[pyclass(module = "hamflight._core", unsendable)]
pub struct Plant {
    scenario: HostScenario,
    plant: HostPlant,
    airframe: Airframe,
}

impl Plant {
    fn observation_vec(&self) -> Vec<f64> {
        let s = self.plant.state();
        let v = s.v_world_m_s();
        let mut o = Vec::with_capacity(OBSERVATION_LEN);
        o.extend_from_slice(s.p_m.as_slice());
        o.extend_from_slice(v.as_slice());
        for r in 0..3 {
            for c in 0..3 {
                o.push(s.rot[(r, c)]);
            }
        }
        o.extend_from_slice(s.w_body_rad_s.as_slice());
        o
    }

    fn interval(&self, dt_s: Option<f64>) -> PyResult<f64> {
        let dt = dt_s.unwrap_or_else(|| self.scenario.control_dt_s());
        if !(dt.is_finite() && dt > 0.0 && dt <= 1.0) {
            return Err(PyValueError::new_err(format!(
                "dt_s must be in (0, 1] s, got {dt}"
            )));
        }
        Ok(dt)
    }

    fn advance(&mut self, rpm: [f64; 4], dt_s: f64) {
        let max_dt = self.scenario.control_dt_s() / self.scenario.physics_substeps() as f64;
        let cmd = self.plant.params.clamp_rpm(rpm);
        self.plant.advance(cmd, dt_s, max_dt);
    }
}

#[pymethods]
impl Plant {
    #[new]
    fn new(scenario: &Scenario) -> Self {
        let s = scenario.s.clone();
        Self {
            plant: s.plant(),
            airframe: airframe_of(&s.vehicle),
            scenario: s,
        }
    }

    /// Back to the scenario's initial state at t = 0; returns the observation.
    fn reset<'py>(&mut self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.plant = self.scenario.plant();
        self.observation(py)
    }

    /// The state as one array of 18: position (m, world), velocity (m/s, world), R (body →
    /// world, row-major), body rates ω (rad/s).
    fn observation<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.observation_vec())
    }

    /// Hold the four rotor speeds `rpm` (clamped to the vehicle's range; the motors' lag, if the
    /// scenario has one, acts on them) for `dt_s` (default: the scenario's control period), the
    /// physics at the scenario's rate; returns the observation.
    #[pyo3(signature = (rpm, dt_s=None))]
    fn step_rpm<'py>(
        &mut self,
        py: Python<'py>,
        rpm: [f64; 4],
        dt_s: Option<f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let dt = self.interval(dt_s)?;
        if !rpm.iter().all(|r| r.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "rpm must be finite, got {rpm:?}"
            )));
        }
        self.advance(rpm, dt);
        Ok(self.observation(py))
    }

    /// The body wrench (collective thrust N, torques N·m) mixed by the core's mixer for this
    /// vehicle (roll and pitch first, then yaw, then the thrust, as on the vehicle), held for
    /// `dt_s`; returns the observation. A non-finite wrench stops the rotors, as the mixer does.
    #[pyo3(signature = (thrust_n, torque_nm, dt_s=None))]
    fn step_wrench<'py>(
        &mut self,
        py: Python<'py>,
        thrust_n: f64,
        torque_nm: [f64; 3],
        dt_s: Option<f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let dt = self.interval(dt_s)?;
        let u = Wrench {
            thrust_n: thrust_n as f32,
            torque_nm: Vector3::from(torque_nm).cast::<f32>(),
        };
        let (cmd, _) = self.airframe.mix(&u);
        self.advance(cmd.rpm.map(f64::from), dt);
        Ok(self.observation(py))
    }

    /// The scenario's reference at `t_s` (default: now), as `Scenario.reference` gives it.
    #[pyo3(signature = (t_s=None))]
    fn reference<'py>(&self, py: Python<'py>, t_s: Option<f64>) -> PyResult<Bound<'py, PyDict>> {
        reference_dict(
            py,
            &self
                .scenario
                .reference(t_s.unwrap_or_else(|| self.plant.t_s())),
        )
    }

    /// Simulated time (s).
    #[getter]
    fn t_s(&self) -> f64 {
        self.plant.t_s()
    }

    /// The scenario's flight length (s).
    #[getter]
    fn duration_s(&self) -> f64 {
        self.scenario.spec.duration_s
    }

    /// The scenario's control period (s): the default step.
    #[getter]
    fn control_dt_s(&self) -> f64 {
        self.scenario.control_dt_s()
    }

    /// The vehicle's mass (kg).
    #[getter]
    fn mass_kg(&self) -> f64 {
        self.scenario.vehicle.mass_kg
    }

    /// Gravity (m/s²).
    #[getter]
    fn gravity_m_s2(&self) -> f64 {
        self.scenario.vehicle.gravity_m_s2
    }

    /// diag(J) (kg·m², body).
    #[getter]
    fn inertia_kg_m2(&self) -> [f64; 3] {
        self.scenario.vehicle.inertia_kg_m2
    }

    /// The rotors' top speed (rpm).
    #[getter]
    fn max_rpm(&self) -> f64 {
        self.scenario.vehicle.max_rpm()
    }

    /// The largest collective thrust the four rotors give (N).
    #[getter]
    fn max_thrust_n(&self) -> f64 {
        4.0 * f64::from(self.airframe.max_rotor_thrust_n())
    }
}
