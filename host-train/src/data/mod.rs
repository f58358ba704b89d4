//! Training data (layer 3): SITL collection and the import of flight logs.

pub mod collect;
pub mod import;
