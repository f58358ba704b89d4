//! # hamflight — the flight core
//!
//! A `no_std`, allocation-free, f32 implementation of "Physics-guided Learning-based Adaptive
//! Control on the SE(3) Manifold" (Duong & Atanasov) for Crazyflie-class quadrotors: fixed-size
//! inference of the learned port-Hamiltonian model, the energy-based (IDA-PBC) tracking controller
//! and the disturbance adaptation law (the paper's, and a composite law beside it).
//!
//! Data flows one way: state + setpoint → controller → wrench → mixer → motors.
//!
//! Modules:
//! - [`lie`]: SO(3) hat/vee, exp/log, rotation error;
//! - [`nn`]: const-generic dense layers and MLPs with their input Jacobians;
//! - [`model`]: the learned Hamiltonian model's networks;
//! - [`reference`](mod@reference): setpoints and the desired attitude from differential flatness;
//! - [`control`]: the IDA-PBC tracking law and the [`FlightController`];
//! - [`gains`]: the controller's [`Gains`], derived from the [`VehicleFacts`] a blob carries;
//! - [`adapt`]: the disturbance adaptation laws: the paper's gradient law and the composite
//!   (prediction-error) law, with the platform's extra [`Measurement`];
//! - [`mixer`]: wrench to rotor commands with saturation;
//! - [`fpu`]: fused multiply–add dense layers and square root on the M4F's FPU, bit-identical on the host;
//! - [`blob`]: the checked weight-blob codec.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![deny(missing_docs)]

pub mod adapt;
pub mod blob;
pub mod control;
pub mod fpu;
pub mod gains;
pub mod lie;
pub mod mixer;
pub mod model;
pub mod nn;
pub mod reference;
pub mod shaping;

pub use adapt::{AdaptationLaw, Measurement};
pub use control::{
    is_rotation, Faults, FlightController, Gains, Output, VehicleFacts, ROTATION_TOLERANCE,
};
pub use mixer::{RotorCommand, Wrench};
pub use model::State;
pub use reference::Setpoint;
