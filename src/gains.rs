//! The controller's gains and what they are derived from: [`Gains`] (feedback gains,
//! adaptation rates, the composite law's observer, the lag compensation), [`VehicleFacts`]
//! (mass, inertia, motor lag: what a blob tells about its vehicle) and the tuning constants
//! [`Gains::for_vehicle`] uses. The design notes behind each value: docs/crazyflie-chain.md
//! ("How the gains are designed for the chain", "Stability margins") and docs/adaptation.md.

use crate::adapt::{AdaptationLaw, AdaptationRates, CompositeGains};
use crate::model::State;
use crate::model::{HamiltonianModel, DEFAULT_MOTOR_TAU_S, MASS_KG};
use nalgebra::Vector3;

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
///   hold; [`Gains::for_mass_kg`]'s 0.015 / 0.002, tuned on a perfect state, oscillate behind
///   the Crazyflie's gyro filter and a 50–70 ms motor lag (docs/crazyflie-chain.md).
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
    /// Whether the motor-lag watch may redesign the attitude loop in flight for the lag the
    /// flight shows ([`crate::control::LagWatch`], [`Gains::with_motor_lag`]). The design of
    /// [`Gains::for_vehicle`] rests on the blob's stated lag; it sets this to [`LAG_WATCH`].
    pub lag_watch: bool,
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

    /// The compensation [`Gains::for_vehicle`] designs for a motor lag `motor_tau_s` (s): down
    /// to [`LAG_TARGET_S`] when slower than it, off otherwise.
    pub fn for_motor_lag(motor_tau_s: f32) -> Self {
        if motor_tau_s > LAG_TARGET_S {
            Self {
                motor_tau_s,
                target_tau_s: LAG_TARGET_S,
            }
        } else {
            Self::OFF
        }
    }

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
/// about √(q h² / (r dt)), adds loop gain and lag at the attitude crossover. Q is set, with
/// [`COMPOSITE_TORQUE_RATE_SCALE`], [`COMPOSITE_GYRO_LAG_S`] and [`COMPOSITE_TORQUE_FILTER_S`],
/// so that the attitude loop keeps 45° of phase margin behind the Crazyflie's chain and a 70 ms
/// lag. The cost is a slower answer to a torque step, which the change detector
/// ([`COMPOSITE_FAULT_INNOVATION`]) buys back. The margin of each change and the cost:
/// docs/crazyflie-chain.md, "The composite law's torque observer, designed for the loop".
pub const COMPOSITE_Q_TORQUE: f32 = 0.5;

/// The share of the (already scaled) torque rates c_R, c_ω the composite law's tracking term
/// keeps under [`Gains::for_vehicle`]: none. The prediction term answers torque disturbances
/// faster per degree of phase margin than the tracking term does.
pub const COMPOSITE_TORQUE_RATE_SCALE: f32 = 0.0;

/// The lag (s) of the composite law's torque prediction behind the motors. The gyro's 2-pole
/// 80 Hz low-pass (2.8 ms), one sample of delay (1 ms), half a 500 Hz tick of hold (1 ms) and
/// the half tick of the rate difference (1 ms) make 5.8 ms. The attitude loop's margin keeps
/// growing past it (the prediction's excess lag feeds a share of the command's rate into ε, a
/// lead in the observer's loop), hence the longer lag; the margin per lag is in
/// docs/crazyflie-chain.md ("The composite law's torque observer, designed for the loop").
pub const COMPOSITE_GYRO_LAG_S: f32 = 0.011;

/// The composite law's low-pass on its torque rows under [`Gains::for_vehicle`] (s). Each ms
/// of it costs the attitude loop about 0.4° of margin, but without it a badly trained model
/// (2 epochs on 8 s of hover) saturates the mixer and crashes on hover-wind: the model's error
/// closes a loop through the unfiltered observer near the Nyquist rate (docs/crazyflie-chain.md,
/// "The composite law's torque observer, designed for the loop").
pub const COMPOSITE_TORQUE_FILTER_S: f32 = 0.005;

/// The composite law's change detector under [`Gains::for_vehicle`]
/// ([`CompositeGains::fault_innovation`], 1e-3 N·m RMS of the torque rows' prediction error,
/// low-passed over 20 ms). Set above what small signals make (the flight error of every
/// scenario without a fault but a setpoint step's first ticks, the margin measurement's
/// injection) and below what a rotor losing 40 % of its thrust makes within 30 ms
/// (docs/adaptation.md, "Rotor loss: saturation, frozen estimates and the change detector").
/// After it, [`CompositeGains::fault_q_torque`] for [`CompositeGains::fault_boost_s`].
pub const COMPOSITE_FAULT_INNOVATION: f32 = 0.35;

/// Whether the composite law's prediction doubts the motor lag ([`CompositeGains::lag_doubt`]):
/// a model's lag is a guess about the motors (the shipped blob's 50 ms flies plants from none to
/// 72 ms), and a lag longer than the motors' otherwise reads every fast command as a
/// disturbance.
pub const COMPOSITE_LAG_DOUBT: bool = true;

/// [`Gains::velocity_consistency_tau_s`] of [`Gains::for_vehicle`] (s): slow against the
/// position loop (4 rad/s), fast against a changing wind; the result is flat across that range
/// (docs/crazyflie-chain.md, "How the gains are designed for the chain").
pub const VELOCITY_CONSISTENCY_TAU_S: f32 = 0.3;

/// The share of the perfect-state torque adaptation rates (c_R = 20,000, c_ω = 2,000) that
/// [`Gains::for_vehicle`] keeps. The adaptation's torque channel closes a second loop around the
/// attitude crossover; at this share the gradient law leaves the attitude loop 45° of phase
/// margin with the Crazyflie's sensor chain and a 50–70 ms motor lag, at the cost of a slower
/// answer to a torque disturbance. Lowering c_ω alone buys more margin but less damping of the
/// adaptation loop. The margins and costs: docs/crazyflie-chain.md, "Stability margins".
pub const TORQUE_ADAPTATION_SCALE: f32 = 0.8;

/// [`AdaptationRates::saturated_drive_m`] of the tuned gains (m): while the mixer saturates the
/// translational drive is that of at most this position error.
pub const SATURATED_DRIVE_M: f32 = 0.02;

/// [`AdaptationRates::saturated_drive_rad`] of the tuned gains (rad).
pub const SATURATED_DRIVE_RAD: f32 = 0.05;

/// Whether [`Gains::for_vehicle`] turns the motor-lag watch on ([`Gains::lag_watch`]): on. It
/// removes 19 of the 26 failing rows of the robustness matrix (docs/envelope.md, "The lag
/// watch") for about 260 instructions a step (`firmware/report.sh`: 9,889 mean and 9,946 worst
/// of the 10,000 budget).
pub const LAG_WATCH: bool = true;

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
        g.lag = LagCompensation::for_motor_lag(tau_m);
        g.velocity_consistency_tau_s = VELOCITY_CONSISTENCY_TAU_S;
        let tau_e = design_lag_s(tau_m);
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
        g.composite.lag_doubt = COMPOSITE_LAG_DOUBT;
        g.lag_watch = LAG_WATCH;
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
            lag_watch: false,
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
            lag_watch: false,
        }
    }
}

/// The attitude design's effective lag for a motor lag τ_m ([`Gains::for_vehicle`]):
/// min(τ_m, [`LAG_TARGET_S`]) + [`SENSOR_DELAY_S`].
fn design_lag_s(tau_m: f32) -> f32 {
    let t = if tau_m > 0.0 { tau_m } else { 0.0 };
    (if t < LAG_TARGET_S { t } else { LAG_TARGET_S }) + SENSOR_DELAY_S
}

impl Gains {
    /// These gains redesigned from motor lag `from_s` to `to_s` (s), as [`Gains::for_vehicle`]
    /// designs them: k_ω ∝ 1 / τ_e and k_R ∝ 1 / τ_e², the lead to [`LAG_TARGET_S`] and the
    /// composite law's prediction on `to_s`.
    pub fn with_motor_lag(mut self, from_s: f32, to_s: f32) -> Self {
        let s = design_lag_s(from_s) / design_lag_s(to_s);
        if s.is_finite() && s > 0.0 {
            self.k_w *= s;
            self.k_r *= s * s;
        }
        self.lag = LagCompensation::for_motor_lag(to_s);
        self.composite.motor_tau_s = to_s;
        self
    }
}
