//! The study's markdown table.

use super::*;

fn cm(f: &Flown) -> String {
    match (f.crashed, f.rmse_m) {
        (true, _) => format!("crash {:.1} s", f.crash_time_s.unwrap_or(f64::NAN)),
        (false, Some(r)) => format!("{:.3}", r * 100.0),
        (false, None) => "–".into(),
    }
}

/// The markdown table: position RMSE (cm, t ≥ 5 s) per controller and scenario (learned ones
/// per seed), then the held-out N-step errors and the learned J per seed.
pub fn table(r: &StudyReport) -> String {
    let mut s = String::from("| controller |");
    for sc in &r.scenarios {
        s += &format!(" {sc} (cm) |");
    }
    s += "\n| --- |";
    s += &" --- |".repeat(r.scenarios.len());
    s += "\n";
    for (key, desc) in STUDY_CONTROLLERS {
        let cell = |sc: &str| {
            r.results(key, sc)
                .into_iter()
                .map(cm)
                .collect::<Vec<_>>()
                .join(" / ")
        };
        let Some(first) = r.scenarios.first() else {
            break;
        };
        let seeds: Vec<String> = r
            .results(key, first)
            .iter()
            .filter_map(|f| f.seed)
            .map(|k| k.to_string())
            .collect();
        if seeds.is_empty() && key.ends_with("-no-lag") {
            continue;
        }
        let label = if seeds.is_empty() {
            desc.to_string()
        } else {
            format!("{desc}, seed {}", seeds.join(" / "))
        };
        s += &format!("| {label} |");
        for sc in &r.scenarios {
            s += &format!(" {} |", cell(sc));
        }
        s += "\n";
    }
    s += "\n| seed | command | windows (train / held out) | held-out last-step error, rate (rad/s): learned / nominal stock / nominal true | velocity (m/s): learned / nominal stock / nominal true | learned diag J (1e-5 kg·m²) | learned thrust gain |\n| --- | --- | --- | --- | --- | --- | --- |\n";
    for sd in &r.seeds {
        let t = sd.heldout_nominal_true.unwrap_or([f64::NAN; 4]);
        s += &format!(
            "| {} | {} | {} / {} | {:.3} / {:.3} / {:.3} | {:.2e} / {:.2e} / {:.2e} | {:.2}, {:.2}, {:.2} | {:.3} |\n",
            sd.seed,
            if sd.motor_lag_filter {
                "realized (τ)"
            } else {
                "commanded"
            },
            sd.train_windows,
            sd.heldout_windows,
            sd.heldout_learned[3],
            sd.heldout_nominal_stock[3],
            t[3],
            sd.heldout_learned[2],
            sd.heldout_nominal_stock[2],
            t[2],
            sd.learned_inertia_diag_kg_m2[0] * 1e5,
            sd.learned_inertia_diag_kg_m2[1] * 1e5,
            sd.learned_inertia_diag_kg_m2[2] * 1e5,
            sd.learned_thrust_gain,
        );
    }
    let j = r.vehicle.inertia_kg_m2;
    s += &format!(
        "\nTrue vehicle: {} kg, diag J {:.2}, {:.2}, {:.2} e-5 kg·m², rotor efficiencies {:?}, motor τ {} s.\n",
        r.vehicle.mass_kg,
        j[0] * 1e5,
        j[1] * 1e5,
        j[2] * 1e5,
        r.vehicle.rotor_efficiency,
        r.motor_tau_s
    );
    s
}
