//! Training data (layer 3): SITL collection and the import of flight logs.
//!
//! Front door: code outside `host-train/src` imports these from here, never from a submodule
//! (`tools/front-door.py` checks it): [`run_collect`] (`host-train collect`), [`collect_dataset`]
//! (`collect::collect`), [`CollectArgs`] (as a typed job, [`CollectJob`]), [`CollectConfig`];
//! [`run_import`] (`host-train import`), [`ImportArgs`] ([`ImportJob`]), [`FileSummary`],
//! [`decode_csv`], [`decode_usd`], [`airborne_flights`], [`fix_rotor_glitches`],
//! [`realize_commands`].

pub mod collect;
pub mod import;

// The layer's front door: what code outside host-train/src uses, by these names.
pub use collect::{
    collect as collect_dataset, run as run_collect, CollectArgs, CollectConfig, CollectJob,
};
pub use import::{
    airborne_flights, decode_csv, decode_usd, fix_rotor_glitches, realize_commands,
    run as run_import, FileSummary, ImportArgs, ImportJob,
};
