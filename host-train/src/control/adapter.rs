//! The core's [`hamflight::FlightController`] behind the host [`Controller`] interface, so the
//! SITL plant flies the exact f32 code the firmware runs; the stock configurations
//! ([`geometric_adaptive`], [`ida_pbc`]) and the gains a learned model flies with. The names
//! the command line knows them by are [`super::registry`]'s.

use crate::control::controller::Controller;
use crate::sim::plant::{PlantState, VehicleParams};
use crate::sim::trajectory::TrajectoryPoint;
use anyhow::{Context, Result};
use hamflight::mixer::Airframe;
use hamflight::model::{HamiltonianModel, LearnedModel, NominalModel};
use hamflight::AdaptationLaw;
use hamflight::{FlightController, Gains, Measurement, Output, Setpoint, State, VehicleFacts};
use std::path::Path;

/// The stock vehicle's gains ([`Gains::default`]) with the adaptation law `law`.
pub fn gains_with(law: AdaptationLaw) -> Gains {
    Gains {
        law,
        ..Gains::default()
    }
}

/// A host controller that is the core's: it also gives the core's full [`Output`].
pub trait CoreStep: Controller {
    /// One core step on f32 state, setpoint and sensor measurement.
    fn core_step(&mut self, state: &State, sp: &Setpoint, meas: &Measurement, dt_s: f32) -> Output;

    /// The adaptation law it flies, or `None` with adaptation off.
    fn core_law(&self) -> Option<AdaptationLaw>;

    /// Mixes for `airframe` instead of the CF2X's.
    fn set_core_airframe(&mut self, airframe: Airframe);
}

impl<M: HamiltonianModel> CoreStep for CoreController<M> {
    fn core_step(&mut self, state: &State, sp: &Setpoint, meas: &Measurement, dt_s: f32) -> Output {
        let out = self.inner.step_measured(state, sp, meas, dt_s);
        self.last = Some(out);
        out
    }

    fn core_law(&self) -> Option<AdaptationLaw> {
        let g = &self.inner.gains;
        g.adapt.then_some(g.law)
    }

    fn set_core_airframe(&mut self, airframe: Airframe) {
        self.inner.airframe = airframe;
    }
}

/// Loads a learned model from a weight blob, with the file named in any error.
pub fn load_learned(path: &Path) -> Result<LearnedModel> {
    let bytes = std::fs::read(path)
        .with_context(|| format!("cannot read weight blob `{}`", path.display()))?;
    LearnedModel::from_blob(&bytes)
        .map_err(|e| anyhow::anyhow!("weight blob `{}`: {e}", path.display()))
}

/// The gains a learned model flies with: those of the vehicle its blob describes (mass, hover
/// inertia, motor lag; [`Gains::for_vehicle`]).
pub fn gains_for(model: &LearnedModel) -> Gains {
    Gains::for_vehicle(&VehicleFacts::of(model))
}

/// The core mixer's airframe for the plant's vehicle (its geometry, coefficients and top speed).
pub fn airframe_of(v: &VehicleParams) -> Airframe {
    Airframe {
        arm_xy_m: v.arm_xy_m as f32,
        kf_n_per_rpm2: v.kf_n_per_rpm2 as f32,
        km_nm_per_rpm2: v.km_nm_per_rpm2 as f32,
        max_rpm: v.max_rpm() as f32,
    }
}

/// [`airframe_of`] the vehicle, or `None` where it is the CF2X's [`Airframe::default`] to 1e-6
/// (so the stock vehicle's flights keep the core's own f32 constants bit for bit).
pub fn other_airframe(v: &VehicleParams) -> Option<Airframe> {
    let (a, d) = (airframe_of(v), Airframe::default());
    let close = |x: f32, y: f32| (x - y).abs() <= 1e-6 * y.abs();
    let same = close(a.arm_xy_m, d.arm_xy_m)
        && close(a.kf_n_per_rpm2, d.kf_n_per_rpm2)
        && close(a.km_nm_per_rpm2, d.km_nm_per_rpm2)
        && close(a.max_rpm, d.max_rpm);
    (!same).then_some(a)
}

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

    /// Mixes for `airframe` instead of the CF2X's.
    pub fn set_airframe(&mut self, airframe: Airframe) {
        self.inner.airframe = airframe;
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
        t_s: f64,
        state: &PlantState,
        reference: &TrajectoryPoint,
        dt_s: f64,
    ) -> [f64; 4] {
        self.step_measured(t_s, state, None, reference, dt_s)
    }

    fn step_measured(
        &mut self,
        _t_s: f64,
        state: &PlantState,
        acc_body_m_s2: Option<&nalgebra::Vector3<f64>>,
        reference: &TrajectoryPoint,
        dt_s: f64,
    ) -> [f64; 4] {
        let meas = Measurement {
            acc_body_m_s2: acc_body_m_s2.map(|a| a.cast::<f32>()),
        };
        let out = self
            .inner
            .step_measured(&state.into(), &reference.into(), &meas, dt_s as f32);
        self.last = Some(out);
        out.rotors.rpm.map(f64::from)
    }

    fn adaptation_estimate(&self) -> Option<Vec<f64>> {
        self.inner.gains.adapt.then(|| {
            self.inner
                .estimate()
                .iter()
                .map(|v| f64::from(*v))
                .collect()
        })
    }
}

/// The classic adaptive baseline: nominal model, hand-chosen features, adaptation on.
pub fn geometric_adaptive() -> CoreController<NominalModel> {
    CoreController::new(
        "geometric-adaptive",
        NominalModel::default(),
        Gains::default(),
    )
}

/// The energy-based law on the nominal model without adaptation.
pub fn ida_pbc() -> CoreController<NominalModel> {
    let gains = Gains {
        adapt: false,
        ..Gains::default()
    };
    CoreController::new("ida-pbc", NominalModel::default(), gains)
}
