//! The bridge's request parser on arbitrary lines, and the core controller on whatever it
//! accepts: parsing never panics; an accepted request converts to the core's types and one
//! controller step on it never panics, gives finite rotor commands, and motors off on a fault.
#![no_main]

use hamflight::model::NominalModel;
use hamflight::{FlightController, Gains};
use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../../host-train/src/bridge/wire.rs"]
mod wire;

fuzz_target!(|data: &[u8]| {
    let Ok(line) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(req) = wire::parse_request(line) else {
        return;
    };
    let (state, sp) = req.to_core();
    let mut c = FlightController::new(NominalModel::default(), Gains::default());
    for dt_s in [0.002, req.t as f32] {
        let out = c.step(&state, &sp, dt_s);
        assert!(
            out.rotors.rpm.iter().all(|r| r.is_finite() && *r >= 0.0),
            "{out:?}"
        );
        if out.faults.is_fault() {
            assert!(out.rotors.rpm.iter().all(|r| *r == 0.0), "{out:?}");
        }
        assert!(out.a.iter().all(|a| a.is_finite()));
    }
});
