//! The baseline controllers: the DSL PID and the geometric (Lee) controller on the true constants.

pub mod geometric;
pub mod pid;

pub use geometric::{Geometric, GeometricGains};
pub use pid::{DslPid, DslPidGains};
