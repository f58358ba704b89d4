//! The JSON-lines bridge: replies in order, one per request; a bad line gets an error and does
//! not stop the stream; a non-finite state gets motors off with a fault flag.

use host_train::bridge::serve;
use host_train::control::core_by_name;

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

/// Hover lines 2 ms apart for `n` ticks, with an optional accelerometer field.
fn hover_lines(n: usize, acc: Option<&str>) -> String {
    (0..n)
        .map(|k| {
            let line = HOVER.replace("\"t\": 0.0", &format!("\"t\": {}", k as f64 * 0.002));
            match acc {
                Some(a) => line.replace("}}", &format!("}}, \"acc\": {a}}}")),
                None => line,
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn estimates(ctrl_name: &str, input: &str) -> Vec<Vec<f64>> {
    let mut ctrl = core_by_name(ctrl_name, None).expect("core controller");
    let mut out = Vec::new();
    serve(ctrl.as_mut(), 0.002, input.as_bytes(), &mut out).expect("serve");
    String::from_utf8(out)
        .expect("utf-8")
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).expect("JSON reply");
            assert!(v.get("error").is_none(), "{v}");
            v["a"]
                .as_array()
                .expect("a")
                .iter()
                .map(|x| x.as_f64().expect("number"))
                .collect()
        })
        .collect()
}

#[test]
fn the_accelerometer_reaches_the_composite_law() {
    // Hovering exactly, a specific force of g along body z says "no disturbance"; one with an
    // extra 0.5 m/s² along body x says a force pushes the vehicle, which the composite law
    // learns from the prediction error at once.
    let calm = estimates(
        "geometric-adaptive-composite",
        &hover_lines(200, Some("[0, 0, 9.8]")),
    );
    let pushed = estimates(
        "geometric-adaptive-composite",
        &hover_lines(200, Some("[0.5, 0, 9.8]")),
    );
    let (calm, pushed) = (
        calm.last().expect("replies"),
        pushed.last().expect("replies"),
    );
    assert!(
        calm.iter().all(|a| a.abs() < 1e-3),
        "calm estimate {calm:?}"
    );
    assert!(pushed[0] > 0.1, "the measured push shows in a: {pushed:?}");
    // The paper's law does not read it: the same replies with and without the field.
    assert_eq!(
        estimates(
            "geometric-adaptive-gradient",
            &hover_lines(50, Some("[0.5, 0, 9.8]"))
        ),
        estimates("geometric-adaptive-gradient", &hover_lines(50, None))
    );
}

#[test]
fn a_malformed_accelerometer_is_an_error_reply() {
    let mut ctrl = core_by_name("geometric-adaptive-composite", None).expect("core controller");
    let mut out = Vec::new();
    let input = hover_lines(1, Some("[0, 9.8]"));
    serve(ctrl.as_mut(), 0.002, input.as_bytes(), &mut out).expect("serve");
    let reply: serde_json::Value =
        serde_json::from_str(String::from_utf8(out).expect("utf-8").trim()).expect("JSON");
    assert!(
        reply["error"]
            .as_str()
            .expect("error")
            .starts_with("line 1"),
        "{reply}"
    );
}

#[test]
fn unknown_controller_is_a_clear_error() {
    let err = core_by_name("nope", None).err().expect("error").to_string();
    assert!(err.contains("adaptive") && err.contains("nope"), "{err}");
}

/// Deterministic SplitMix64.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Tokens that stress the parser and the core: huge, tiny, negative zero, non-numbers.
const TOKENS: [&str; 14] = [
    "1e308", "-1e308", "1e39", "1e-45", "-0", "0.1", "3", "null", "true", "\"x\"", "[]", "{}",
    "1e400", "NaN",
];

/// One random edit of a request line (bytes; may leave UTF-8).
fn mutate_line(rng: &mut Rng, line: &mut Vec<u8>) {
    let pos = rng.below(line.len() + 1);
    match rng.below(7) {
        0 if !line.is_empty() => {
            let at = pos.min(line.len() - 1);
            line[at] ^= 1 << rng.below(8);
        }
        1 if pos < line.len() => {
            line.remove(pos);
        }
        2 => line.insert(pos, b"{}[]:,\"0123456789.-eE "[rng.below(22)]),
        3 => {
            // Replace a number with a stress token.
            let digits: Vec<usize> = (0..line.len())
                .filter(|&i| line[i].is_ascii_digit())
                .collect();
            if let Some(&i) = digits.get(rng.below(digits.len())) {
                let tok = TOKENS[rng.below(TOKENS.len())].as_bytes();
                line.splice(i..i + 1, tok.iter().copied());
            }
        }
        4 => line.truncate(pos),
        5 => {
            let key = [&b"\"extra\": 1, "[..], b"\"t\": 2, ", b"\"R\": [], "][rng.below(3)];
            let at = line.iter().position(|&b| b == b'{').map_or(0, |i| i + 1);
            line.splice(at..at, key.iter().copied());
        }
        _ => line.insert(pos, rng.next() as u8),
    }
    // One line stays one line.
    for b in line.iter_mut() {
        if *b == b'\n' {
            *b = b' ';
        }
    }
}

/// The stable-toolchain counterpart of `fuzz/fuzz_targets/bridge_line.rs`, run by the README's
/// test command: 4,000 seeded mutants of request lines (byte flips, deletions, stress numbers,
/// unknown or repeated keys, truncation, non-UTF-8 bytes) through `serve` in one stream. Exactly
/// one reply per non-blank line, in order; a line gets an error reply naming its number exactly
/// when `parse_request` rejects it (or it is not UTF-8); every other reply has four finite,
/// non-negative rotor speeds, and zero ones when it reports a fault.
#[test]
fn randomized_lines_get_one_right_reply_each() {
    let mut rng = Rng(0xB41D6E);
    let seeds = [
        HOVER.to_string(),
        HOVER.replace("\"setpoint\": {\"p\": [0, 0, 1]}", "\"setpoint\": {\"p\": [0.5, 0, 1], \"v\": [0, 0, 0], \"a\": [0, 0, 0], \"j\": [0, 0, 0], \"yaw\": 0.1, \"yaw_rate\": 0}"),
    ];
    let mut input = Vec::new();
    let mut expected = Vec::new(); // per non-blank line: (line number, parses?)
    for n in 0..4000 {
        let mut line = seeds[rng.below(2)].as_bytes().to_vec();
        // Strictly increasing t, so that most accepted lines have a valid tick.
        let t = format!("\"t\": {}", 0.002 * (n + 1) as f64);
        let s = String::from_utf8(line.clone())
            .unwrap()
            .replace("\"t\": 0.0", &t);
        line = s.into_bytes();
        for _ in 0..rng.below(4) {
            mutate_line(&mut rng, &mut line);
        }
        let parses = std::str::from_utf8(&line)
            .ok()
            .map(|l| host_train::bridge::parse_request(l).is_ok());
        let blank = std::str::from_utf8(&line).is_ok_and(|l| l.trim().is_empty());
        if !blank {
            expected.push((n + 1, parses.unwrap_or(false)));
        }
        input.extend_from_slice(&line);
        input.push(b'\n');
    }
    let weights = concat!(env!("CARGO_MANIFEST_DIR"), "/../weights/default.hfw");
    let mut ctrl = core_by_name("adaptive", Some(weights.as_ref())).expect("core controller");
    let mut out = Vec::new();
    serve(ctrl.as_mut(), 0.002, &input[..], &mut out).expect("serve survives every line");
    let replies: Vec<serde_json::Value> = String::from_utf8(out)
        .expect("replies are UTF-8")
        .lines()
        .map(|l| serde_json::from_str(l).expect("each reply is JSON"))
        .collect();
    assert_eq!(replies.len(), expected.len());
    let (mut ok, mut err, mut faults) = (0, 0, 0);
    for (reply, (n, parses)) in replies.iter().zip(&expected) {
        if *parses {
            assert!(reply.get("error").is_none(), "line {n}: {reply}");
            let rpm: Vec<f64> = reply["rpm"]
                .as_array()
                .expect("rpm")
                .iter()
                .map(|v| v.as_f64().expect("a number"))
                .collect();
            assert_eq!(rpm.len(), 4, "line {n}");
            assert!(
                rpm.iter().all(|r| r.is_finite() && *r >= 0.0),
                "line {n}: {rpm:?}"
            );
            if reply["faults"]["fault"] == true {
                assert!(rpm.iter().all(|r| *r == 0.0), "line {n}: {reply}");
                faults += 1;
            }
            ok += 1;
        } else {
            let e = reply["error"]
                .as_str()
                .unwrap_or_else(|| panic!("line {n}: {reply}"));
            assert!(e.starts_with(&format!("line {n}: ")), "{e}");
            err += 1;
        }
    }
    // Both kinds of line, and faulted steps among the accepted ones, were exercised.
    assert!(
        ok > 500 && err > 500 && faults > 0,
        "ok {ok}, errors {err}, faults {faults}"
    );
}

/// Found by the randomized test above: a line that is not UTF-8 used to end the bridge
/// (`BufRead::lines` fails on it). It now gets an error reply and the stream goes on.
#[test]
fn a_line_that_is_not_utf8_gets_an_error_and_the_stream_goes_on() {
    let mut ctrl = core_by_name("geometric-adaptive", None).expect("core controller");
    let mut input = b"{\"t\": 0.0, \"p\": [0, 0, 1], \"R\": \xff}\r\n".to_vec();
    input.extend_from_slice(HOVER.as_bytes());
    input.extend_from_slice(b"\r\n");
    let mut out = Vec::new();
    serve(ctrl.as_mut(), 0.002, &input[..], &mut out).expect("serve");
    let text = String::from_utf8(out).expect("utf-8");
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 2, "{text}");
    assert!(lines[0].contains("line 1: not UTF-8"), "{}", lines[0]);
    let hover: serde_json::Value = serde_json::from_str(lines[1]).expect("json");
    assert_eq!(hover["faults"]["fault"], false, "CRLF line parsed: {hover}");
}

/// The setpoint object is the core's `Setpoint` (its `serde` form) and keeps the documented
/// protocol: names `p`, `v`, `a`, `j`, `yaw`, `yaw_rate`; only `p` required, the rest zero by
/// default; integers and decimals alike; unknown or misspelt names, a missing `p` and arrays of
/// the wrong length are errors.
#[test]
fn setpoint_json_keeps_the_documented_form() {
    use host_train::bridge::parse_request;
    use nalgebra::Vector3;
    let with = |sp: &str| HOVER.replace("{\"p\": [0, 0, 1]}", sp);
    let (_, sp) = parse_request(HOVER)
        .expect("the hover line parses")
        .to_core();
    assert_eq!(
        sp,
        hamflight::Setpoint::hover(Vector3::new(0.0, 0.0, 1.0), 0.0)
    );
    let full = with(
        r#"{"p": [0.5, -1, 2.25], "v": [0.1, 0, 0], "a": [0, 0.2, 0], "j": [0, 0, -3], "yaw": 0.5, "yaw_rate": -0.25}"#,
    );
    let (_, sp) = parse_request(&full)
        .expect("the full setpoint parses")
        .to_core();
    assert_eq!(
        sp,
        hamflight::Setpoint {
            p_m: Vector3::new(0.5, -1.0, 2.25),
            v_m_s: Vector3::new(0.1, 0.0, 0.0),
            a_m_s2: Vector3::new(0.0, 0.2, 0.0),
            j_m_s3: Vector3::new(0.0, 0.0, -3.0),
            yaw_rad: 0.5,
            yaw_rate_rad_s: -0.25,
        }
    );
    for bad in [
        r#"{"p": [0, 0, 1], "vel": [0, 0, 0]}"#,
        r#"{"p_m": [0, 0, 1]}"#,
        r#"{"v": [0, 0, 0]}"#,
        r#"{"p": [0, 0]}"#,
        r#"{"p": [0, 0, 1, 2]}"#,
        r#"{"p": [0, 0, 1], "yaw": "north"}"#,
    ] {
        assert!(parse_request(&with(bad)).is_err(), "{bad} was accepted");
    }
}
