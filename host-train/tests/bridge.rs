//! The JSON-lines bridge: replies in order, one per request; a bad line gets an error and does
//! not stop the stream; a non-finite state gets motors off with a fault flag.

use host_train::bridge::serve;
use host_train::flight::core_by_name;

const HOVER: &str = r#"{"t": 0.0, "p": [0, 0, 1], "R": [[1,0,0],[0,1,0],[0,0,1]], "v": [0,0,0], "w": [0,0,0], "setpoint": {"p": [0, 0, 1]}}"#;

#[test]
fn replies_in_order_and_survives_bad_lines() {
    let mut ctrl = core_by_name("geometric-adaptive", None).expect("core controller");
    let nan_state = HOVER
        .replace("\"t\": 0.0", "\"t\": 0.004")
        .replace("\"v\": [0,0,0]", "\"v\": [0,0,1e300]");
    let input = format!(
        "{HOVER}\nnot json\n{}\n\n{nan_state}\n",
        HOVER.replace("\"t\": 0.0", "\"t\": 0.002")
    );
    let mut out = Vec::new();
    serve(ctrl.as_mut(), 0.002, input.as_bytes(), &mut out).expect("serve");
    let lines: Vec<serde_json::Value> = String::from_utf8(out)
        .expect("utf-8")
        .lines()
        .map(|l| serde_json::from_str(l).expect("each reply is JSON"))
        .collect();
    assert_eq!(lines.len(), 4, "{lines:?}");
    // Hover: the thrust holds the weight and no fault is raised.
    let thrust = lines[0]["thrust_n"].as_f64().expect("thrust");
    assert!((thrust - 0.027 * 9.8).abs() < 1e-3, "hover thrust {thrust}");
    assert_eq!(lines[0]["faults"]["fault"], false);
    assert_eq!(lines[0]["rpm"].as_array().map(Vec::len), Some(4));
    assert!(lines[1]["error"]
        .as_str()
        .expect("error")
        .starts_with("line 2"));
    assert_eq!(lines[2]["t"], 0.002);
    // 1e300 m/s overflows f32 to infinity: the controller answers with motors off and a fault.
    assert_eq!(lines[3]["faults"]["fault"], true);
    assert!(lines[3]["rpm"]
        .as_array()
        .expect("rpm")
        .iter()
        .all(|v| v.as_f64() == Some(0.0)));
}

#[test]
fn unknown_controller_is_a_clear_error() {
    let err = core_by_name("nope", None).err().expect("error").to_string();
    assert!(err.contains("adaptive") && err.contains("nope"), "{err}");
}
