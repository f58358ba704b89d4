//! Commands that combine the layers (layer 4): training with its flight check, the training benchmark, the demo and the vehicle study.

pub mod bench;
pub mod check;
pub mod demo;
pub mod fit_port;
pub mod fit_response;
pub mod prior_check;
pub mod score;
pub mod train;
pub mod vehicle_study;
