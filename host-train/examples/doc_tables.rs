//! The docs' generated tables: every table between a pair of markers
//!
//! ```text
//! <!-- generated: NAME -->
//! ...
//! <!-- end generated: NAME -->
//! ```
//!
//! in README.md and docs/*.md is written by this program from SITL flights of the shipped blob,
//! so no page's number is typed by hand.
//!
//! - `cargo run --release -p host-train --example doc_tables -- --write` rewrites the blocks;
//! - `-- --check` (CI) flies the same flights and fails, naming the page, the block and the first
//!   line that differs, when a page's block is not what the code gives today (a number edited by
//!   hand, or a change to the law that moved a figure without regenerating the page).
//!
//! Every NAME on a page must be one this program knows, and every block it knows must be on a
//! page: a missing or unknown block is an error too.
//!
//! The `firmware-budget` block is the firmware's cost on the STM32F405, from
//! `firmware/report.sh` under QEMU (instruction counts are exact with `-icount shift=0`); it needs
//! `qemu-system-arm` and the thumbv7em target. Without QEMU the block is left as the page has it,
//! with a warning, except under CI (`CI=true`), where that is an error.
//!
//! The Bitcraze blocks (`bitcraze-summary`, `bitcraze-loop`, `bitcraze-loop-truth`) and the
//! vehicle blocks (`vehicles-summary`, `vehicles`) are rendered from committed study scores in
//! `docs/data/`, not flown here: `tools/bitcraze-loop` needs a crazyflie-firmware checkout (CI has
//! none) and `host-train vehicle-study` trains nine blobs (minutes, and training's last digits may
//! depend on the host's CPU). `--check` verifies the pages against those files; whoever reruns a
//! study regenerates its file and the pages with one command: `CRAZYFLIE_BASE=/path/to/checkout
//! tools/bitcraze-loop/doc-data.sh`, or `tools/vehicle-study-doc-data.sh`.

use hamflight::{Gains, VehicleFacts};
use host_train::control::{by_name, load_learned, Controller, CoreController, DEFAULT_WEIGHTS};
use host_train::fly::{fly_scenario, Report};
use host_train::sim::Scenario;
use host_train::ControllerSpec;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The pages that may hold generated blocks.
const PAGES: [&str; 5] = [
    "README.md",
    "docs/adaptation.md",
    "docs/crazyflie-chain.md",
    "docs/firmware.md",
    "docs/vehicles.md",
];

/// The firmware builds of the budget table: label, `FEATURES`, `NO_DEFAULT`.
const BUDGET_BUILDS: [(&str, &str, bool); 3] = [
    ("composite law, 500 Hz (the default image)", "", false),
    (
        "composite law, 1 kHz (`FEATURES=loop-1khz`)",
        "loop-1khz",
        false,
    ),
    ("the paper's gradient law (`NO_DEFAULT=1`)", "", true),
];

/// The scenarios of the per-law table: each exercises the estimator.
const LAW_SCENARIOS: [&str; 6] = [
    "paper-spiral",
    "paper-spiral-realistic",
    "step",
    "gust-spiral",
    "rotor-loss-mid",
    "hover-wind-step",
];
const LAW_CONTROLLERS: [&str; 4] = [
    "adaptive-gradient",
    "adaptive-composite",
    "geometric-adaptive-gradient",
    "geometric-adaptive-composite",
];

fn cm(x: Option<f64>) -> String {
    x.map_or("—".into(), |x| format!("{:.3}", 100.0 * x))
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// One flight of `controller` (the shipped blob for the learned ones) on `scenario`.
fn flight(sc: &Scenario, controller: &str) -> anyhow::Result<Report> {
    let weights = root().join(DEFAULT_WEIGHTS);
    let mut ctrl = by_name(controller, sc, Some(&weights))?;
    let log = fly_scenario(sc, ctrl.as_mut());
    Ok(Report::from_flight(&log, sc, None))
}

fn scenario(name: &str) -> anyhow::Result<Scenario> {
    Scenario::load(root().join(format!("scenarios/{name}.toml")))
}

/// `laws`: both laws on both adaptive controllers, on the scenarios that exercise the estimator.
fn laws_table() -> anyhow::Result<String> {
    let mut out = String::from(
        "| scenario | controller | RMSE t ≥ 5 s (cm) | max (cm) | events: peak (cm) / recovery (s) / RMSE 5 s after (cm) |\n| --- | --- | --- | --- | --- |\n",
    );
    for s in LAW_SCENARIOS {
        let sc = scenario(s)?;
        for c in LAW_CONTROLLERS {
            let r = flight(&sc, c)?;
            let ev: Vec<String> = r
                .events
                .iter()
                .map(|e| {
                    format!(
                        "t = {} s: {} / {} / {}",
                        e.t_s,
                        cm(Some(e.peak_err_m)),
                        e.recovery_s.map_or("never".into(), |x| format!("{x:.2}")),
                        cm(e.rmse_after_m)
                    )
                })
                .collect();
            let crashed = if r.crashed { " (crashed)" } else { "" };
            let events = if ev.is_empty() {
                "—".into()
            } else {
                ev.join("; ")
            };
            out += &format!(
                "| {s} | {c}{crashed} | {} | {} | {events} |\n",
                cm(r.rmse_pos_window_m),
                cm(Some(r.max_err_m)),
            );
        }
    }
    Ok(out)
}

/// `rotor-loss-set`: RMSE over t ≥ 5 s, the peak after the fault and the recovery time, per
/// rotor share, lag, law and state source.
fn rotor_loss_table() -> anyhow::Result<String> {
    let mut out = String::from(
        "| rotor, lag | law | true state: RMSE (cm) / peak (cm) / recovery (s) | sensor chain: RMSE (cm) / peak (cm) / recovery (s) |\n| --- | --- | --- | --- |\n",
    );
    let cell = |r: &Report| {
        let e = r.events.first();
        let rec = e
            .and_then(|e| e.recovery_s)
            .map_or("never < 1 cm".into(), |x| format!("{x:.2}"));
        let crashed = r
            .crash_time_s
            .map_or(String::new(), |t| format!(" (crash at {t:.2} s)"));
        format!(
            "{} / {} / {rec}{crashed}",
            cm(r.rmse_pos_window_m),
            cm(e.map(|e| e.peak_err_m))
        )
    };
    for share in [55, 50] {
        for lag in [20, 50, 72] {
            for law in ["gradient", "composite"] {
                let name = format!("rotor-loss-{share}-lag{lag}");
                let c = format!("adaptive-{law}");
                let t = flight(&scenario(&name)?, &c)?;
                let ch = flight(&scenario(&format!("cf-{name}"))?, &c)?;
                out += &format!(
                    "| 1 to {share} %, {lag} ms | {law} | {} | {} |\n",
                    cell(&t),
                    cell(&ch)
                );
            }
        }
    }
    Ok(out)
}

/// `default-vs-paper`: the default law (composite) against the paper's gradient law on every
/// scenario flown with the shipped blob (the `bl-*` ones have a blob of their own), with the bar
/// max(1.5×, +0.05 cm).
fn default_vs_paper_table() -> anyhow::Result<String> {
    let mut names: Vec<String> = std::fs::read_dir(root().join("scenarios"))?
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .filter_map(|p| p.file_stem().map(|s| s.to_string_lossy().into_owned()))
        .filter(|n| !n.starts_with("bl-"))
        .collect();
    names.sort();
    let mut out = String::from(
        "| scenario | default (composite), RMSE t ≥ 5 s (cm) | paper's gradient law (cm) | bar max(1.5×, +0.05 cm) |\n| --- | --- | --- | --- |\n",
    );
    for n in names {
        let sc = scenario(&n)?;
        let (d, g) = (flight(&sc, "adaptive")?, flight(&sc, "adaptive-gradient")?);
        let score = |r: &Report| {
            if r.crashed {
                None
            } else {
                r.rmse_pos_window_m
            }
        };
        let verdict = match (score(&d), score(&g)) {
            (Some(d), Some(g)) if d <= (1.5 * g).max(g + 0.0005) => "met".to_string(),
            (Some(_), Some(_)) => "**missed**".to_string(),
            (None, _) => "**default crashed**".to_string(),
            (Some(_), None) => "met (the paper's law crashed)".to_string(),
        };
        out += &format!(
            "| {n} | {} | {} | {verdict} |\n",
            cm(score(&d)),
            cm(score(&g))
        );
    }
    Ok(out)
}

/// `gains`: the shipped blob flown with the perfect-state gains (`Gains::for_mass_kg`) and with
/// the vehicle-derived ones (`Gains::for_vehicle`, the default), on the true state.
fn gains_table() -> anyhow::Result<String> {
    const ROWS: [(&str, &str); 13] = [
        ("paper-spiral", "adaptive"),
        ("paper-spiral", "adaptive-gradient"),
        ("paper-spiral-realistic", "adaptive"),
        ("paper-spiral-realistic", "adaptive-gradient"),
        ("step", "adaptive"),
        ("step", "adaptive-gradient"),
        ("gust-spiral", "adaptive"),
        ("gust-spiral", "adaptive-gradient"),
        ("diamond", "adaptive"),
        ("diamond", "adaptive-gradient"),
        ("rotor-loss-mid", "adaptive"),
        ("rotor-loss-mid", "adaptive-gradient"),
        ("paper-spiral", "learned"),
    ];
    let weights = root().join(DEFAULT_WEIGHTS);
    let mut out = String::from(
        "| scenario | controller | `Gains::for_mass_kg` | `Gains::for_vehicle` (default) |\n| --- | --- | --- | --- |\n",
    );
    for (s, c) in ROWS {
        let sc = scenario(s)?;
        let spec = ControllerSpec::parse(c)?;
        let mut cells = Vec::new();
        for perfect_state in [true, false] {
            let model = load_learned(&weights)?;
            let facts = VehicleFacts::of(&model);
            let base = if perfect_state {
                Gains::for_mass_kg(facts.mass_kg)
            } else {
                Gains::for_vehicle(&facts)
            };
            let mut ctrl = CoreController::new(c, model, spec.gains(base));
            let log = fly_scenario(&sc, &mut ctrl as &mut dyn Controller);
            let r = Report::from_flight(&log, &sc, None);
            cells.push(if r.crashed {
                "crashed".to_string()
            } else {
                format!("{} cm", cm(r.rmse_pos_window_m))
            });
        }
        out += &format!("| {s} | {c} | {} | {} |\n", cells[0], cells[1]);
    }
    Ok(out)
}

/// `paper-spiral`: the README's first table, every controller on paper-spiral with the shipped
/// blob; the best RMSE over t ≥ 5 s in bold.
fn paper_spiral_table() -> anyhow::Result<String> {
    const CONTROLLERS: [&str; 5] = [
        "pid",
        "geometric",
        "geometric-adaptive",
        "learned",
        "adaptive",
    ];
    let sc = scenario("paper-spiral")?;
    let mut reports = Vec::new();
    for c in CONTROLLERS {
        reports.push((c, flight(&sc, c)?));
    }
    let best = reports
        .iter()
        .filter(|(_, r)| !r.crashed)
        .filter_map(|(_, r)| r.rmse_pos_window_m)
        .fold(f64::INFINITY, f64::min);
    let mut out = String::from(
        "| controller | crashed | RMSE t ≥ 5 s (cm) | RMSE whole (cm) | max error (cm) |\n| --- | --- | --- | --- | --- |\n",
    );
    for (c, r) in &reports {
        let crashed = r
            .crash_time_s
            .map_or("no".to_string(), |t| format!("yes, at {t:.2} s"));
        let window = if r.crashed { None } else { r.rmse_pos_window_m };
        let is_best = window == Some(best);
        let (name, w) = if is_best {
            (format!("**{c}**"), format!("**{}**", cm(window)))
        } else {
            (c.to_string(), cm(window))
        };
        out += &format!(
            "| {name} | {crashed} | {w} | {} | {} |\n",
            cm(Some(r.rmse_pos_m)),
            cm(Some(r.max_err_m))
        );
    }
    Ok(out)
}

/// `n` with a comma every three digits, as the pages write numbers.
fn thousands(n: u64) -> String {
    let d = n.to_string();
    let mut out = String::new();
    for (i, c) in d.chars().enumerate() {
        if i > 0 && (d.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// One `firmware/report.sh` run (`CYCLES=0`): its key=value figures.
fn firmware_report(features: &str, no_default: bool) -> anyhow::Result<BTreeMap<String, u64>> {
    let kv = std::env::temp_dir().join(format!(
        "hamflight-doc-budget-{}-{features}-{no_default}.txt",
        std::process::id()
    ));
    let out = std::process::Command::new(root().join("firmware/report.sh"))
        .env("CYCLES", "0")
        .env("FEATURES", features)
        .env("NO_DEFAULT", if no_default { "1" } else { "0" })
        .env("REPORT_KV", &kv)
        .output()?;
    if !out.status.success() {
        anyhow::bail!(
            "firmware/report.sh (FEATURES={features:?}, NO_DEFAULT={no_default}) failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let text = std::fs::read_to_string(&kv)?;
    let _ = std::fs::remove_file(&kv);
    text.split_whitespace()
        .map(|pair| {
            let (k, v) = pair
                .split_once('=')
                .ok_or_else(|| anyhow::anyhow!("report.sh wrote `{pair}`, not key=value"))?;
            Ok((k.to_string(), v.parse::<u64>()?))
        })
        .collect()
}

/// The firmware's budget table: every build of [`BUDGET_BUILDS`] through `firmware/report.sh`.
fn firmware_budget_table() -> anyhow::Result<String> {
    let mut out = String::from(
        "| build (`firmware/report.sh`, QEMU `-icount shift=0`) | one step, mean / worst (instructions; budget ≤ 10,000) | worst step at 168 MHz, 1 instruction/cycle | flash, image with the 9,820-byte blob (budget ≤ 65,536 B) | static RAM (budget ≤ 32,768 B) | peak stack, flying |\n| --- | --- | --- | --- | --- | --- |\n",
    );
    for (label, features, no_default) in BUDGET_BUILDS {
        let r = firmware_report(features, no_default)?;
        let get = |k: &str| {
            r.get(k)
                .copied()
                .ok_or_else(|| anyhow::anyhow!("report.sh gave no `{k}`"))
        };
        let max = get("max_instructions")?;
        out += &format!(
            "| {label} | {} / {} | {:.1} µs | {} B | {} B | {} B |\n",
            thousands(get("mean_instructions")?),
            thousands(max),
            max as f64 / 168.0,
            thousands(get("flash_bytes")?),
            thousands(get("sram_bytes")?),
            thousands(get("stack_peak_bytes")?),
        );
    }
    Ok(out)
}

/// Whether the firmware's budget can be measured here (QEMU); under CI its absence is an error.
fn qemu_present() -> anyhow::Result<bool> {
    let found = std::process::Command::new("qemu-system-arm")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        if std::env::var("CI").is_ok_and(|v| v == "true") {
            anyhow::bail!(
                "qemu-system-arm is missing: the firmware-budget block needs it (apt-get install qemu-system-arm)"
            );
        }
        eprintln!(
            "doc_tables: WARNING: no qemu-system-arm, so the firmware-budget block is left as the pages have it (apt-get install qemu-system-arm to measure it)"
        );
    }
    Ok(found)
}

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
fn bitcraze_summary_table() -> anyhow::Result<String> {
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
fn bitcraze_loop_table() -> anyhow::Result<String> {
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
fn bitcraze_truth_table() -> anyhow::Result<String> {
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
fn vehicles_summary_table() -> anyhow::Result<String> {
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
fn vehicles_table() -> anyhow::Result<String> {
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

/// Every block this program writes, by name (`firmware-budget` only with QEMU).
fn generate() -> anyhow::Result<BTreeMap<&'static str, String>> {
    let mut b = BTreeMap::new();
    if qemu_present()? {
        eprintln!(
            "doc_tables: measuring the firmware under QEMU (firmware/report.sh, 3 builds)..."
        );
        b.insert("firmware-budget", firmware_budget_table()?);
    }
    b.insert("laws", laws_table()?);
    b.insert("rotor-loss-set", rotor_loss_table()?);
    b.insert("default-vs-paper", default_vs_paper_table()?);
    b.insert("gains", gains_table()?);
    b.insert("paper-spiral", paper_spiral_table()?);
    b.insert("bitcraze-summary", bitcraze_summary_table()?);
    b.insert("bitcraze-loop", bitcraze_loop_table()?);
    b.insert("bitcraze-loop-truth", bitcraze_truth_table()?);
    b.insert("vehicles-summary", vehicles_summary_table()?);
    b.insert("vehicles", vehicles_table()?);
    Ok(b)
}

const OPEN: &str = "<!-- generated: ";
const CLOSE: &str = "<!-- end generated: ";

/// The page with every block replaced by `blocks`' text; the blocks it held, by name, with the
/// text the page had for each.
fn rewrite(
    page: &str,
    text: &str,
    blocks: &BTreeMap<&str, String>,
) -> anyhow::Result<(String, Vec<(String, String)>)> {
    let mut out = String::new();
    let mut found = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find(OPEN) {
        let after = &rest[i + OPEN.len()..];
        let end = after
            .find(" -->")
            .ok_or_else(|| anyhow::anyhow!("{page}: an unterminated `{OPEN}` marker"))?;
        let name = after[..end].trim().to_string();
        let close = format!("{CLOSE}{name} -->");
        let body_start = i + OPEN.len() + end + " -->".len();
        let j = rest[body_start..].find(&close).ok_or_else(|| {
            anyhow::anyhow!("{page}: block `{name}` has no closing `{close}` marker")
        })?;
        let old = &rest[body_start..body_start + j];
        let old = old.strip_prefix('\n').unwrap_or(old).to_string();
        let body = match blocks.get(name.as_str()) {
            Some(b) => b,
            // Not measurable on this machine (qemu_present warned): the page's text stays.
            None if name == "firmware-budget" => &old,
            None => anyhow::bail!(
                "{page}: block `{name}` is not one doc_tables writes ({:?})",
                blocks.keys().collect::<Vec<_>>()
            ),
        };
        out += &rest[..body_start];
        out += "\n";
        out += body;
        out += &close;
        rest = &rest[body_start + j + close.len()..];
        found.push((name, old));
    }
    out += rest;
    Ok((out, found))
}

fn first_difference(a: &str, b: &str) -> String {
    for (i, (x, y)) in a.lines().zip(b.lines()).enumerate() {
        if x != y {
            return format!("line {} of the block:\n  page: {x}\n  code: {y}", i + 1);
        }
    }
    format!(
        "the block has {} lines, the code gives {}",
        a.lines().count(),
        b.lines().count()
    )
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let write = match args.first().map(String::as_str) {
        Some("--write") => true,
        Some("--check") => false,
        _ => {
            eprintln!(
                "usage: doc_tables --write | --check\n\n  --write  fly the flights and rewrite the generated blocks of {PAGES:?}\n  --check  fly them and fail if a page's block differs (CI)"
            );
            std::process::exit(2);
        }
    };
    eprintln!("doc_tables: flying the tables' flights (seconds in release)...");
    let blocks = generate()?;
    let mut seen = Vec::new();
    let mut stale = Vec::new();
    for page in PAGES {
        let path = root().join(page);
        let text = std::fs::read_to_string(&path)?;
        let (new, found) = rewrite(page, &text, &blocks)?;
        let names: Vec<&str> = found.iter().map(|(n, _)| n.as_str()).collect();
        if new != text {
            if write {
                host_train::io::write_atomic(&path, new.as_bytes())?;
                eprintln!("doc_tables: rewrote {page} ({})", names.join(", "));
            } else {
                for (name, page_block) in &found {
                    // A block not measured here (no QEMU) is left as the page has it.
                    let Some(code_block) = blocks.get(name.as_str()) else {
                        continue;
                    };
                    if page_block != code_block {
                        stale.push(format!(
                            "{page}, block `{name}`: {}",
                            first_difference(page_block, code_block)
                        ));
                    }
                }
            }
        }
        seen.extend(found.into_iter().map(|(n, _)| n));
    }
    for name in blocks.keys() {
        if !seen.iter().any(|s| s == name) {
            anyhow::bail!("block `{name}` is on no page of {PAGES:?}");
        }
    }
    if !stale.is_empty() {
        for s in &stale {
            eprintln!("doc_tables: STALE {s}");
        }
        anyhow::bail!(
            "{} generated block(s) differ from what the code gives: run `cargo run --release -p host-train --example doc_tables -- --write` and commit the pages",
            stale.len()
        );
    }
    if !write {
        eprintln!(
            "doc_tables: OK, {} blocks on {} pages match the code",
            seen.len(),
            PAGES.len()
        );
    }
    Ok(())
}
