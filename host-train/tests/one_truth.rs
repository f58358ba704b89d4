//! Facts written in more than one place, checked against each other: where two copies can drift
//! apart, a test says which one moved.

use host_train::io::{LEE_COMMAND_VARS, USD_ACC_VARS, USD_STATE_VARS};
use host_train::sim::VehicleParams;
use std::path::Path;

fn repo_file(rel: &str) -> String {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel);
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("cannot read {}: {e}", p.display()))
}

/// The SITL's CF2X and the core's mixer describe the same rotors.
#[test]
fn the_hosts_cf2x_is_the_cores_airframe() {
    let host = VehicleParams::cf2x();
    let core = hamflight::mixer::Airframe::default();
    let rel = |a: f64, b: f32| (a - b as f64).abs() <= 1e-6 * a.abs();
    assert!(rel(host.arm_xy_m, core.arm_xy_m), "arm");
    assert!(rel(host.kf_n_per_rpm2, core.kf_n_per_rpm2), "k_f");
    assert!(rel(host.km_nm_per_rpm2, core.km_nm_per_rpm2), "k_m");
    assert!(
        (host.max_rpm() - core.max_rpm as f64).abs() < 1.0,
        "max rpm: host {} core {}",
        host.max_rpm(),
        core.max_rpm
    );
    let facts = hamflight::VehicleFacts::default();
    assert!(rel(host.mass_kg, facts.mass_kg), "mass");
    for i in 0..3 {
        assert!(
            rel(host.inertia_kg_m2[i], facts.inertia_kg_m2[i]),
            "inertia {i}"
        );
    }
}

/// `tools/usd/config.txt` logs exactly what `host-train import` reads, in its order.
#[test]
fn the_usd_deck_config_logs_what_import_reads() {
    let text = repo_file("tools/usd/config.txt");
    let vars: Vec<&str> = text
        .lines()
        .map(|l| l.split('#').next().unwrap_or("").trim())
        .skip_while(|l| *l != "on:fixedFrequency")
        .skip(3) // the event line, its frequency and its mode
        .filter(|l| !l.is_empty())
        .take_while(|l| !l.starts_with("on:"))
        .collect();
    let expected: Vec<&str> = USD_STATE_VARS
        .iter()
        .chain(LEE_COMMAND_VARS.iter())
        .chain(USD_ACC_VARS.iter())
        .copied()
        .collect();
    assert_eq!(vars, expected, "tools/usd/config.txt vs import's variables");
    assert!(
        vars.len() <= 20,
        "the deck stores at most 20 variables per event"
    );
}

/// The law `--help` and the docs name as the default is `Gains::default()`'s.
#[test]
fn the_default_law_is_named_truly() {
    let law = hamflight::Gains::default().law;
    let name = match law {
        hamflight::AdaptationLaw::Gradient => "gradient",
        #[allow(unreachable_patterns)]
        _ => "composite",
    };
    let registry = host_train::control::ControllerSpec::parse("adaptive")
        .map(|s| s.about.to_lowercase())
        .expect("`adaptive` is registered");
    assert!(
        registry.contains(name),
        "`adaptive`'s description does not name the default {name} law: {registry}"
    );
}

/// `eval --controller`'s help names every controller of the registry, the one list of names,
/// and `bridge --controller`'s every core controller.
#[test]
fn eval_help_names_every_registered_controller() {
    use clap::Args;
    let help_of = |cmd: clap::Command| -> String {
        let mut cmd = cmd;
        cmd.render_long_help().to_string()
    };
    let help = help_of(host_train::fly::EvalArgs::augment_args(clap::Command::new(
        "eval",
    )));
    let words: Vec<&str> = help
        .split(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
        .collect();
    let bridge = help_of(host_train::bridge::BridgeArgs::augment_args(
        clap::Command::new("bridge"),
    ));
    for name in host_train::control::core_names() {
        assert!(
            bridge
                .split(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
                .any(|w| w == name),
            "`bridge --controller`'s help does not name `{name}`: {bridge}"
        );
    }
    for name in host_train::control::names() {
        assert!(
            words.contains(&name),
            "`eval --controller`'s help does not name `{name}`: {help}"
        );
    }
}

/// Every name of the registry builds a controller, and the controller says its name back: the
/// list and the constructors cannot drift apart.
#[test]
fn every_registered_name_builds() {
    use host_train::control::{by_name, names};
    let sc = host_train::Scenario::from_toml_str(
        "duration_s = 1.0\n[trajectory]\nkind = \"hover\"\nposition_m = [0.0, 0.0, 1.0]\n",
        "<registry>",
        "registry",
    )
    .expect("scenario");
    let weights = Path::new(env!("CARGO_MANIFEST_DIR")).join("../weights/default.hfw");
    for name in names() {
        let c = by_name(name, &sc, Some(&weights))
            .unwrap_or_else(|e| panic!("`{name}` is registered but does not build: {e:#}"));
        assert_eq!(c.name(), name);
    }
}
