//! The controller interface every flight controller implements on the host (the baselines here,
//! and the core's adaptive controller through an adapter).

use nalgebra::Vector3;

use crate::sim::plant::PlantState;
use crate::sim::trajectory::TrajectoryPoint;

/// A flight controller: state + reference in, four rotor speed commands out.
pub trait Controller {
    /// Short name, as used on the command line and in reports (e.g. `"pid"`).
    fn name(&self) -> &str;

    /// Forget all internal state (integrators, adaptation, filters) before a new flight.
    fn reset(&mut self);

    /// One control tick at time `t_s` (s) with the measured `state`, the `reference` and the
    /// tick period `dt_s` (s). Returns rotor speed commands (rpm) for rotors 1..4 (numbering of
    /// [`crate::sim::plant`]); the plant clamps them to its limits and holds them until the next tick.
    fn step(
        &mut self,
        t_s: f64,
        state: &PlantState,
        reference: &TrajectoryPoint,
        dt_s: f64,
    ) -> [f64; 4];

    /// [`Controller::step`] with the accelerometer's reading (specific force in the body frame,
    /// m/s²) when the platform gives one. Controllers that do not use it ignore it (the default).
    fn step_measured(
        &mut self,
        t_s: f64,
        state: &PlantState,
        acc_body_m_s2: Option<&Vector3<f64>>,
        reference: &TrajectoryPoint,
        dt_s: f64,
    ) -> [f64; 4] {
        let _ = acc_body_m_s2;
        self.step(t_s, state, reference, dt_s)
    }

    /// The current adaptation estimate (e.g. the paper's `a`), if the controller adapts.
    fn adaptation_estimate(&self) -> Option<Vec<f64>> {
        None
    }
}
