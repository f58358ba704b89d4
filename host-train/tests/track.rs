//! `host-train track`: both adaptation laws' estimates against the true wind on gust-spiral,
//! with the figure and the report written.

use host_train::fly::{run_track, TrackArgs};
use std::path::Path;

#[test]
fn track_writes_the_figure_and_the_composite_law_follows_the_gusts() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let out = std::env::temp_dir().join(format!("hamflight-track-{}", std::process::id()));
    let args = TrackArgs {
        scenario: root.join("scenarios/gust-spiral.toml"),
        controller: "adaptive".into(),
        weights: root.join("weights/default.hfw"),
        out: out.clone(),
        bandwidth: false,
    };
    let r = run_track(&args).expect("track runs");
    let rms = |law: &str| {
        r.laws
            .iter()
            .find(|l| l.law == law)
            .map(|l| l.rms_error_m_s2)
            .expect("both laws flown")
    };
    let (gradient, composite) = (rms("Gradient"), rms("Composite"));
    println!("estimate − wind RMS: gradient {gradient:.3}, composite {composite:.3} m/s²");
    // The composite estimate follows the gusts where the gradient law's lags and shrinks them
    // (docs/adaptation.md, "Both estimates against the truth").
    assert!(composite < 0.15, "composite estimate error {composite}");
    assert!(gradient > 2.5 * composite, "{gradient} vs {composite}");
    let svg = std::fs::read_to_string(out.join("disturbance.svg")).expect("figure written");
    assert!(svg.contains("true wind") && svg.contains("Composite law"));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("track.json")).expect("report"))
            .expect("valid JSON");
    assert_eq!(json["laws"].as_array().map(Vec::len), Some(2));
    assert!(!out.join("bandwidth.svg").exists(), "only with --bandwidth");
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn track_refuses_a_controller_it_cannot_fly_both_ways() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let args = TrackArgs {
        scenario: root.join("scenarios/gust-spiral.toml"),
        controller: "geometric".into(),
        weights: root.join("weights/default.hfw"),
        out: std::env::temp_dir().join("hamflight-track-refused"),
        bandwidth: false,
    };
    let e = run_track(&args).expect_err("geometric has no adaptation law");
    assert!(e.to_string().contains("--controller geometric"), "{e}");
}
