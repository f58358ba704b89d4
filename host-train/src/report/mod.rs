//! Reports (layer 2): the SVG figures.

pub mod plot;
