//! The control loop, independent of the chip: the latest input from the link, one
//! [`FlightController::step`] per timer tick, the PWM map, the watchdog and the statistics.
//!
//! A tick steps the controller only when a fresh input arrived since the previous tick (a state
//! is never used twice, so the adaptation law integrates each measurement once), with dt the
//! time since the state it last used ([`dt_for`]: two periods after one dropped frame, by the
//! sender's sequence numbers bounded by the firmware's ticks). Without
//! fresh input the motors hold their last command until the watchdog runs out: no valid state
//! for [`WATCHDOG_MS`] stops them. The next valid state resumes control (the adaptation estimate
//! is kept).
//!
//! The setpoint is held: an input without one ([`Input::setpoint`] `None`) flies the last one
//! received. Until there is one (at boot, and after a watchdog trip, which forgets it) an input
//! counts as no input.

use crate::link::{Input, LinkStatus, ModelKind, Report, Telemetry};
use crate::motor::{rpm_to_pwm, Motors};
use embedded_hal::pwm::SetDutyCycle;
use hamflight::blob::BlobError;
use hamflight::model::{HamiltonianModel, LearnedModel};
use hamflight::{FlightController, Gains, Setpoint, State, VehicleFacts};

/// Control-loop rate (Hz): 500, or 1000 with the `loop-1khz` feature.
pub const LOOP_HZ: u32 = if cfg!(feature = "loop-1khz") {
    1000
} else {
    500
};
/// One control period (s): the controller's dt when consecutive ticks each bring a fresh state.
pub const DT_S: f32 = 1.0 / LOOP_HZ as f32;
/// Motors off when no valid state arrived for this long (ms).
pub const WATCHDOG_MS: u32 = 50;
/// [`WATCHDOG_MS`] in control ticks (rounded up).
pub const WATCHDOG_TICKS: u32 = (WATCHDOG_MS * LOOP_HZ).div_ceil(1000);

/// The model the firmware flies: the learned model of the embedded blob, decoded in place into
/// a `static` (see [`load_model`]) and borrowed, so that its 10 KiB never pass through the stack.
#[cfg(not(hamflight_untrained))]
pub type Model = &'static LearnedModel;
/// The model the firmware flies: built without trained weights (`build.rs` found no
/// `weights/default.hfw`), the nominal model; the embedded placeholder blob is still checked.
#[cfg(hamflight_untrained)]
pub type Model = hamflight::model::NominalModel;

/// Which model this build flies (reported in [`crate::link::Hello`]).
pub const MODEL_KIND: ModelKind = if cfg!(hamflight_untrained) {
    ModelKind::Nominal
} else {
    ModelKind::Learned
};

/// Decodes and checks the weight blob into `slot` ([`hamflight::blob::decode_model_into`]: in
/// place, no copy of the weights on the stack; the networks, the mass, the motor lag and the port
/// terms) and builds the model on it.
///
/// # Errors
/// The blob's first failed check ([`BlobError`]); `slot` is then unchanged.
#[cfg(not(hamflight_untrained))]
pub fn load_model(blob: &[u8], slot: &'static mut LearnedModel) -> Result<Model, BlobError> {
    hamflight::blob::decode_model_into(blob, slot)?;
    Ok(slot)
}

/// Decodes and checks the weight blob into `slot` (in place, as the trained build does) and
/// builds the nominal model.
///
/// # Errors
/// The blob's first failed check ([`BlobError`]).
#[cfg(hamflight_untrained)]
pub fn load_model(blob: &[u8], slot: &'static mut LearnedModel) -> Result<Model, BlobError> {
    hamflight::blob::decode_into(blob, &mut slot.weights).map(|()| Model::default())
}

/// The controller's dt (s) for a step on a state `seq_gap` sender periods after the state it
/// last used, and `ticks_since_used` of the firmware's own ticks later: the time that passed
/// between the two states, as the smaller of the two clocks says. The sender's count
/// ([`Input::seq`], one per control period) sees states lost on the link and stays exact when the
/// firmware waits on a lock-step host (the PIL test); the firmware's ticks bound a sender that
/// skips numbers. One period for the first state, the first after a watchdog trip, and a repeated
/// or restarted sequence (gap 0, or beyond the watchdog timeout).
pub fn dt_for(ticks_since_used: Option<u32>, seq_gap: u32) -> f32 {
    let periods = match ticks_since_used {
        Some(ticks) if (1..=WATCHDOG_TICKS).contains(&seq_gap) => seq_gap.min(ticks).max(1),
        _ => 1,
    };
    periods as f32 * DT_S
}

// The longest dt (the watchdog timeout) must stay inside the core's (0, 0.1] s.
const _: () = assert!(WATCHDOG_TICKS >= 1 && WATCHDOG_MS <= 100);

/// Counts ticks without a valid state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Watchdog {
    ticks_since_valid: u32,
    timeout_ticks: u32,
    tripped: bool,
    trips: u32,
}

impl Watchdog {
    /// A watchdog that trips after `timeout_ticks` ticks without [`Watchdog::feed`]; it starts
    /// tripped-free but with no state seen.
    pub const fn new(timeout_ticks: u32) -> Self {
        Self {
            ticks_since_valid: 0,
            timeout_ticks,
            tripped: false,
            trips: 0,
        }
    }

    /// A valid state arrived.
    pub fn feed(&mut self) {
        self.ticks_since_valid = 0;
        self.tripped = false;
    }

    /// One tick without a valid state; true exactly on the tick that trips it.
    pub fn starve(&mut self) -> bool {
        self.ticks_since_valid = self.ticks_since_valid.saturating_add(1);
        if !self.tripped && self.ticks_since_valid >= self.timeout_ticks {
            self.tripped = true;
            self.trips += 1;
            return true;
        }
        false
    }

    /// True while tripped (motors must be off).
    pub fn tripped(&self) -> bool {
        self.tripped
    }

    /// Trips so far.
    pub fn trips(&self) -> u32 {
        self.trips
    }
}

/// Measures the cost of a step with a free-running counter.
pub trait CostCounter {
    /// The counter now.
    fn now(&mut self) -> u32;
    /// Ticks from `start` to now (handles wrap-around and down-counters).
    fn since(&mut self, start: u32) -> u32;
}

/// A counter that measures nothing (host tests).
#[derive(Clone, Copy, Debug, Default)]
pub struct NoCost;

impl CostCounter for NoCost {
    fn now(&mut self) -> u32 {
        0
    }
    fn since(&mut self, _start: u32) -> u32 {
        0
    }
}

/// What a tick did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TickOutcome {
    /// The controller ran; send this telemetry.
    Stepped(Telemetry),
    /// The motors went off without a step (first tick of that condition); report it.
    Stopped(LinkStatus),
    /// Nothing new.
    Idle,
}

/// The chip-independent control loop.
pub struct ControlLoop<M> {
    controller: Result<FlightController<M>, BlobError>,
    latest: Option<Input>,
    /// The last setpoint received; `None` at boot and after a watchdog trip.
    setpoint: Option<Setpoint>,
    /// Ticks since the controller last used a state (a step without fault), counting the
    /// current one; `None` before the first and after a watchdog trip.
    ticks_since_used: Option<u32>,
    /// [`Input::seq`] of the state last used.
    last_used_seq: u32,
    watchdog: Watchdog,
    status: LinkStatus,
    steps: u32,
    max_cost: u32,
    min_cost: u32,
    total_cost: u64,
}

/// The core's gains for the vehicle the blob describes ([`Gains::for_vehicle`]: mass, inertia,
/// motor lag); with the `composite` feature, the composite adaptation law.
pub fn default_gains(facts: &VehicleFacts) -> Gains {
    #[cfg(feature = "composite")]
    {
        Gains {
            law: hamflight::AdaptationLaw::Composite,
            ..Gains::for_vehicle(facts)
        }
    }
    #[cfg(not(feature = "composite"))]
    {
        Gains::for_vehicle(facts)
    }
}

impl<M: HamiltonianModel> ControlLoop<M> {
    /// A loop on `model` (or on the reason the model could not be loaded: then the motors stay
    /// off) with [`default_gains`].
    pub fn new(model: Result<M, BlobError>) -> Self {
        let status = if model.is_ok() {
            LinkStatus::WaitingForState
        } else {
            LinkStatus::BadBlob
        };
        Self {
            controller: model.map(|m| {
                let gains = default_gains(&VehicleFacts::of(&m));
                FlightController::new(m, gains)
            }),
            latest: None,
            setpoint: None,
            ticks_since_used: None,
            last_used_seq: 0,
            watchdog: Watchdog::new(WATCHDOG_TICKS),
            status,
            steps: 0,
            max_cost: 0,
            min_cost: u32::MAX,
            total_cost: 0,
        }
    }

    /// The blob check's result.
    pub fn blob_error(&self) -> Option<BlobError> {
        self.controller.as_ref().err().copied()
    }

    /// The controller, unless the blob check failed.
    pub fn controller_mut(&mut self) -> Option<&mut FlightController<M>> {
        self.controller.as_mut().ok()
    }

    /// Why the motors are off, or `Running`.
    pub fn status(&self) -> LinkStatus {
        self.status
    }

    /// A new input from the link; the next tick uses it.
    pub fn on_input(&mut self, input: Input) {
        self.latest = Some(input);
    }

    /// One timer tick: step on fresh input, else hold or stop the motors.
    pub fn tick<A, B, C, D, K>(
        &mut self,
        motors: &mut Motors<A, B, C, D>,
        cost: &mut K,
    ) -> TickOutcome
    where
        A: SetDutyCycle,
        B: SetDutyCycle,
        C: SetDutyCycle,
        D: SetDutyCycle,
        K: CostCounter,
    {
        let controller = match self.controller.as_mut() {
            Ok(c) => c,
            Err(_) => {
                motors.off();
                self.latest = None;
                return TickOutcome::Idle;
            }
        };
        self.ticks_since_used = self.ticks_since_used.map(|n| n.saturating_add(1));
        let latest = self.latest.take();
        if let Some(sp) = latest.and_then(|i| i.setpoint) {
            self.setpoint = Some(sp);
        }
        let (Some(input), Some(setpoint)) = (latest, self.setpoint) else {
            if self.watchdog.starve() {
                motors.off();
                self.status = LinkStatus::WatchdogTripped;
                self.ticks_since_used = None;
                self.setpoint = None;
                return TickOutcome::Stopped(self.status);
            }
            if self.watchdog.tripped() || self.status == LinkStatus::WaitingForState {
                motors.off();
            }
            return TickOutcome::Idle;
        };

        let dt_s = dt_for(
            self.ticks_since_used,
            input.seq.wrapping_sub(self.last_used_seq),
        );
        let start = cost.now();
        let state = State::from(&input.state);
        let meas = hamflight::Measurement {
            acc_body_m_s2: input.state.acc.map(nalgebra::Vector3::from),
        };
        let out = controller.step_measured(&state, &setpoint, &meas, dt_s);
        let mut pwm = out.rotors.rpm.map(rpm_to_pwm);
        if motors.set(pwm).is_err() {
            pwm = [0; 4];
        }
        let spent = cost.since(start);

        if !out.faults.is_fault() {
            // The law and the adaptation integrated this state over `dt_s`.
            self.ticks_since_used = Some(0);
            self.last_used_seq = input.seq;
        }
        if out.faults.bad_state {
            // Not a valid state: it does not feed the watchdog (the step already gave motors off).
            if self.watchdog.starve() {
                self.status = LinkStatus::WatchdogTripped;
                self.ticks_since_used = None;
                self.setpoint = None;
            }
        } else {
            self.watchdog.feed();
            self.status = LinkStatus::Running;
        }
        self.steps = self.steps.wrapping_add(1);
        self.max_cost = self.max_cost.max(spent);
        self.min_cost = self.min_cost.min(spent);
        self.total_cost = self.total_cost.wrapping_add(u64::from(spent));
        let mut t = Telemetry::from_output(input.seq, &out, pwm);
        t.step_cost = spent;
        t.watchdog_trips = self.watchdog.trips();
        TickOutcome::Stepped(t)
    }

    /// Statistics so far (stack and frame counts are filled in by the caller).
    pub fn report(&self) -> Report {
        Report {
            steps: self.steps,
            max_step_cost: self.max_cost,
            min_step_cost: if self.steps == 0 { 0 } else { self.min_cost },
            total_step_cost: self.total_cost,
            watchdog_trips: self.watchdog.trips(),
            ..Report::default()
        }
    }
}
