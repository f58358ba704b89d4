//! The simulation (layer 1): the plant, scenarios, the reference, the sensor chain and its EKF.

pub mod ekf;
pub mod plant;
pub mod scenario;
pub mod sensors;
pub mod trajectory;
pub mod vehicle;
