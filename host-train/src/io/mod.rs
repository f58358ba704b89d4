//! Files (layer 1): atomic writing, the flight log, the uSD-card deck log and the dataset.

pub mod dataset;
pub mod files;
pub mod flightlog;
pub mod usdlog;
