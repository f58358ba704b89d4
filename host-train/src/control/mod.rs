//! Controllers (layer 2): the host interface, the baselines, the core's adapter and the name registry.
//!
//! Front door: code outside `host-train/src` imports these from here, never from a submodule
//! (`tools/front-door.py` checks it): [`Controller`]; [`Geometric`]; [`CoreController`],
//! [`CoreStep`], [`load_learned`], [`gains_for`], [`gains_with`], [`airframe_of`] (the core's
//! controller); [`by_name`], [`baseline_by_name`], [`core_by_name`], [`controllers`],
//! [`names`], [`DEFAULT_WEIGHTS`] (the registry); [`ControllerSpec`], [`core_names`]; the
//! onboard Mellinger port's [`Mellinger`], [`MellingerGains`], [`MellingerOutput`],
//! [`OnboardConfig`], [`OnboardLaw`], [`LegacyControl`], [`legacy_power_distribution`].

pub mod adapter;
pub mod baselines;
pub mod controller;
pub mod onboard;
pub mod registry;
pub mod spec;

// The layer's front door: what code outside host-train/src uses, by these names.
pub use adapter::{airframe_of, gains_for, gains_with, load_learned, CoreController, CoreStep};
pub use baselines::Geometric;
pub use controller::Controller;
pub use onboard::{
    legacy_power_distribution, LegacyControl, Mellinger, MellingerGains, MellingerOutput,
    OnboardConfig, OnboardLaw,
};
pub use registry::{baseline_by_name, by_name, controllers, core_by_name, names, DEFAULT_WEIGHTS};
pub use spec::{core_names, ControllerSpec};
