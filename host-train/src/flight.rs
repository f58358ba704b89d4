//! The core's [`hamflight::FlightController`] behind the host [`Controller`] interface, so the
//! SITL plant flies the exact f32 code the firmware runs.
//!
//! Names in `host-train eval --controller`:
//! - `adaptive`: learned model + adaptation (the paper's controller);
//! - `learned`: learned model, adaptation off (the paper's "without adaptation");
//! - `geometric-adaptive`: nominal model with hand-chosen features (a constant world force and
//!   a constant body torque) + adaptation — the classic adaptive baseline;
//! - `ida-pbc`: nominal model, no adaptation (the energy-based law on the true constants).

use crate::controller::{Controller, TrajectoryPoint};
use crate::plant::PlantState;
use hamflight::model::{HamiltonianModel, NominalModel};
use hamflight::{FlightController, Gains, Output};

/// Adapts a core [`FlightController`] to the host [`Controller`] trait.
pub struct CoreController<M> {
    name: String,
    inner: FlightController<M>,
    last: Option<Output>,
}

impl<M: HamiltonianModel> CoreController<M> {
    /// Wraps a controller on `model` with `gains` under `name`.
    pub fn new(name: &str, model: M, gains: Gains) -> Self {
        Self {
            name: name.to_owned(),
            inner: FlightController::new(model, gains),
            last: None,
        }
    }

    /// The wrapped core controller.
    pub fn inner(&self) -> &FlightController<M> {
        &self.inner
    }

    /// The output of the last step, if any.
    pub fn last_output(&self) -> Option<&Output> {
        self.last.as_ref()
    }
}

impl<M: HamiltonianModel> Controller for CoreController<M> {
    fn name(&self) -> &str {
        &self.name
    }

    fn reset(&mut self) {
        self.inner.reset();
        self.last = None;
    }

    fn step(
        &mut self,
        _t_s: f64,
        state: &PlantState,
        reference: &TrajectoryPoint,
        dt_s: f64,
    ) -> [f64; 4] {
        let out = self
            .inner
            .step(&state.into(), &reference.into(), dt_s as f32);
        self.last = Some(out);
        out.rotors.rpm.map(f64::from)
    }

    fn adaptation_estimate(&self) -> Option<Vec<f64>> {
        self.inner
            .gains
            .adapt
            .then(|| self.inner.estimate().iter().map(|v| f64::from(*v)).collect())
    }
}

/// The classic adaptive baseline: nominal model, hand-chosen features, adaptation on.
pub fn geometric_adaptive() -> CoreController<NominalModel> {
    CoreController::new("geometric-adaptive", NominalModel::default(), Gains::default())
}

/// The energy-based law on the nominal model without adaptation.
pub fn ida_pbc() -> CoreController<NominalModel> {
    let gains = Gains {
        adapt: false,
        ..Gains::default()
    };
    CoreController::new("ida-pbc", NominalModel::default(), gains)
}
