//! Files (layer 1): atomic writing, the flight log, the uSD-card deck log and the dataset.
//!
//! Front door: code outside `host-train/src` imports these from here, never from a submodule
//! (`tools/front-door.py` checks it): [`write_atomic`], [`write_json_atomic`]; [`FlightLog`];
//! the dataset's [`Dataset`], [`Flight`], [`Realization`], [`RealizationMeta`], [`Sample`],
//! [`VehicleDescription`], [`WindowSpec`], [`load_dataset`], [`load_dataset_manifest`],
//! [`save_dataset`], [`dataset_windows`], [`sample_segments`], [`realization_file`],
//! [`DATASET_FORMAT`], [`DATASET_FORMAT_V1`], [`DATASET_CSV_HEADER`] (`dataset::{load,
//! load_manifest, save, windows, segments, FORMAT, FORMAT_V1, CSV_HEADER}`); the uSD log's
//! [`parse_usd`] (`usdlog::parse`), [`ParseOptions`], [`UsdError`], [`UsdWriter`], [`Var`],
//! [`VarType`], [`EventType`], [`crc32`], [`FIXED_FREQUENCY_ID`], [`LEE_COMMAND_VARS`],
//! [`USD_STATE_VARS`], [`USD_ACC_VARS`].

pub mod dataset;
pub mod files;
pub mod flightlog;
pub mod usdlog;

// The layer's front door: what code outside host-train/src uses, by these names.
pub use dataset::{
    load as load_dataset, load_manifest as load_dataset_manifest, realization_file,
    save as save_dataset, segments as sample_segments, windows as dataset_windows, Dataset, Flight,
    Realization, RealizationMeta, Sample, VehicleDescription, WindowSpec,
};
pub use dataset::{
    CSV_HEADER as DATASET_CSV_HEADER, FORMAT as DATASET_FORMAT, FORMAT_V1 as DATASET_FORMAT_V1,
};
pub use files::{write_atomic, write_json_atomic};
pub use flightlog::FlightLog;
pub use usdlog::{
    crc32, parse as parse_usd, EventType, ParseOptions, UsdError, UsdWriter, Var, VarType,
    FIXED_FREQUENCY_ID, LEE_COMMAND_VARS, USD_ACC_VARS, USD_STATE_VARS,
};
