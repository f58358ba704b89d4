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

mod compare;
mod studies;
use studies::{
    bitcraze_loop_table, bitcraze_summary_table, bitcraze_truth_table, vehicles_summary_table,
    vehicles_table,
};

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
        "| build (`firmware/report.sh`, QEMU `-icount shift=0`) | one step, mean / worst (instructions; budget ≤ 10,000) | worst step at 168 MHz, 1 instruction/cycle | flash, image with the 9,820-byte blob (budget ≤ 65,536 B) | static RAM (budget ≤ 32,768 B) | peak stack, flying | control step's stack, measured / static bound (budget ≤ 1,194 B) |\n| --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for (label, features, no_default) in BUDGET_BUILDS {
        let r = firmware_report(features, no_default)?;
        let get = |k: &str| {
            r.get(k)
                .copied()
                .ok_or_else(|| anyhow::anyhow!("report.sh gave no `{k}`"))
        };
        let max = get("max_instructions")?;
        // The static bound needs binutils' objdump (report.sh omits it without, except under CI).
        let step_static = get("step_stack_static_bytes").map_err(|e| {
            e.context(
                "no static stack bound: install binutils-arm-none-eabi (arm-none-eabi-objdump)",
            )
        })?;
        out += &format!(
            "| {label} | {} / {} | {:.1} µs | {} B | {} B | {} B | {} / {} B |\n",
            thousands(get("mean_instructions")?),
            thousands(max),
            max as f64 / 168.0,
            thousands(get("flash_bytes")?),
            thousands(get("sram_bytes")?),
            thousands(get("stack_peak_bytes")?),
            thousands(get("step_stack_bytes")?),
            thousands(step_static),
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
                    if !compare::same_block(name, page_block, code_block) {
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
