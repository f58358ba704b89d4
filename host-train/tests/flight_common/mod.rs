//! What the closed-loop test files share: repository paths, scenarios by name, and one flight
//! of a named controller on the shipped blob that must not crash.

use host_train::control::{by_name, DEFAULT_WEIGHTS};
use host_train::fly::{fly_scenario, Report};
use host_train::sim::Scenario;
use std::path::{Path, PathBuf};

/// A path in the repository.
pub fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path)
}

/// `scenarios/NAME.toml`.
pub fn scenario(name: &str) -> Scenario {
    Scenario::load(repo(&format!("scenarios/{name}.toml"))).expect("scenario loads")
}

/// Flies `name` (the shipped blob for the learned controllers) on `sc`; fails on a crash.
pub fn fly(name: &str, sc: &Scenario) -> Report {
    let weights = repo(DEFAULT_WEIGHTS);
    let mut ctrl = by_name(name, sc, Some(&weights)).expect("controller exists");
    let log = fly_scenario(sc, ctrl.as_mut());
    let r = Report::from_flight(&log, sc, None);
    assert!(!r.crashed, "{name} crashed on {}: {r:?}", sc.name);
    r
}
