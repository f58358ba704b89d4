//! The command line's traps for a new user, closed: `import --calm` takes several logs, `import`
//! never assumes the stock mass for someone else's vehicle, and `train` never overwrites the
//! shipped weights unless `--out` names them. Parsed with the same clap definitions as the binary.

use clap::Parser;
use host_train::data::ImportArgs;
use host_train::train::TrainArgs;
use std::path::PathBuf;

#[derive(Parser, Debug)]
struct Import {
    #[command(flatten)]
    args: ImportArgs,
}

#[derive(Parser, Debug)]
struct Train {
    #[command(flatten)]
    args: TrainArgs,
}

fn paths(names: &[&str]) -> Vec<PathBuf> {
    names.iter().map(PathBuf::from).collect()
}

#[test]
fn calm_takes_every_following_log_and_may_be_repeated() {
    let a = Import::try_parse_from([
        "import",
        "--out",
        "D",
        "w0",
        "w1",
        "--calm",
        "c0",
        "c1",
        "c2",
        "--mass-kg",
        "0.03",
    ])
    .expect("parses")
    .args;
    assert_eq!(a.logs, paths(&["w0", "w1"]));
    assert_eq!(a.calm, paths(&["c0", "c1", "c2"]));

    let b = Import::try_parse_from([
        "import",
        "--out",
        "D",
        "--calm",
        "c0",
        "--mass-kg",
        "0.03",
        "--calm",
        "c1",
        "w0",
    ]);
    // `w0` after `--calm c1` is a calm log too: the help says to give the disturbed logs first.
    let b = b.expect("parses").args;
    assert_eq!(b.calm, paths(&["c0", "c1", "w0"]));
    assert!(b.logs.is_empty());
}

#[test]
fn import_requires_the_vehicle_mass() {
    let err = Import::try_parse_from(["import", "--out", "D", "w0"]).expect_err("no mass given");
    let msg = err.to_string();
    assert!(
        msg.contains("--mass-kg"),
        "error does not name the flag: {msg}"
    );
    let ok = Import::try_parse_from(["import", "--out", "D", "w0", "--mass-kg", "0.034"])
        .expect("parses")
        .args;
    assert_eq!(ok.mass_kg, Some(0.034));
    // A vehicle description carries the mass instead.
    let v = Import::try_parse_from(["import", "--out", "D", "w0", "--vehicle", "cf2x"])
        .expect("a vehicle file stands in for --mass-kg")
        .args;
    assert_eq!(v.mass_kg, None);
    assert_eq!(v.vehicle.as_deref(), Some(std::path::Path::new("cf2x")));
}

#[test]
fn import_new_matches_the_command_line_defaults() {
    let parsed = Import::try_parse_from(["import", "--out", "D", "--mass-kg", "0.027"])
        .expect("parses")
        .args;
    let built = host_train::data::ImportArgs::new("D".into(), 0.027);
    assert_eq!(format!("{parsed:?}"), format!("{built:?}"));
}

#[test]
fn train_requires_an_explicit_output() {
    let err = Train::try_parse_from(["train", "--data", "D"]).expect_err("no --out given");
    assert!(err.to_string().contains("--out"), "{err}");
    let ok = Train::try_parse_from(["train", "--data", "D", "--out", "my.hfw"])
        .expect("parses")
        .args;
    assert_eq!(ok.out, PathBuf::from("my.hfw"));
}
