//! The first program: load a weight blob, build the flight controller for the vehicle the blob
//! describes, and step it on a state, as the firmware's loop does at 500 Hz.
//!
//!     cargo run --example first_flight [-- FILE.hfw]
//!
//! Everything here is what the no_std core offers: only the file reading and the printing use
//! std. On the MCU the blob comes from flash and `blob::decode_model_into` fills a static model
//! in place (`firmware/src/main.rs`).

use hamflight::model::LearnedModel;
use hamflight::{FlightController, Gains, Setpoint, State, VehicleFacts};
use nalgebra::Vector3;

/// The shipped blob, built into the program.
static DEFAULT_BLOB: &[u8] = include_bytes!("../weights/default.hfw");

fn main() {
    let file = std::env::args().nth(1);
    let bytes = match &file {
        Some(path) => std::fs::read(path).unwrap_or_else(|e| fail(&format!("{path}: {e}"))),
        None => DEFAULT_BLOB.to_vec(),
    };
    // The blob's networks (M, g, W), mass, motor lag and port terms; a bad blob is refused
    // with the reason (version, length, checksum, a value out of range).
    let model = LearnedModel::from_blob(&bytes).unwrap_or_else(|e| fail(&format!("{e}")));
    // Gains designed for the vehicle the blob describes (its mass, inertia and motor lag).
    let facts = VehicleFacts::of(&model);
    let mut controller = FlightController::new(model, Gains::for_vehicle(&facts));

    // 10 cm below a hover setpoint at 1 m, level and at rest.
    let state = State {
        p_m: Vector3::new(0.0, 0.0, 0.9),
        ..State::default()
    };
    let setpoint = Setpoint::hover(Vector3::new(0.0, 0.0, 1.0), 0.0);
    println!(
        "vehicle: {:.4} kg, J diag {:.3e} {:.3e} {:.3e} kg m², motor lag {:.0} ms",
        facts.mass_kg,
        facts.inertia_kg_m2.x,
        facts.inertia_kg_m2.y,
        facts.inertia_kg_m2.z,
        facts.motor_tau_s * 1e3
    );
    for tick in 0..5 {
        let out = controller.step(&state, &setpoint, 0.002);
        if out.faults.is_fault() {
            fail(&format!(
                "tick {tick}: the controller refused: {:?}",
                out.faults
            ));
        }
        println!(
            "tick {tick}: thrust {:.4} N, torques {:+.2e} {:+.2e} {:+.2e} N m, rotor thrusts {:.4?} N",
            out.wrench.thrust_n,
            out.wrench.torque_nm.x,
            out.wrench.torque_nm.y,
            out.wrench.torque_nm.z,
            out.rotors.thrust_n
        );
    }
}

fn fail(why: &str) -> ! {
    eprintln!("first_flight: {why}");
    std::process::exit(1)
}
