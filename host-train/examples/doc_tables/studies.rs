//! The blocks rendered from committed study scores (`docs/data/`): Bitcraze's controllers behind
//! their own estimator (`tools/bitcraze-loop`) and the vehicle study.

use super::root;

/// The committed study scores the Bitcraze and vehicle tables are rendered from: the studies need
/// a crazyflie-firmware checkout (CI has none) or minutes of training, so a person regenerates
/// the files (`tools/bitcraze-loop/doc-data.sh`, `tools/vehicle-study-doc-data.sh`) and CI checks
/// the pages against them.
const BITCRAZE_DATA: &str = "docs/data/bitcraze-loop.json";
const BITCRAZE_TRUTH_DATA: &str = "docs/data/bitcraze-loop-truth.json";
const VEHICLE_DATA: [&str; 3] = ["heavy", "light", "asym"];

fn read_json(rel: &str) -> anyhow::Result<serde_json::Value> {
    let path = root().join(rel);
    let text = std::fs::read_to_string(&path).map_err(|e| {
        anyhow::anyhow!(
            "{rel}: {e} (the committed study scores the docs' tables are rendered from)"
        )
    })?;
    Ok(serde_json::from_str(&text)?)
}

/// A string array of a JSON object.
fn strings(v: &serde_json::Value, key: &str) -> anyhow::Result<Vec<String>> {
    v[key]
        .as_array()
        .ok_or_else(|| anyhow::anyhow!("no `{key}` array"))?
        .iter()
        .map(|s| {
            s.as_str()
                .map(String::from)
                .ok_or_else(|| anyhow::anyhow!("`{key}` holds a non-string"))
        })
        .collect()
}

/// One flight of bitcraze-loop's `--scores` file.
#[derive(serde::Deserialize)]
struct BcFlight {
    scenario: String,
    controller: String,
    rmse_pos_window_m: Option<f64>,
    crash_time_s: Option<f64>,
    att_std_deg: Option<f64>,
    saturated_fraction: f64,
    est_pos_bias_m: Option<[f64; 3]>,
    pos_err_mean_m: Option<[f64; 3]>,
}

/// A bitcraze-loop `--scores` file: its commit, controllers, scenarios and flights.
struct BcStudy {
    commit: String,
    controllers: Vec<String>,
    scenarios: Vec<String>,
    flights: Vec<BcFlight>,
}

impl BcStudy {
    fn load(rel: &str) -> anyhow::Result<Self> {
        let v = read_json(rel)?;
        let parse = || -> anyhow::Result<Self> {
            Ok(Self {
                commit: v["crazyflie_firmware_commit"]
                    .as_str()
                    .ok_or_else(|| anyhow::anyhow!("no crazyflie_firmware_commit"))?
                    .to_string(),
                controllers: strings(&v, "controllers")?,
                scenarios: strings(&v, "scenarios")?,
                flights: serde_json::from_value(v["flights"].clone())?,
            })
        };
        parse().map_err(|e| anyhow::anyhow!("{rel}: {e}"))
    }

    fn get(&self, scenario: &str, controller: &str) -> anyhow::Result<&BcFlight> {
        self.flights
            .iter()
            .find(|f| f.scenario == scenario && f.controller == controller)
            .ok_or_else(|| anyhow::anyhow!("no flight of {controller} on {scenario}"))
    }
}

/// A flight's score for ranking (a crash ranks last).
fn bc_rank(f: &BcFlight) -> f64 {
    match (f.crash_time_s, f.rmse_pos_window_m) {
        (None, Some(e)) => e,
        _ => f64::INFINITY,
    }
}

/// A flight's RMSE cell (cm), or its crash.
fn bc_cell(f: &BcFlight) -> String {
    match (f.crash_time_s, f.rmse_pos_window_m) {
        (Some(t), _) => format!("crash at {t:.1} s"),
        (None, Some(e)) => format!("{:.2}", e * 100.0),
        (None, None) => "–".into(),
    }
}

fn bold(s: String, on: bool) -> String {
    if on {
        format!("**{s}**")
    } else {
        s
    }
}

/// Bitcraze's controllers as the pages name them.
fn bc_label(controller: &str) -> Option<&'static str> {
    match controller {
        "bc-pid" => Some("PID"),
        "bc-mellinger" => Some("Mellinger"),
        "bc-lee" => Some("Lee"),
        "bc-brescianini" => Some("Brescianini"),
        _ => None,
    }
}

/// The README's short names of the study's scenarios.
fn bc_scenario_label(scenario: &str) -> &str {
    match scenario {
        "cf-hover-lag50" => "hover",
        "cf-calm-spiral" => "calm spiral",
        "cf-paper-spiral" => "paper's wind",
        "cf-rotor-loss" => "rotor loss",
        "cf-hover-wind" => "steady wind",
        "gust-spiral" => "gusts",
        other => other,
    }
}

/// `bitcraze-summary` (README): the default controller against the best of Bitcraze's four.
pub fn bitcraze_summary_table() -> anyhow::Result<String> {
    let s = BcStudy::load(BITCRAZE_DATA)?;
    let ours = "adaptive";
    let mut out = String::from("| RMSE t ≥ 5 s (cm) |");
    for sc in &s.scenarios {
        out += &format!(" {} |", bc_scenario_label(sc));
    }
    out += "\n| --- |";
    out += &" --- |".repeat(s.scenarios.len());
    let (mut row_ours, mut row_bc) = (
        format!("\n| `{ours}` |"),
        String::from("\n| best of Bitcraze's four |"),
    );
    for sc in &s.scenarios {
        let a = s.get(sc, ours)?;
        let mut best: Option<&BcFlight> = None;
        for c in s.controllers.iter().filter(|c| bc_label(c).is_some()) {
            let f = s.get(sc, c)?;
            if best.is_none_or(|b| bc_rank(f) < bc_rank(b)) {
                best = Some(f);
            }
        }
        let b = best.ok_or_else(|| anyhow::anyhow!("{BITCRAZE_DATA}: no Bitcraze controller"))?;
        let label = bc_label(&b.controller).unwrap_or_default();
        row_ours += &format!(" {} |", bold(bc_cell(a), bc_rank(a) <= bc_rank(b)));
        row_bc += &format!(
            " {} |",
            bold(format!("{} ({label})", bc_cell(b)), bc_rank(b) < bc_rank(a))
        );
    }
    Ok(out + &row_ours + &row_bc + "\n")
}

/// The header of a per-controller table of the study.
fn bc_header(s: &BcStudy) -> String {
    let mut out = String::from("| scenario |");
    let mut first_bc = true;
    for c in &s.controllers {
        out += &match bc_label(c) {
            Some(l) if first_bc => {
                first_bc = false;
                format!(" Bitcraze {l} |")
            }
            Some(l) => format!(" {l} |"),
            None => format!(" `{c}` |"),
        };
    }
    out += "\n| --- |";
    out += &" --- |".repeat(s.controllers.len());
    out + "\n"
}

/// One RMSE table of the study, the best of each row in bold.
fn bc_rmse_rows(s: &BcStudy) -> anyhow::Result<String> {
    let mut out = bc_header(s);
    for sc in &s.scenarios {
        let row: Vec<&BcFlight> = s
            .controllers
            .iter()
            .map(|c| s.get(sc, c))
            .collect::<anyhow::Result<_>>()?;
        // The best as the table prints it: equal cells are all bold.
        let best = row
            .iter()
            .min_by(|a, b| bc_rank(a).total_cmp(&bc_rank(b)))
            .filter(|f| bc_rank(f).is_finite())
            .map(|f| bc_cell(f));
        out += &format!("| {sc} |");
        for f in row {
            let cell = bc_cell(f);
            let on = best.as_ref() == Some(&cell);
            out += &format!(" {} |", bold(cell, on));
        }
        out += "\n";
    }
    Ok(out)
}

/// `bitcraze-loop` (docs/crazyflie-chain.md): every controller on every scenario behind
/// Bitcraze's Kalman estimate, then attitude σ / capping, then the estimator's bias.
pub fn bitcraze_loop_table() -> anyhow::Result<String> {
    let s = BcStudy::load(BITCRAZE_DATA)?;
    let mut out = format!(
        "Measured on crazyflie-firmware `{}` with the shipped blob (`{BITCRAZE_DATA}`; RMSE over t ≥ 5 s, cm, the best of each row in bold):\n\n",
        s.commit
    );
    out += &bc_rmse_rows(&s)?;
    out += "\nLargest roll/pitch standard deviation over t ≥ 5 s (deg) / ticks capped (%):\n\n";
    out += &bc_header(&s);
    for sc in &s.scenarios {
        out += &format!("| {sc} |");
        for c in &s.controllers {
            let f = s.get(sc, c)?;
            let sd = f.att_std_deg.map_or("–".into(), |x| format!("{x:.2}"));
            out += &format!(" {sd} / {:.1} |", f.saturated_fraction * 100.0);
        }
        out += "\n";
    }
    out += "\nThe estimate's bias (Kalman − truth) and `adaptive`'s mean position error (truth − reference), x / y, mean over t ≥ 5 s (cm):\n\n| scenario | estimate's bias | `adaptive`'s mean error |\n| --- | --- | --- |\n";
    // Centimetres to 0.01, without a sign on a rounded zero.
    let cm2 = |x: f64| {
        let s = format!("{:.2}", x * 100.0);
        if s == "-0.00" {
            "0.00".into()
        } else {
            s
        }
    };
    let xy =
        |v: Option<[f64; 3]>| v.map_or("–".into(), |v| format!("{} / {}", cm2(v[0]), cm2(v[1])));
    for sc in &s.scenarios {
        let f = s.get(sc, "adaptive")?;
        out += &format!(
            "| {sc} | {} | {} |\n",
            xy(f.est_pos_bias_m),
            xy(f.pos_err_mean_m)
        );
    }
    Ok(out)
}

/// `bitcraze-loop-truth` (docs/crazyflie-chain.md): the same on the true state.
pub fn bitcraze_truth_table() -> anyhow::Result<String> {
    let s = BcStudy::load(BITCRAZE_TRUTH_DATA)?;
    bc_rmse_rows(&s)
}

/// One flight of `host-train vehicle-study --scores`.
#[derive(serde::Deserialize)]
struct VsFlight {
    controller: String,
    seed: Option<u64>,
    scenario: String,
    rmse_m: Option<f64>,
    crashed: bool,
    crash_time_s: Option<f64>,
}

/// A `vehicle-study --scores` file.
#[derive(serde::Deserialize)]
struct VsStudy {
    vehicle: String,
    mass_kg: f64,
    rotor_efficiency: [f64; 4],
    motor_tau_s: f64,
    scenarios: Vec<String>,
    flights: Vec<VsFlight>,
}

impl VsStudy {
    fn load(vehicle: &str) -> anyhow::Result<Self> {
        let rel = format!("docs/data/vehicle-study-{vehicle}.json");
        serde_json::from_value(read_json(&rel)?).map_err(|e| anyhow::anyhow!("{rel}: {e}"))
    }

    /// The flights of `controller` on the `i`-th scenario, in seed order.
    fn cells(&self, controller: &str, i: usize) -> Vec<&VsFlight> {
        self.flights
            .iter()
            .filter(|f| f.controller == controller && f.scenario == self.scenarios[i])
            .collect()
    }

    /// "heavy (0.034 kg, weak rotor, 20 ms)".
    fn label(&self) -> String {
        let weak = self.rotor_efficiency.iter().filter(|e| **e < 1.0).count();
        let weak = match weak {
            0 => String::new(),
            1 => ", weak rotor".into(),
            2 => ", two weak rotors".into(),
            n => format!(", {n} weak rotors"),
        };
        format!(
            "{} ({:.3} kg{weak}, {:.0} ms)",
            self.vehicle,
            self.mass_kg,
            self.motor_tau_s * 1000.0
        )
    }
}

fn vs_cell(f: &VsFlight) -> String {
    match (f.crashed, f.rmse_m) {
        (true, _) => format!("crash {:.1} s", f.crash_time_s.unwrap_or(f64::NAN)),
        (false, Some(r)) => format!("{:.3}", r * 100.0),
        (false, None) => "–".into(),
    }
}

/// The worst of the seeds (a crash is worst).
fn vs_worst(fs: &[&VsFlight]) -> String {
    fs.iter()
        .max_by(|a, b| {
            let r = |f: &VsFlight| {
                if f.crashed {
                    f64::INFINITY
                } else {
                    f.rmse_m.unwrap_or(f64::NAN)
                }
            };
            r(a).total_cmp(&r(b))
        })
        .map_or("–".into(), |f| vs_cell(f))
}

fn vs_studies() -> anyhow::Result<Vec<VsStudy>> {
    VEHICLE_DATA.iter().map(|v| VsStudy::load(v)).collect()
}

fn vs_crashes(studies: &[VsStudy]) -> usize {
    studies
        .iter()
        .flat_map(|s| &s.flights)
        .filter(|f| f.crashed)
        .count()
}

/// `vehicles-summary` (README): per vehicle and law, the nominal model with stock constants and
/// the learned blobs' worst seed.
pub fn vehicles_summary_table() -> anyhow::Result<String> {
    let studies = vs_studies()?;
    let mut out = format!(
        "RMSE t ≥ 5 s in cm, learned blobs' worst seed; {} crashed:\n\n| vehicle | law | nominal, stock constants: calm / windy / rotor loss | learned: calm / windy / rotor loss |\n| --- | --- | --- | --- |\n",
        match vs_crashes(&studies) {
            0 => "nothing".to_string(),
            n => format!("{n} flights"),
        }
    );
    for s in &studies {
        for (k, law) in ["gradient", "composite"].into_iter().enumerate() {
            let name = if k == 0 { s.label() } else { s.vehicle.clone() };
            let n = s.scenarios.len();
            let nominal: Vec<String> = (0..n)
                .map(|i| vs_worst(&s.cells(&format!("geometric-adaptive-{law}"), i)))
                .collect();
            let learned: Vec<String> = (0..n)
                .map(|i| vs_worst(&s.cells(&format!("adaptive-{law}"), i)))
                .collect();
            out += &format!(
                "| {name} | {law} | {} | {} |\n",
                nominal.join(" / "),
                learned.join(" / ")
            );
        }
    }
    Ok(out)
}

/// `vehicles` (docs/vehicles.md): every vehicle's bar flights, seeds 0 / 1 / 2, then learned
/// over nominal under the composite law.
pub fn vehicles_table() -> anyhow::Result<String> {
    let studies = vs_studies()?;
    let rows = [
        (
            "geometric-adaptive-gradient",
            "geometric-adaptive (nominal, stock constants), gradient",
        ),
        (
            "geometric-adaptive-composite",
            "geometric-adaptive (nominal, stock constants), composite",
        ),
        ("adaptive-gradient", "adaptive (learned), gradient"),
        (
            host_train::pipeline::TRUE_COMPOSITE,
            "nominal, TRUE mass, inertia and motor lag (the floor), composite",
        ),
        ("adaptive-composite", "adaptive (learned), composite"),
    ];
    let mut out = format!(
        "RMSE over t ≥ 5 s (cm, `--scores` of each study: `docs/data/vehicle-study-NAME.json`), learned blobs seeds {}; {} crashed:\n\n| vehicle | controller | calm spiral | windy spiral | rotor loss |\n| --- | --- | --- | --- | --- |\n",
        studies
            .first()
            .map(|s| {
                s.cells("adaptive-composite", 0)
                    .iter()
                    .filter_map(|f| f.seed)
                    .map(|k| k.to_string())
                    .collect::<Vec<_>>()
                    .join(" / ")
            })
            .unwrap_or_default(),
        match vs_crashes(&studies) {
            0 => "nothing".to_string(),
            n => format!("{n} flights"),
        }
    );
    for s in &studies {
        for (key, label) in rows {
            out += &format!("| {} | {label} |", s.vehicle);
            for i in 0..s.scenarios.len() {
                let cells: Vec<String> = s.cells(key, i).into_iter().map(vs_cell).collect();
                out += &format!(" {} |", cells.join(" / "));
            }
            out += "\n";
        }
    }
    out += "\nLearned + composite over nominal + composite, seeds in the same order:\n\n| vehicle | calm spiral | windy spiral | rotor loss |\n| --- | --- | --- | --- |\n";
    for s in &studies {
        out += &format!("| {} |", s.vehicle);
        for i in 0..s.scenarios.len() {
            let nominal = s
                .cells("geometric-adaptive-composite", i)
                .first()
                .and_then(|f| f.rmse_m);
            let ratios: Vec<String> = s
                .cells("adaptive-composite", i)
                .iter()
                .map(|f| match (f.rmse_m, nominal) {
                    (Some(l), Some(n)) if !f.crashed => format!("{:.3}", l / n),
                    _ => "–".into(),
                })
                .collect();
            out += &format!(" {} |", ratios.join(" / "));
        }
        out += "\n";
    }
    Ok(out)
}
