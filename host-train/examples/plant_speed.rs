//! The SITL plant's speed at 1 kHz physics, in simulated seconds per wall second: a measurement,
//! not a test (speed is measured, never asserted).
//!
//! `cargo run --release -p host-train --example plant_speed`

use host_train::{Plant, PlantState};
use nalgebra::Vector3;

fn main() {
    const DT: f64 = 1e-3;
    let mut plant = Plant::nominal(PlantState::at_rest(Vector3::new(0.0, 0.0, 1.0), 0.0));
    let h = plant.params.hover_rpm();
    let n = 1_000_000;
    let t0 = std::time::Instant::now();
    for k in 0..n {
        let d = if k % 2 == 0 { 10.0 } else { -10.0 };
        plant.step([h + d, h - d, h + d, h - d], DT);
    }
    let wall = t0.elapsed().as_secs_f64();
    println!(
        "plant: {n} steps of 1 ms in {wall:.3} s = {:.0} simulated s per wall s ({:.0} ns/step); \
         final state finite: {}",
        n as f64 * DT / wall,
        wall / n as f64 * 1e9,
        plant.state().is_finite()
    );
}
