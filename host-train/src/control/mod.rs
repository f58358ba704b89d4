//! Controllers (layer 2): the host interface, the baselines, the core's adapter and the name registry.

pub mod adapter;
pub mod baselines;
pub mod controller;
pub mod registry;
pub mod spec;
