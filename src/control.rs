//! The energy-based (IDA-PBC) tracking controller with disturbance compensation
//! (paper eq. `ES_DI_COMP_control`), u = u_ES + u_DI + u_DC, and the [`FlightController`] that
//! owns the model, the gains and the adaptation state.
//!
//! Expanded for the quadrotor (docs/math.md, "The IDA-PBC control law"), with body-frame errors
//! e_p = Rᵀ(p − p*), e_v = v − Rᵀv*, e_R = ½(R*ᵀR − RᵀR*)^∨, e_ω = ω − RᵀR*ω*:
//!
//! - b_v = m g Rᵀe₃ − 𝔭_v × ω − k_p e_p + 𝔭̇*_v − k_v e_v − (W a)_v, with 𝔭̇*_v = m(Rᵀa* − ω × Rᵀv*);
//! - b_ω = ω × Jω − k_R e_R + 𝔭̇*_ω − k_ω e_ω − (W a)_ω, with 𝔭̇*_ω = −J(ω × RᵀR*ω*) (ω̇* ≈ 0);
//! - u = g†[b_v; b_ω].
//!
//! The quadrotor cannot make body x/y force, so R* follows b_v (F = R b_v, b₃* = F/‖F‖, see
//! [`crate::reference::desired_attitude`]) with Ḟ ≈ m p⃛* (the feedforward part of Ḟ: a
//! documented approximation). g† is taken on the actuated rows only (body z force and the three
//! torques): for the true g it is exactly the pseudo-inverse, and for a learned g it keeps model
//! error in the unactuated rows from leaking into the torques.

use crate::adapt::{
    Adaptation, AdaptationLaw, AdaptationRates, CompositeGains, Measurement, TrackingError,
};
#[cfg(feature = "composite")]
use crate::adapt::{PortPrediction, PredictionInput};
use crate::mixer::{Airframe, RotorCommand, Saturation, Wrench};
use crate::model::{HamiltonianModel, ModelTerms, State, DEFAULT_MOTOR_TAU_S, FEATURES, MASS_KG};
use crate::reference::{desired_attitude, Setpoint, TiltLimit};
use crate::shaping::SetpointShaper;
use nalgebra::{Matrix3, Matrix4, SVector, Vector3, Vector4};

/// Controller gains and adaptation rates.
///
/// [`Gains::for_vehicle`] (and so [`Gains::default`], the stock CF2X) derives them from the
/// vehicle ([`VehicleFacts`]: mass, inertia, motor lag), for the sensor chain a Crazyflie gives
/// the controller (filtered gyro, an estimator, one sample of delay; docs/crazyflie-chain.md):
/// - k_p = 16 m, k_v = 8 m (ω_n = 4 rad/s, ζ = 1). The paper's 5 m and 2.5 m (ω_n = 2.2 rad/s,
///   ζ = 0.56) are stable but leave the adaptation loop slow and lightly damped.
/// - k_R and k_ω from the inertia and the motor lag, with the lag compensated
///   ([`LagCompensation`]); for the CF2X k_R = 4.3e-3 N·m/rad and k_ω = 4.2e-4 N·m·s/rad
///   (crazyflie-firmware's Lee controller uses 0.007 / 0.00115). The paper's k_R = 1.0 and
///   k_ω = 0.08, read as SI torque gains on J ≈ 1.4e-5 kg·m², are beyond what a 500 Hz loop can
///   hold; the earlier 0.015 / 0.002 ([`Gains::for_mass_kg`]) were tuned on a perfect state and
///   oscillate behind the Crazyflie's gyro filter and a 50–70 ms motor lag.
/// - Adaptation rates act on feature units: with features scaled so that a reads as m/s² (force)
///   and 1e-3 N·m (torque), m c_p ≈ 22 /s² and m c_v ≈ 14 /s keep the third-order translational
///   error loop (s³ + 8s² + (16 + m c_v)s + m c_p) well damped.
/// - The law's velocity is made consistent with the position
///   ([`Gains::velocity_consistency_tau_s`]), so a biased velocity estimate does not bias the
///   adaptation.
/// - The adaptation law is the composite law of [`crate::adapt`] where it is compiled in (feature
///   `composite`, a default), else the paper's gradient law; `law: AdaptationLaw::Gradient`
///   selects the paper's. Under saturation the tracking term's drive is bounded
///   ([`SATURATED_DRIVE_M`], [`SATURATED_DRIVE_RAD`]), never switched off; the composite law's
///   torque observer has a change detector ([`COMPOSITE_FAULT_INNOVATION`]). The robust clipping of [`AdaptationRates`] is off by
///   default (it cost the gradient law on paper-spiral and changed nothing measurable with the
///   composite law).
///
/// [`Gains::paper`] gives the paper's literal values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gains {
    /// k_p: position stiffness (N/m).
    pub k_p: f32,
    /// k_v: velocity damping (N·s/m).
    pub k_v: f32,
    /// k_R: attitude stiffness (N·m/rad).
    pub k_r: f32,
    /// k_ω: angular damping (N·m·s/rad).
    pub k_w: f32,
    /// Per-axis factor on k_R and k_ω (body x, y, z), ones by default. [`Gains::for_vehicle`]
    /// sets it to each axis's inertia relative to the stock one's, over the design's: a model
    /// learns J and the torque rows of g only up to a common factor per axis (J ω̇ = g_τ u + d
    /// fits the data as well with both scaled), and with it the attitude loop the vehicle sees
    /// is the same on every axis whichever split the model learned.
    pub attitude_axis_scale: Vector3<f32>,
    /// Largest tilt of the desired thrust axis from world z (rad).
    pub max_tilt_rad: f32,
    /// Adaptation rates (paper eq. `geometric_adaptive_law`).
    pub rates: AdaptationRates,
    /// Whether the adaptation law runs (the paper's "with" / "without adaptation").
    pub adapt: bool,
    /// Which adaptation law: the paper's gradient law or the composite law (see [`crate::adapt`]).
    pub law: AdaptationLaw,
    /// Tuning of the composite law's prediction term.
    pub composite: CompositeGains,
    /// Natural frequency ω (rad/s) of the reference model that shapes setpoint jumps
    /// ([`crate::shaping`]); 0 turns it off. Smooth trajectories pass unchanged.
    pub shaping_omega_rad_s: f32,
    /// The motor-lag compensation in front of the mixer.
    pub lag: LagCompensation,
    /// Time constant τ_c (s) of the velocity-consistency correction; 0 turns it off (the law uses
    /// the state's velocity as given, as the paper).
    ///
    /// The law uses v + Rᵀ c, where c is the low-passed (τ_c) difference between the rate of
    /// the given position and the given velocity in the world frame, ṗ − R v. An estimator whose
    /// model has no horizontal body force (the Crazyflie's EKF in flight) carries a steady
    /// velocity bias b_v under a steady external force while its position stays put; the law's
    /// damping k_v e_v then pushes with k_v b_v, and the paper's adaptation settles where
    /// c_p ê_p = −c_v b_v, a position offset of (c_v / c_p) b_v. The position's rate is
    /// unbiased at steady state, so the corrected velocity is too; on an unbiased state c ≈ 0
    /// (differences of order dt · acceleration).
    pub velocity_consistency_tau_s: f32,
}

/// Motor-lag compensation: a lead on the wrench that makes a first-order motor lag τ_m look
/// like a shorter one τ_t to the law's torques.
///
/// The controller keeps û, the delivered wrench (after the mixer's saturation) through the motor
/// model τ_m û̇ = u_cmd − û, and commands u_cmd = û + (τ_m / τ_t)(u − û). If the model holds, û
/// follows the law's u with time constant τ_t: τ_t û̇ = u − û. Equivalently a lead
/// (τ_m s + 1)/(τ_t s + 1) whose state is the delivered wrench, so a saturated command does
/// not wind it up. Off when `motor_tau_s` ≤ `target_tau_s`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LagCompensation {
    /// τ_m: the motors' time constant the compensation assumes (s); 0 turns it off.
    pub motor_tau_s: f32,
    /// τ_t: the lag the law should see instead (s).
    pub target_tau_s: f32,
}

impl LagCompensation {
    /// No compensation.
    pub const OFF: Self = Self {
        motor_tau_s: 0.0,
        target_tau_s: 0.0,
    };

    /// The lead ratio τ_m / τ_t, or `None` when off (or not a finite ratio above 1).
    pub fn ratio(&self) -> Option<f32> {
        let r = self.motor_tau_s / self.target_tau_s;
        (self.target_tau_s > 0.0 && r.is_finite() && r > 1.0).then_some(r)
    }
}

/// The lag the compensated motors show the law (s): [`Gains::for_vehicle`] makes any slower
/// motor look like this one.
pub const LAG_TARGET_S: f32 = 0.006;

/// The delay in front of the attitude loop besides the motors (s) that [`Gains::for_vehicle`]
/// designs for: the gyro's 2-pole 80 Hz low-pass (≈ 2.8 ms), one sample between estimate and
/// controller (1 ms) and half a 500 Hz tick of hold (1 ms).
pub const SENSOR_DELAY_S: f32 = 0.005;

/// The accelerometer's delay in front of the law (s): its 2-pole 30 Hz low-pass (≈ 7.5 ms),
/// one sample between estimate and controller and half a tick of hold. The composite law's
/// prediction of the force rows is delayed by it ([`CompositeGains::accel_lag_s`]), as the
/// torque rows' is by [`SENSOR_DELAY_S`].
pub const ACCEL_DELAY_S: f32 = 0.0095;

/// The composite law's torque process noise Q under [`Gains::for_vehicle`] ((1e-3 N·m)² per
/// second). The prediction term is a disturbance observer on the torque rows: its bandwidth,
/// about √(q h² / (r dt)), adds loop gain and lag at the attitude crossover. Measured with the
/// chain and a 70 ms lag (docs/crazyflie-chain.md): the earlier tuning (Q = 1, the tracking
/// term's torque rates, a 10 ms low-pass on both sides, no sensor lag in the prediction) left
/// the attitude loop 35°: the observer took 13°, the tracking term's torque rates 8°. With
/// [`COMPOSITE_TORQUE_RATE_SCALE`], [`COMPOSITE_GYRO_LAG_S`] and
/// [`COMPOSITE_TORQUE_FILTER_S`], Q = 0.5 leaves 45.3°. The cost is a slower answer to a torque
/// step: rotor-loss-mid recovers in 1.26 s instead of 0.73 s (the gradient law: 2.88 s).
pub const COMPOSITE_Q_TORQUE: f32 = 0.5;

/// The share of the (already scaled) torque rates c_R, c_ω the composite law's tracking term
/// keeps under [`Gains::for_vehicle`]: none. The prediction term answers torque disturbances
/// faster per degree of phase margin than the tracking term does.
pub const COMPOSITE_TORQUE_RATE_SCALE: f32 = 0.0;

/// The lag (s) of the composite law's torque prediction behind the motors. The gyro's 2-pole
/// 80 Hz low-pass (2.8 ms), one sample of delay (1 ms), half a 500 Hz tick of hold (1 ms) and
/// the half tick of the rate difference (1 ms) make 5.8 ms; the margin keeps growing past it
/// (with Q = 0.8 and no low-pass: 41.6° with none, 44.1° at 6 ms, 45.4° at 8 ms, 46.9° at
/// 11 ms: the prediction's excess lag feeds a share of the command's rate into ε, a lead in
/// the observer's loop). 11 ms is chosen.
pub const COMPOSITE_GYRO_LAG_S: f32 = 0.011;

/// The composite law's low-pass on its torque rows under [`Gains::for_vehicle`] (s). Each ms
/// of it costs the attitude loop about 0.4° of margin, but without it a badly trained model
/// (2 epochs on 8 s of hover) saturates the mixer on 90 % of ticks and crashes on hover-wind:
/// the model's error closes a loop through the unfiltered observer near the Nyquist rate.
/// 3 ms and 5 ms both fly it (0.32 % and 0.20 % saturated).
pub const COMPOSITE_TORQUE_FILTER_S: f32 = 0.005;

/// The composite law's change detector under [`Gains::for_vehicle`]
/// ([`CompositeGains::fault_innovation`], 1e-3 N·m RMS of the torque rows' prediction error,
/// low-passed over 20 ms). Without a fault the error stays below 0.3 on every scenario of
/// `scenarios/` but a setpoint step's first ticks (docs/adaptation.md, "Rotor loss"); the
/// margin measurement's injection makes 0.2; a rotor losing 40 % of its thrust crosses 0.35
/// within 30 ms. After it, [`CompositeGains::fault_q_torque`] for
/// [`CompositeGains::fault_boost_s`].
pub const COMPOSITE_FAULT_INNOVATION: f32 = 0.35;

/// [`Gains::velocity_consistency_tau_s`] of [`Gains::for_vehicle`] (s): slow against the
/// position loop (4 rad/s), fast against a changing wind; measured flat from 0.1 to 1 s.
pub const VELOCITY_CONSISTENCY_TAU_S: f32 = 0.3;

/// The share of the perfect-state torque adaptation rates (c_R = 20,000, c_ω = 2,000) that
/// [`Gains::for_vehicle`] keeps. The adaptation's torque channel closes a second loop around the
/// attitude crossover. At the full rates the gradient law leaves 44° of the attitude loop's 54°
/// phase margin with the Crazyflie's sensor chain and a 50–70 ms motor lag; at 0.8 it leaves
/// 46°, so the loop keeps 45° with adaptation on. The cost is a slower answer to a torque
/// disturbance: rotor-loss-mid 1.81 → 1.99 cm. Lower c_ω alone buys more margin but less damping
/// of the adaptation loop, and hover attitude σ grows past 0.2°.
pub const TORQUE_ADAPTATION_SCALE: f32 = 0.8;

/// [`AdaptationRates::saturated_drive_m`] of the tuned gains (m): while the mixer saturates the
/// translational drive is that of at most this position error.
pub const SATURATED_DRIVE_M: f32 = 0.02;

/// [`AdaptationRates::saturated_drive_rad`] of the tuned gains (rad).
pub const SATURATED_DRIVE_RAD: f32 = 0.05;

/// The symmetric-optimum spacing a of the attitude design: the PD zero at ω_c / a, the lag at
/// a ω_c; a = 3 gives a phase margin of atan 3 − atan ⅓ ≈ 53° on the design model.
pub const ATTITUDE_SPACING: f32 = 3.0;

impl Default for Gains {
    /// The tuned gains for the stock vehicle ([`VehicleFacts::default`]).
    fn default() -> Self {
        Self::for_vehicle(&VehicleFacts::default())
    }
}

/// What the gains are derived from: the facts about the vehicle that a model (its weight blob)
/// carries. One image flies any vehicle because every gain comes from these.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VehicleFacts {
    /// Mass m (kg).
    pub mass_kg: f32,
    /// Principal moments of inertia diag(J) at hover (kg·m², body).
    pub inertia_kg_m2: Vector3<f32>,
    /// The actuator chain's first-order time constant (s): the motors' own plus the model's
    /// learned torque lag ([`crate::model::PortTerms::torque_lag_s`]).
    pub motor_tau_s: f32,
}

impl Default for VehicleFacts {
    /// The stock CF2X: [`MASS_KG`], J = diag(1.4, 1.4, 2.17)·1e-5 kg·m², [`DEFAULT_MOTOR_TAU_S`].
    fn default() -> Self {
        Self {
            mass_kg: MASS_KG,
            inertia_kg_m2: Vector3::new(1.4e-5, 1.4e-5, 2.17e-5),
            motor_tau_s: DEFAULT_MOTOR_TAU_S,
        }
    }
}

impl VehicleFacts {
    /// The facts `model` gives: its mass, the diagonal of its J at hover (level, at rest; the
    /// stock inertia where J⁻¹ is singular or not positive) and its motor lag.
    pub fn of<M: HamiltonianModel>(model: &M) -> Self {
        let stock = Self::default();
        let terms = model.terms(&State::default());
        let inertia_kg_m2 = match terms.inertia_inv.try_inverse().map(|j| j.diagonal()) {
            Some(d) if d.iter().all(|x| x.is_finite() && *x > 0.0) => d,
            _ => stock.inertia_kg_m2,
        };
        // The actuator chain's lag: the motors' own and the learned one from the rotors to the
        // torque that acts (PortTerms::torque_lag_s; zero for a rigid-body model).
        let tau = model.motor_tau_s() + model.port().torque_lag_s;
        Self {
            mass_kg: model.mass_kg(),
            inertia_kg_m2,
            motor_tau_s: if tau.is_finite() && tau >= 0.0 {
                tau
            } else {
                stock.motor_tau_s
            },
        }
    }

    /// Each axis's inertia relative to the stock vehicle's (J_i / J_stock,i), or `None` unless
    /// all three are finite and positive.
    fn inertia_ratio(&self) -> Option<Vector3<f32>> {
        let stock = Self::default().inertia_kg_m2;
        let r = self.inertia_kg_m2.component_div(&stock);
        r.iter().all(|x| x.is_finite() && *x > 0.0).then_some(r)
    }

    /// [`Gains::attitude_axis_scale`]: J_i / J_stock,i over the ratio of the axis k_R and k_ω
    /// are designed on (the smaller of x and y), so that k_R,i = J_stock,xy r_i ω_c² / a; ones
    /// on the stock vehicle and on any vehicle whose inertia is the stock one scaled. A factor
    /// within 1e-5 of one (the rounding of a J that came back through J⁻¹) is one, so the
    /// stock gains are bit for bit [`Gains::default`]'s whichever way J was read.
    pub fn attitude_axis_scale(&self) -> Vector3<f32> {
        match self.inertia_ratio() {
            Some(r) => (r / r.x.min(r.y)).map(|s| if (s - 1.0).abs() <= 1e-5 { 1.0 } else { s }),
            None => Vector3::new(1.0, 1.0, 1.0),
        }
    }

    /// [`crate::adapt::CompositeGains::r_torque_axis`]: (r_i / min(r_x, r_y))², with
    /// r_i = J_i / J_stock,i. A torque row's noise is J_i times the gyro's, so its variance R
    /// grows with J_i²: with this every axis's observer runs at the design axis's bandwidth
    /// whichever split of J and g the model learned (ones on the stock vehicle and on any
    /// uniformly scaled one).
    pub fn torque_noise_scale(&self) -> [f32; 3] {
        let s = self.attitude_axis_scale();
        [s.x * s.x, s.y * s.y, s.z * s.z]
    }
}

impl Gains {
    /// The gains for the vehicle `facts` describes: the translational gains of
    /// [`Gains::for_mass_kg`], and the attitude loop designed from the inertia and the motor lag.
    ///
    /// - A motor lag τ_m longer than [`LAG_TARGET_S`] is compensated down to it
    ///   ([`LagCompensation`]); the composite law's prediction assumes the same τ_m.
    /// - The law's velocity is made consistent with the position
    ///   ([`VELOCITY_CONSISTENCY_TAU_S`]), against an estimator's velocity bias.
    /// - The attitude loop per axis is J s² behind the lag τ_e = min(τ_m, τ_t) +
    ///   [`SENSOR_DELAY_S`]. A PD law k_R + k_ω s on it, by the symmetric optimum with spacing
    ///   a = [`ATTITUDE_SPACING`]: crossover ω_c = 1 / (a τ_e), k_ω = J ω_c, k_R = J ω_c² / a
    ///   (|L(jω_c)| = 1 exactly on the design model), with J the smaller of J_x and J_y.
    /// - The torque adaptation rates c_R, c_ω at [`TORQUE_ADAPTATION_SCALE`] of the
    ///   perfect-state ones, so that adaptation leaves the attitude loop 45° of phase margin.
    pub fn for_vehicle(facts: &VehicleFacts) -> Self {
        let mut g = Self::for_mass_kg(facts.mass_kg);
        let tau_m = if facts.motor_tau_s.is_finite() && facts.motor_tau_s > 0.0 {
            facts.motor_tau_s
        } else {
            0.0
        };
        g.composite.motor_tau_s = tau_m;
        g.lag = if tau_m > LAG_TARGET_S {
            LagCompensation {
                motor_tau_s: tau_m,
                target_tau_s: LAG_TARGET_S,
            }
        } else {
            LagCompensation::OFF
        };
        g.velocity_consistency_tau_s = VELOCITY_CONSISTENCY_TAU_S;
        let tau_e = tau_m.min(LAG_TARGET_S) + SENSOR_DELAY_S;
        let j = facts.inertia_kg_m2.x.min(facts.inertia_kg_m2.y);
        let wc = 1.0 / (ATTITUDE_SPACING * tau_e);
        if j.is_finite() && j > 0.0 {
            g.k_w = j * wc;
            g.k_r = j * wc * wc / ATTITUDE_SPACING;
            g.attitude_axis_scale = facts.attitude_axis_scale();
            g.composite.r_torque_axis = facts.torque_noise_scale();
        }
        g.rates.c_r *= TORQUE_ADAPTATION_SCALE;
        g.rates.c_w *= TORQUE_ADAPTATION_SCALE;
        g.composite.gyro_lag_s = COMPOSITE_GYRO_LAG_S;
        g.composite.torque_filter_tau_s = COMPOSITE_TORQUE_FILTER_S;
        g.composite.accel_lag_s = ACCEL_DELAY_S;
        g.composite.q_torque = COMPOSITE_Q_TORQUE;
        g.composite.torque_rate_scale = COMPOSITE_TORQUE_RATE_SCALE;
        g.composite.fault_innovation = COMPOSITE_FAULT_INNOVATION;
        g
    }

    /// The gains tuned on a perfect state for a vehicle of mass `mass_kg` (kg): k_p = 16 m and
    /// k_v = 8 m, so the translational loop keeps its natural frequency (4 rad/s) and damping
    /// (ζ = 1) whatever the vehicle weighs, with the stiff attitude gains k_R = 0.015,
    /// k_ω = 0.002, no lag compensation and no velocity consistency. The base of
    /// [`Gains::for_vehicle`], which is what a vehicle should fly.
    pub fn for_mass_kg(mass_kg: f32) -> Self {
        Self {
            k_p: 16.0 * mass_kg,
            k_v: 8.0 * mass_kg,
            k_r: 0.015,
            k_w: 0.002,
            attitude_axis_scale: Vector3::new(1.0, 1.0, 1.0),
            max_tilt_rad: 0.6,
            rates: AdaptationRates {
                c_p: 800.0,
                c_v: 500.0,
                c_r: 20_000.0,
                c_w: 2_000.0,
                a_max: 20.0,
                drive_max_m: f32::INFINITY,
                drive_max_rad: f32::INFINITY,
                soft_freeze_m: f32::INFINITY,
                saturated_drive_m: SATURATED_DRIVE_M,
                saturated_drive_rad: SATURATED_DRIVE_RAD,
                normalized: true,
            },
            adapt: true,
            law: AdaptationLaw::default(),
            composite: CompositeGains::default(),
            shaping_omega_rad_s: 3.0,
            lag: LagCompensation::OFF,
            velocity_consistency_tau_s: 0.0,
        }
    }

    /// The paper's literal values (Sec. 4): k_p = 0.135, k_v = 0.0675, k_R = 1.0, k_ω = 0.08,
    /// c_p = c_v = 0.04, c_R = c_ω = 0.5, and no robust clipping. See the type's docs for why
    /// they are not the default.
    pub fn paper() -> Self {
        Self {
            k_p: 0.135,
            k_v: 0.0675,
            k_r: 1.0,
            k_w: 0.08,
            attitude_axis_scale: Vector3::new(1.0, 1.0, 1.0),
            max_tilt_rad: 0.6,
            rates: AdaptationRates {
                c_p: 0.04,
                c_v: 0.04,
                c_r: 0.5,
                c_w: 0.5,
                a_max: 20.0,
                drive_max_m: f32::INFINITY,
                drive_max_rad: f32::INFINITY,
                soft_freeze_m: f32::INFINITY,
                saturated_drive_m: f32::INFINITY,
                saturated_drive_rad: f32::INFINITY,
                normalized: false,
            },
            adapt: true,
            law: AdaptationLaw::Gradient,
            composite: CompositeGains::default(),
            shaping_omega_rad_s: 0.0,
            lag: LagCompensation::OFF,
            velocity_consistency_tau_s: 0.0,
        }
    }
}

/// Faults and conditions of one step. Any of the first four means the output is
/// [`RotorCommand::OFF`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Faults {
    /// The state had a NaN or infinite component, or its R is not a rotation
    /// (see [`ROTATION_TOLERANCE`]).
    pub bad_state: bool,
    /// The setpoint had a NaN or infinite component.
    pub bad_setpoint: bool,
    /// dt was not in (0, 0.1] s.
    pub bad_dt: bool,
    /// The model or the law produced a non-finite or singular value.
    pub numeric: bool,
    /// The mixer saturated (a condition, not a fault: the output is still used).
    pub saturation: Saturation,
    /// The tilt limit shaped the desired attitude (a condition).
    pub tilt_limited: bool,
}

impl Faults {
    /// True if the output was forced to the safe state.
    pub fn is_fault(&self) -> bool {
        self.bad_state || self.bad_setpoint || self.bad_dt || self.numeric
    }
}

/// Largest accepted ‖RᵀR − I‖_F for the state's attitude (dimensionless); beyond it, or with
/// det R ≤ 0 (a reflection), the state is `bad_state` and the motors go off.
///
/// A rotation rounded to f32 (from a unit quaternion, or an integrated attitude) sits near 1e-6;
/// a quaternion whose norm is off by ε gives ≈ 4√3 ε, so 1e-3 accepts a quaternion normalized to
/// ≈ 1.4e-4, while a matrix scaled by 1.001 or sheared by 1e-3 is already refused. Inside the
/// tolerance the law's errors (e_R, Rᵀ v*) change by the same relative 1e-3: harmless.
pub const ROTATION_TOLERANCE: f32 = 1e-3;

/// True if `r` is a rotation to [`ROTATION_TOLERANCE`]: ‖RᵀR − I‖_F ≤ tolerance and det R > 0.
/// False for non-finite entries.
pub fn is_rotation(r: &Matrix3<f32>) -> bool {
    // RᵀR is symmetric: its entries are the columns' dot products, six of them, so
    // ‖RᵀR − I‖²_F = Σᵢ (cᵢ·cᵢ − 1)² + 2 Σᵢ<ⱼ (cᵢ·cⱼ)², and det R = c₀ · (c₁ × c₂).
    let (c0, c1, c2) = (r.column(0), r.column(1), r.column(2));
    let d00 = c0.dot(&c0) - 1.0;
    let d11 = c1.dot(&c1) - 1.0;
    let d22 = c2.dot(&c2) - 1.0;
    let (d01, d02, d12) = (c0.dot(&c1), c0.dot(&c2), c1.dot(&c2));
    let dev2 = d00 * d00 + d11 * d11 + d22 * d22 + 2.0 * (d01 * d01 + d02 * d02 + d12 * d12);
    let det = c0.dot(&c1.cross(&c2));
    // The comparisons are false for NaN: a non-finite R is refused.
    dev2 <= ROTATION_TOLERANCE * ROTATION_TOLERANCE && det > 0.0
}

/// What one control step produces.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Output {
    /// Rotor commands to apply ([`RotorCommand::OFF`] on a fault).
    pub rotors: RotorCommand,
    /// The wrench u the law asked for (before the mixer's saturation).
    pub wrench: Wrench,
    /// The wrench to hand to an outside mixer (the Crazyflie's power distribution, a simulator
    /// that takes thrust and moments): [`Output::wrench`] with the motor-lag lead
    /// ([`LagCompensation`]) on the torques, the wrench `rotors` mixes. Handing over `wrench`
    /// instead drops the lead the attitude gains were designed with.
    pub command: Wrench,
    /// The wrench the rotors deliver ([`Output::rotors`] through the forward mixer): the
    /// command less what the mixer's saturation gave up; zero on a fault.
    pub delivered: Wrench,
    /// The disturbance-weight estimate a after this step.
    pub a: SVector<f32, FEATURES>,
    /// The tracking errors of this step.
    pub errors: TrackingError,
    /// Faults and conditions.
    pub faults: Faults,
}

/// The flight controller: model, gains, mixer and adaptation state. `step` is allocation-free
/// and panic-free; non-finite input gives motors off and a fault flag.
#[derive(Clone, Debug)]
pub struct FlightController<M> {
    model: M,
    /// Gains and rates (may be changed between steps).
    pub gains: Gains,
    /// Rotor geometry for the mixer.
    pub airframe: Airframe,
    adaptation: Adaptation,
    /// The composite law's compensation feedforward: the last world compensation force R (W a)_v
    /// (N) and its low-passed rate (N/s).
    #[cfg_attr(not(feature = "composite"), allow(dead_code))]
    comp_prev_n: Option<Vector3<f32>>,
    #[cfg_attr(not(feature = "composite"), allow(dead_code))]
    comp_rate_n_s: Vector3<f32>,
    /// `gains.max_tilt_rad` with its cosine and sine, refreshed when the gain changes.
    tilt: TiltLimit,
    /// The reference model that shapes setpoint jumps.
    shaper: SetpointShaper,
    /// The delivered wrench through the motor model ([`LagCompensation`]): û = [f; τ].
    u_model: Option<Vector4<f32>>,
    /// The last given position (m, world) and velocity (m/s, world), and the
    /// velocity-consistency correction c (m/s, world), for [`Gains::velocity_consistency_tau_s`].
    prev_p_m: Option<(Vector3<f32>, Vector3<f32>)>,
    velocity_correction_m_s: Vector3<f32>,
    /// The model's terms at this tick's state, written in place by the step.
    terms: ModelTerms,
    /// True if the model carries port terms ([`crate::model::PortTerms`]) other than the
    /// identity: the law then compensates them (read once, at construction).
    port_active: bool,
}

impl<M: HamiltonianModel> FlightController<M> {
    /// A controller on `model` with `gains`, the CF2X airframe and a = 0.
    pub fn new(model: M, gains: Gains) -> Self {
        let port_active = !model.port().is_identity();
        Self {
            port_active,
            model,
            gains,
            airframe: Airframe::default(),
            adaptation: Adaptation::default(),
            comp_prev_n: None,
            comp_rate_n_s: Vector3::zeros(),
            tilt: TiltLimit::new(gains.max_tilt_rad),
            shaper: SetpointShaper::default(),
            u_model: None,
            prev_p_m: None,
            velocity_correction_m_s: Vector3::zeros(),
            terms: ModelTerms::ZERO,
        }
    }

    /// The model the controller uses.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The current disturbance-weight estimate a.
    pub fn estimate(&self) -> SVector<f32, FEATURES> {
        self.adaptation.a
    }

    /// Resets the adaptation (a = 0).
    pub fn reset(&mut self) {
        self.adaptation.reset();
        self.shaper.reset();
        self.comp_prev_n = None;
        self.comp_rate_n_s = Vector3::zeros();
        self.u_model = None;
        self.prev_p_m = None;
    }

    fn safe(&mut self, faults: Faults) -> Output {
        self.comp_prev_n = None;
        self.u_model = None;
        self.prev_p_m = None;
        self.shaper.reset();
        // The next good tick does not follow this one by one interval, and nothing was delivered.
        self.adaptation.break_sequence();
        self.adaptation.record_input(&Wrench::default());
        Output {
            rotors: RotorCommand::OFF,
            wrench: Wrench::default(),
            command: Wrench::default(),
            delivered: Wrench::default(),
            a: self.adaptation.a,
            errors: TrackingError::default(),
            faults,
        }
    }

    /// One control tick of length `dt_s` (s) without extra measurements:
    /// [`FlightController::step_measured`] with [`Measurement::default`].
    ///
    /// # Examples
    ///
    /// Hold a hover on the shipped weights; a non-finite state turns the motors off:
    ///
    /// ```
    /// use hamflight::model::LearnedModel;
    /// use hamflight::{FlightController, Gains, RotorCommand, Setpoint, State, VehicleFacts};
    /// use nalgebra::Vector3;
    ///
    /// let model = LearnedModel::from_blob(include_bytes!("../weights/default.hfw"))?;
    /// let gains = Gains::for_vehicle(&VehicleFacts::of(&model));
    /// let mut fc = FlightController::new(model, gains);
    /// let hold = Setpoint::hover(Vector3::new(0.0, 0.0, 1.0), 0.0);
    /// let at_hold = State { p_m: hold.p_m, ..State::default() };
    ///
    /// let out = fc.step(&at_hold, &hold, 0.002);
    /// assert!(!out.faults.is_fault());
    /// let thrust_n: f32 = out.rotors.thrust_n.iter().sum();
    /// assert!((thrust_n - 0.027 * 9.81).abs() < 0.05, "about m g at hover: {thrust_n}");
    ///
    /// let bad = State { p_m: Vector3::new(f32::NAN, 0.0, 1.0), ..at_hold };
    /// let out = fc.step(&bad, &hold, 0.002);
    /// assert!(out.faults.is_fault());
    /// assert_eq!(out.rotors, RotorCommand::OFF);
    /// # Ok::<(), hamflight::blob::BlobError>(())
    /// ```
    pub fn step(&mut self, state: &State, sp: &Setpoint, dt_s: f32) -> Output {
        self.step_measured(state, sp, &Measurement::default(), dt_s)
    }

    /// The adaptation state (a and the composite law's P).
    pub fn adaptation(&self) -> &Adaptation {
        &self.adaptation
    }

    /// One control tick of length `dt_s` (s): the wrench of the IDA-PBC law, mixed to rotors,
    /// then one step of the adaptation law; `meas` feeds the composite law (the accelerometer).
    pub fn step_measured(
        &mut self,
        state: &State,
        sp: &Setpoint,
        meas: &Measurement,
        dt_s: f32,
    ) -> Output {
        let mut out = Output::default();
        self.step_into(state, sp, meas, dt_s, &mut out);
        out
    }

    /// [`FlightController::step_measured`] written into `out`: for a caller that keeps the
    /// output in place (the Crazyflie app, whose stabilizer task has a small stack).
    pub fn step_into(
        &mut self,
        state: &State,
        sp: &Setpoint,
        meas: &Measurement,
        dt_s: f32,
        out: &mut Output,
    ) {
        // Without the composite law nothing reads the measurement.
        #[cfg(not(feature = "composite"))]
        let _ = meas;
        let mut faults = Faults {
            bad_state: !(state.is_finite() && is_rotation(&state.rot)),
            bad_setpoint: !sp.is_finite(),
            bad_dt: !(dt_s > 0.0 && dt_s <= 0.1),
            ..Faults::default()
        };
        if faults.is_fault() {
            *out = self.safe(faults);
            return;
        }
        let shaped = self.shaper.shape(sp, dt_s, self.gains.shaping_omega_rad_s);
        let sp = &shaped;
        if self.tilt.max_rad != self.gains.max_tilt_rad {
            self.tilt = TiltLimit::new(self.gains.max_tilt_rad);
        }
        let v_law = self.consistent_velocity(state, dt_s);
        self.model.write_terms(state, &mut self.terms);
        let Some(inertia) = self.terms.inertia_inv.try_inverse() else {
            faults.numeric = true;
            *out = self.safe(faults);
            return;
        };
        let demand = self.demand(state, sp, &v_law, &inertia, dt_s);
        faults.tilt_limited = demand.tilt_limited;
        let act = self.actuate(&demand.b_act, dt_s);
        faults.saturation = act.sat;
        let errors = &demand.errors;
        if act.singular || !(act.u.iter().all(|x| x.is_finite()) && errors_finite(errors)) {
            faults.numeric = true;
            *out = self.safe(faults);
            return;
        }
        if self.gains.adapt {
            self.adapt(state, meas, &inertia, &demand, &act, dt_s);
        }
        *out = Output {
            rotors: act.rotors,
            wrench: act.wrench,
            command: act.commanded,
            delivered: act.delivered,
            a: self.adaptation.a,
            errors: *errors,
            faults,
        };
    }

    /// The law's body-frame demand b = [b_v; b_ω] on the actuated rows and its errors (paper
    /// eq. `ES_DI_COMP_control`, docs/math.md "The IDA-PBC control law"). Out of line, as are
    /// [`Self::actuate`] and [`Self::adapt`]: each phase's temporaries then live in its own
    /// frame, not all at once in the step's, which keeps the step's stack small enough to run
    /// inline in the Crazyflie's stabilizer task.
    #[inline(never)]
    fn demand(
        &mut self,
        state: &State,
        sp: &Setpoint,
        v: &Vector3<f32>,
        inertia: &Matrix3<f32>,
        dt_s: f32,
    ) -> Demand {
        let g = &self.gains;
        let t = &self.terms;
        let m = t.mass_kg;
        let r = &state.rot;
        let rt = r.transpose();
        let w = &state.w_body_rad_s;
        let wa = t.features * self.adaptation.a;
        let wa_v = Vector3::new(wa.x, wa.y, wa.z);
        let wa_w = Vector3::new(wa.w, wa.a, wa.b);
        #[cfg(feature = "composite")]
        let mut port_pred = PortPrediction::default();

        // Translational law: b_v (body frame).
        let e_p = rt * (state.p_m - sp.p_m);
        let v_ref = rt * sp.v_m_s;
        let e_v = v - v_ref;
        let mut b_v =
            rt * ((Vector3::z() * t.gravity_m_s2 + sp.a_m_s2) * m) - e_p * g.k_p - e_v * g.k_v
                + w.cross(&e_v) * m
                - wa_v;
        // The port terms at the reference (docs/math.md "Dissipation, potential and actuator
        // lag"): the law cancels the drag, the gyrator and the learned potential at the
        // reference velocity, so what is left acts on the errors alone and is passive.
        if self.port_active {
            // With the composite law, the port force at the state for its prediction too.
            #[cfg(feature = "composite")]
            {
                let port = self.model.port();
                let (f_law, f_pred) = port.force_pair(&v_ref, &state.v_body_m_s, w);
                port_pred.input_gain = port.input_gain();
                port_pred.force_n = f_pred;
                b_v -= f_law;
            }
            #[cfg(not(feature = "composite"))]
            {
                b_v -= self.model.port().force(&v_ref, w);
            }
        }

        // Desired attitude from the force the law wants. Its rate Ḟ ≈ m p⃛*, and with the
        // composite law also minus the rate of the compensation R (W a)_v, so that the attitude
        // loop is told ahead how the thrust axis must turn to follow a changing disturbance.
        #[cfg_attr(not(feature = "composite"), allow(unused_mut))]
        let mut f_dot = sp.j_m_s3 * m;
        #[cfg(feature = "composite")]
        if g.adapt && g.law == AdaptationLaw::Composite && g.composite.feedforward_tau_s > 0.0 {
            let comp = r * wa_v;
            if let Some(prev) = self.comp_prev_n {
                let rate = (comp - prev) / dt_s;
                let alpha = dt_s / (g.composite.feedforward_tau_s + dt_s);
                let next = self.comp_rate_n_s + (rate - self.comp_rate_n_s) * alpha;
                if next.iter().all(|x| x.is_finite()) {
                    self.comp_rate_n_s = next;
                }
            }
            self.comp_prev_n = Some(comp);
            f_dot -= self.comp_rate_n_s;
        }
        #[cfg(not(feature = "composite"))]
        let _ = dt_s;
        let att = desired_attitude(
            &(r * b_v),
            &f_dot,
            sp.yaw_rad,
            sp.yaw_rate_rad_s,
            &self.tilt,
        );
        let e_r = crate::lie::rotation_error(r, &att.rot);
        let w_des_body = rt * att.rot * att.w_rad_s;
        let e_w = w - w_des_body;

        // Rotational law: b_ω (body frame).
        let p_w = inertia * w;
        let p_dot_des_w = -(inertia * w.cross(&w_des_body));
        let pd_w = (e_r * g.k_r + e_w * g.k_w).component_mul(&g.attitude_axis_scale);
        let mut b_w = w.cross(&p_w) - pd_w + p_dot_des_w - wa_w;
        if self.port_active {
            let b_up = Vector3::new(r.m31, r.m32, r.m33);
            // With the composite law, the port torque at the state for its prediction too.
            #[cfg(feature = "composite")]
            {
                let (t_law, t_pred) = self.model.port().torque_pair(
                    &b_up,
                    (&v_ref, &w_des_body),
                    (&state.v_body_m_s, w),
                );
                port_pred.torque_nm = t_pred;
                b_w -= t_law;
            }
            #[cfg(not(feature = "composite"))]
            {
                b_w -= self.model.port().torque(&b_up, &v_ref, &w_des_body);
            }
        }
        Demand {
            b_act: Vector4::new(b_v.z, b_w.x, b_w.y, b_w.z),
            errors: TrackingError { e_p, e_v, e_r, e_w },
            tilt_limited: att.tilt_limited,
            #[cfg(feature = "composite")]
            port_pred,
        }
    }

    /// u = g† b on the actuated rows (body z force, torques), the motor-lag lead, the mixer,
    /// and the delivered wrench's motor model ([`Actuation::singular`] if g's actuated block
    /// is singular).
    #[inline(never)]
    fn actuate(&mut self, b_act: &Vector4<f32>, dt_s: f32) -> Actuation {
        let g = &self.gains;
        let g_act = self.terms.gain.fixed_rows::<4>(2).into_owned();
        let b_act = *b_act;
        let u = match solve_in_order(&g_act, &b_act) {
            Some(u) => u,
            None => match g_act.try_inverse() {
                Some(inv) => inv * b_act,
                None => {
                    match (g_act.transpose() * g_act + Matrix4::identity() * 1e-9).try_inverse() {
                        Some(inv) => inv * g_act.transpose() * b_act,
                        None => {
                            return Actuation {
                                singular: true,
                                ..Actuation::default()
                            }
                        }
                    }
                }
            },
        };
        // The input's learned effective gain k (PortTerms::input_gain): u = k⁻¹ ∘ g† b.
        let u = if self.port_active {
            let k = self.model.port().input_gain();
            if !k.iter().all(|&x| x >= crate::model::port::MIN_INPUT_GAIN) {
                return Actuation {
                    singular: true,
                    ..Actuation::default()
                };
            }
            u.component_div(&k)
        } else {
            u
        };
        let wrench = Wrench {
            thrust_n: u.x,
            torque_nm: Vector3::new(u.y, u.z, u.w),
        };
        // Motor-lag compensation: lead the command from the delivered wrench's model.
        let lead = g.lag.ratio();
        let commanded = match (lead, self.u_model) {
            // The torques only: the attitude loop is the one the lag limits, and a lead on the
            // collective thrust would spend a heavy vehicle's small thrust margin.
            (Some(ratio), Some(model)) => {
                let c = model + (u - model) * ratio;
                Wrench {
                    thrust_n: u.x,
                    torque_nm: Vector3::new(c.y, c.z, c.w),
                }
            }
            _ => wrench,
        };
        let (rotors, sat) = self.airframe.mix(&commanded);
        let delivered = self.airframe.wrench(&rotors.thrust_n);
        if lead.is_some() {
            let d = Vector4::new(
                delivered.thrust_n,
                delivered.torque_nm.x,
                delivered.torque_nm.y,
                delivered.torque_nm.z,
            );
            let beta = dt_s / (g.lag.motor_tau_s + dt_s);
            let next = match self.u_model {
                Some(m) => m + (d - m) * beta,
                None => d,
            };
            self.u_model = next.iter().all(|x| x.is_finite()).then_some(next);
        }
        Actuation {
            singular: false,
            u,
            wrench,
            commanded,
            rotors,
            sat,
            delivered,
        }
    }

    /// Adaptation (paper eq. geometric_adaptive_law, with the robust clipping of
    /// crate::adapt); the tracking term's drive is bounded while the mixer cannot deliver the
    /// wrench ([`AdaptationRates::saturated`]), so the estimate neither winds up on an
    /// unreachable demand nor stays frozen through a fault that keeps the mixer saturated. The composite law's
    /// prediction term compares with the wrench actually delivered, so it keeps running.
    #[inline(never)]
    fn adapt(
        &mut self,
        state: &State,
        meas: &Measurement,
        inertia: &Matrix3<f32>,
        demand: &Demand,
        act: &Actuation,
        dt_s: f32,
    ) {
        let t = &self.terms;
        let errors = &demand.errors;
        #[cfg(not(feature = "composite"))]
        let _ = (state, meas, inertia);
        let g = &self.gains;
        let sat = act.sat;
        // The features' normalization, once for both terms.
        let scale = Adaptation::feature_normalization(&t.features, t.mass_kg);
        #[cfg(feature = "composite")]
        if g.law == AdaptationLaw::Composite {
            let x = PredictionInput {
                features: &t.features,
                gain: &t.gain,
                mass_kg: t.mass_kg,
                gravity_m_s2: t.gravity_m_s2,
                inertia,
                rot: &state.rot,
                v_body_m_s: &state.v_body_m_s,
                w_body_rad_s: &state.w_body_rad_s,
                measurement: meas,
                feature_scale: scale,
                port: self.port_active.then_some(&demand.port_pred),
            };
            self.adaptation
                .predict_step(&g.composite, g.rates.a_max, &x, dt_s);
        }
        if !self.shaper.freezes_adaptation() {
            // Saturated: the drive bounded, not switched off (AdaptationRates::saturated).
            let rates = if sat.roll_pitch || sat.thrust {
                g.rates.saturated()
            } else {
                g.rates
            };
            #[cfg(feature = "composite")]
            let torque_share = if g.law == AdaptationLaw::Composite {
                g.composite.torque_rate_scale
            } else {
                1.0
            };
            #[cfg(not(feature = "composite"))]
            let torque_share = 1.0;
            self.adaptation
                .step(&rates, &t.features, errors, (scale, torque_share), dt_s);
        }
        #[cfg(feature = "composite")]
        self.adaptation.record_input(&act.delivered);
        #[cfg(not(feature = "composite"))]
        let _ = act.delivered;
    }
}

/// What [`FlightController::demand`] gives the rest of the step.
struct Demand {
    /// b on the actuated rows: [b_v,z (N); b_ω (N·m)].
    b_act: Vector4<f32>,
    errors: TrackingError,
    tilt_limited: bool,
    /// The port terms at the state for the composite prediction (when the port is active):
    /// computed beside the law's, handed to [`FlightController::adapt`] (not kept in the
    /// controller, whose size the Crazyflie app's C ABI fixes).
    #[cfg(feature = "composite")]
    port_pred: PortPrediction,
}

/// What [`FlightController::actuate`] gives the rest of the step.
#[derive(Default)]
struct Actuation {
    /// g's actuated block was singular: nothing else is set.
    singular: bool,
    /// u = g† b = [f (N); τ (N·m)].
    u: Vector4<f32>,
    /// u as a wrench, and with the motor-lag lead.
    wrench: Wrench,
    commanded: Wrench,
    rotors: RotorCommand,
    sat: Saturation,
    /// The wrench `rotors` deliver.
    delivered: Wrench,
}

impl<M> FlightController<M> {
    /// The body velocity the law uses: the state's, plus Rᵀ c with the velocity-consistency
    /// correction c ([`Gains::velocity_consistency_tau_s`]) updated from this tick's position.
    fn consistent_velocity(&mut self, state: &State, dt_s: f32) -> Vector3<f32> {
        let tau = self.gains.velocity_consistency_tau_s;
        if tau.is_nan() || tau <= 0.0 {
            self.prev_p_m = None;
            return state.v_body_m_s;
        }
        let v_world = state.rot * state.v_body_m_s;
        if let Some((prev_p, prev_v)) = self.prev_p_m {
            // The mean velocity over the tick against the mean of its ends: second order in dt.
            let diff = (state.p_m - prev_p) / dt_s - (v_world + prev_v) * 0.5;
            let alpha = dt_s / (tau + dt_s);
            let next = self.velocity_correction_m_s + (diff - self.velocity_correction_m_s) * alpha;
            if next.iter().all(|x| x.is_finite()) {
                self.velocity_correction_m_s = next;
            }
        } else {
            self.velocity_correction_m_s = Vector3::zeros();
        }
        self.prev_p_m = Some((state.p_m, v_world));
        state.v_body_m_s + state.rot.transpose() * self.velocity_correction_m_s
    }
}

/// x with G x = b by Gaussian elimination with the pivots in diagonal order (no row
/// exchanges), a third of the work of G⁻¹ and then G⁻¹ b. `None` unless every pivot keeps more
/// than half of its diagonal entry's magnitude (NaN included): g's actuated block is near
/// diagonal (identity for the true g), and where it is not the caller inverts G instead.
#[inline(always)]
fn solve_in_order(g: &Matrix4<f32>, b: &Vector4<f32>) -> Option<Vector4<f32>> {
    let keeps = |pivot: f32, diag: f32| pivot.abs() > 0.5 * diag.abs();
    let p1 = g.m11;
    if !keeps(p1, p1) {
        return None;
    }
    let (l2, l3, l4) = (g.m21 / p1, g.m31 / p1, g.m41 / p1);
    let (a22, a23, a24) = (g.m22 - l2 * g.m12, g.m23 - l2 * g.m13, g.m24 - l2 * g.m14);
    let (a32, a33, a34) = (g.m32 - l3 * g.m12, g.m33 - l3 * g.m13, g.m34 - l3 * g.m14);
    let (a42, a43, a44) = (g.m42 - l4 * g.m12, g.m43 - l4 * g.m13, g.m44 - l4 * g.m14);
    let (b2, b3, b4) = (b.y - l2 * b.x, b.z - l3 * b.x, b.w - l4 * b.x);
    if !keeps(a22, g.m22) {
        return None;
    }
    let (l3, l4) = (a32 / a22, a42 / a22);
    let (a33, a34, b3) = (a33 - l3 * a23, a34 - l3 * a24, b3 - l3 * b2);
    let (a43, a44, b4) = (a43 - l4 * a23, a44 - l4 * a24, b4 - l4 * b2);
    if !keeps(a33, g.m33) {
        return None;
    }
    let l4 = a43 / a33;
    let (a44, b4) = (a44 - l4 * a34, b4 - l4 * b3);
    if !keeps(a44, g.m44) {
        return None;
    }
    let x4 = b4 / a44;
    let x3 = (b3 - a34 * x4) / a33;
    let x2 = (b2 - a23 * x3 - a24 * x4) / a22;
    let x1 = (b.x - g.m12 * x2 - g.m13 * x3 - g.m14 * x4) / p1;
    Some(Vector4::new(x1, x2, x3, x4))
}

fn errors_finite(e: &TrackingError) -> bool {
    crate::fpu::all_finite(
        [e.e_p, e.e_v, e.e_r, e.e_w]
            .iter()
            .flat_map(|v| v.iter().copied()),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The in-order elimination solves a near-diagonal G as the inverse does, and hands a G
    /// whose pivots collapse (a permutation, a singular or non-finite G) back to the inverse.
    #[test]
    fn solve_in_order_matches_the_inverse_or_declines() {
        let g = Matrix4::new(
            1.02, 0.03, -0.01, 0.02, //
            -0.04, 0.97, 0.05, 0.01, //
            0.02, -0.03, 1.1, -0.06, //
            0.01, 0.02, 0.04, 0.9,
        );
        let b = Vector4::new(0.26, 1e-3, -2e-3, 4e-4);
        let x = solve_in_order(&g, &b).expect("near diagonal");
        let want = g.try_inverse().expect("invertible") * b;
        assert!((x - want).norm() <= 1e-6 * want.norm(), "{x} vs {want}");
        let perm = Matrix4::new(
            0.0, 1.0, 0.0, 0.0, //
            1.0, 0.0, 0.0, 0.0, //
            0.0, 0.0, 1.0, 0.0, //
            0.0, 0.0, 0.0, 1.0,
        );
        assert_eq!(solve_in_order(&perm, &b), None);
        assert_eq!(solve_in_order(&Matrix4::zeros(), &b), None);
        let mut nan = g;
        nan.m33 = f32::NAN;
        assert_eq!(solve_in_order(&nan, &b), None);
    }
}
