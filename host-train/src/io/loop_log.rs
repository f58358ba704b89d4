//! The closed-loop logs of the benchmark flights (`tools/benchmark/nanodrone.py --loop-out`):
//! per 100 Hz row the estimated state, the high-level commander's reference and the onboard
//! controller's motor commands, for replaying the onboard Mellinger controller
//! (`host-train onboard`). Also the record types that controller's interface shares.
//!
//! CSV columns (one header line, any order): `t_s,px_m,py_m,pz_m,qw,qx,qy,qz,
//! vx_world_m_s,vy_world_m_s,vz_world_m_s,wx_rad_s,wy_rad_s,wz_rad_s,erpm1..erpm4,
//! ref_px_m,ref_py_m,ref_pz_m,ref_vx_m_s,ref_vy_m_s,ref_vz_m_s,ref_yaw_rad,cmd1..cmd4,vbat_v`.
//! Position, velocity world (z up); quaternion body→world; rates body; `cmd*` the log's
//! `m*_thrust` (PWM / 65535). `erpm*` may be `nan` (dropped packets); nothing else may.

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

use nalgebra::{UnitQuaternion, Vector3};

/// The estimated state the onboard controller sees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OnboardState {
    /// Position, world, m.
    pub p_m: Vector3<f64>,
    /// Velocity, world, m/s.
    pub v_m_s: Vector3<f64>,
    /// Attitude, body (FLU) to world (z up).
    pub q: UnitQuaternion<f64>,
    /// Body angular rate (the gyro), rad/s.
    pub w_body_rad_s: Vector3<f64>,
}

/// The full-state reference (the high-level commander's setpoint, position mode absolute).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OnboardSetpoint {
    /// Reference position, world, m.
    pub p_m: Vector3<f64>,
    /// Reference velocity, world, m/s.
    pub v_m_s: Vector3<f64>,
    /// Reference acceleration (feedforward), world, m/s².
    pub a_m_s2: Vector3<f64>,
    /// Reference yaw, rad.
    pub yaw_rad: f64,
}

impl OnboardSetpoint {
    /// Hover at `p_m` with yaw `yaw_rad`.
    pub fn hover(p_m: Vector3<f64>, yaw_rad: f64) -> Self {
        Self {
            p_m,
            v_m_s: Vector3::zeros(),
            a_m_s2: Vector3::zeros(),
            yaw_rad,
        }
    }
}

/// Normalized motor commands 0..1 (PWM ratio / 65535), motors 1..4 in the benchmark's order.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct MotorCommands(pub [f64; 4]);

impl MotorCommands {
    /// Collective: the mean of the four commands.
    pub fn collective(&self) -> f64 {
        self.0.iter().sum::<f64>() / 4.0
    }

    /// The legacy distribution's inverse: (collective, roll, pitch, yaw) in command units
    /// (normalized), with roll = the firmware's `control.roll`, pitch = `control.pitch`,
    /// yaw = `control.yaw` (each divided by 65535) when no motor is capped.
    pub fn axes(&self) -> [f64; 4] {
        let [m1, m2, m3, m4] = self.0;
        // m1 = T - r + p + y, m2 = T - r - p - y, m3 = T + r - p + y, m4 = T + r + p - y,
        // with r = roll / 2, p = pitch / 2.
        let t = (m1 + m2 + m3 + m4) / 4.0;
        let r = (-m1 - m2 + m3 + m4) / 4.0;
        let p = (m1 - m2 - m3 + m4) / 4.0;
        let y = (m1 - m2 + m3 - m4) / 4.0;
        [t, 2.0 * r, 2.0 * p, y]
    }
}

/// One logged closed-loop flight.
#[derive(Clone, Debug, Default)]
pub struct LoopFlight {
    /// The run's name (the file stem).
    pub name: String,
    /// Row times, s.
    pub t_s: Vec<f64>,
    /// The estimated state per row.
    pub state: Vec<OnboardState>,
    /// The reference per row; the logs carry no acceleration, so `a_m_s2` is zero here
    /// (`host-train onboard --accel` derives one).
    pub setpoint: Vec<OnboardSetpoint>,
    /// The onboard controller's motor commands per row.
    pub cmd: Vec<MotorCommands>,
    /// Measured motor speeds, eRPM (`nan` where dropped).
    pub erpm: Vec<[f64; 4]>,
    /// Battery voltage, V.
    pub vbat_v: Vec<f64>,
    /// Any further numeric columns, by name (e.g. the logged wrench `log_thrust`,
    /// `log_torque_roll`, `log_torque_pitch`, `log_torque_yaw`); `nan` allowed.
    pub extra: std::collections::BTreeMap<String, Vec<f64>>,
}

impl LoopFlight {
    /// Number of rows.
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    /// Whether the flight has no rows.
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }
}

/// The columns a loop log must carry.
pub const LOOP_COLUMNS: [&str; 30] = [
    "t_s",
    "px_m",
    "py_m",
    "pz_m",
    "qw",
    "qx",
    "qy",
    "qz",
    "vx_world_m_s",
    "vy_world_m_s",
    "vz_world_m_s",
    "wx_rad_s",
    "wy_rad_s",
    "wz_rad_s",
    "erpm1",
    "erpm2",
    "erpm3",
    "erpm4",
    "ref_px_m",
    "ref_py_m",
    "ref_pz_m",
    "ref_vx_m_s",
    "ref_vy_m_s",
    "ref_vz_m_s",
    "ref_yaw_rad",
    "cmd1",
    "cmd2",
    "cmd3",
    "cmd4",
    "vbat_v",
];

/// Reads one loop-log CSV; errors name the file, the line and the column.
pub fn read_loop_csv(path: &Path) -> Result<LoopFlight> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    parse_loop_csv(&text, path)
}

/// Parses a loop log's text (`path` only names it in errors).
pub fn parse_loop_csv(text: &str, path: &Path) -> Result<LoopFlight> {
    let mut rd = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let header = rd
        .headers()
        .with_context(|| format!("{}: reading the header", path.display()))?
        .clone();
    let mut idx = [0usize; 30];
    for (slot, name) in idx.iter_mut().zip(LOOP_COLUMNS) {
        *slot = header.iter().position(|h| h == name).with_context(|| {
            format!(
                "{}: line 1: missing column `{name}` (a loop log needs {})",
                path.display(),
                LOOP_COLUMNS.join(",")
            )
        })?;
    }
    let extra_cols: Vec<(usize, String)> = header
        .iter()
        .enumerate()
        .filter(|(_, h)| !LOOP_COLUMNS.contains(h))
        .map(|(i, h)| (i, h.to_string()))
        .collect();
    let name = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut f = LoopFlight {
        name,
        ..LoopFlight::default()
    };
    for (row, rec) in rd.records().enumerate() {
        let line = row + 2;
        let rec = rec.with_context(|| format!("{}: line {line}", path.display()))?;
        let mut v = [0.0f64; 30];
        for (k, (&i, col)) in idx.iter().zip(LOOP_COLUMNS).enumerate() {
            let cell = rec.get(i).unwrap_or("");
            let x: f64 = cell.parse().map_err(|_| {
                anyhow::anyhow!(
                    "{}: line {line}: column `{col}`: `{cell}` is not a number",
                    path.display()
                )
            })?;
            let may_be_nan = col.starts_with("erpm");
            if !x.is_finite() && !may_be_nan {
                bail!(
                    "{}: line {line}: column `{col}` is {cell} (only erpm may be nan)",
                    path.display()
                );
            }
            v[k] = x;
        }
        let q = nalgebra::Quaternion::new(v[4], v[5], v[6], v[7]);
        if (q.norm() - 1.0).abs() > 0.1 {
            bail!(
                "{}: line {line}: quaternion norm {} is not 1",
                path.display(),
                q.norm()
            );
        }
        if let Some(&last) = f.t_s.last() {
            if v[0] <= last {
                bail!(
                    "{}: line {line}: t_s {} does not increase (previous {last})",
                    path.display(),
                    v[0]
                );
            }
        }
        f.t_s.push(v[0]);
        f.state.push(OnboardState {
            p_m: Vector3::new(v[1], v[2], v[3]),
            v_m_s: Vector3::new(v[8], v[9], v[10]),
            q: UnitQuaternion::from_quaternion(q),
            w_body_rad_s: Vector3::new(v[11], v[12], v[13]),
        });
        f.erpm.push([v[14], v[15], v[16], v[17]]);
        f.setpoint.push(OnboardSetpoint {
            p_m: Vector3::new(v[18], v[19], v[20]),
            v_m_s: Vector3::new(v[21], v[22], v[23]),
            a_m_s2: Vector3::zeros(),
            yaw_rad: v[24],
        });
        f.cmd.push(MotorCommands([v[25], v[26], v[27], v[28]]));
        f.vbat_v.push(v[29]);
        for (i, col) in &extra_cols {
            let cell = rec.get(*i).unwrap_or("");
            let x: f64 = cell.parse().map_err(|_| {
                anyhow::anyhow!(
                    "{}: line {line}: column `{col}`: `{cell}` is not a number",
                    path.display()
                )
            })?;
            f.extra.entry(col.clone()).or_default().push(x);
        }
    }
    if f.is_empty() {
        bail!("{}: no data rows", path.display());
    }
    Ok(f)
}

/// Reads every `*.csv` under `dir` (sorted by name), or under `dir/train` and `dir/test` when
/// `dir` holds those folders (train first).
pub fn read_loop_dir(dir: &Path) -> Result<Vec<LoopFlight>> {
    let mut files: Vec<PathBuf> = Vec::new();
    let splits: Vec<PathBuf> = ["train", "test"]
        .iter()
        .map(|s| dir.join(s))
        .filter(|p| p.is_dir())
        .collect();
    let folders = if splits.is_empty() {
        vec![dir.to_path_buf()]
    } else {
        splits
    };
    for folder in folders {
        let mut here: Vec<PathBuf> = std::fs::read_dir(&folder)
            .with_context(|| format!("listing {}", folder.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "csv"))
            .collect();
        here.sort();
        files.extend(here);
    }
    if files.is_empty() {
        bail!(
            "{}: no loop-log CSV files (expected *.csv, or train/ and test/ folders)",
            dir.display()
        );
    }
    files.iter().map(|p| read_loop_csv(p)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header() -> String {
        LOOP_COLUMNS.join(",")
    }

    fn row(t: f64) -> String {
        format!(
            "{t},0,0,1,1,0,0,0,0,0,0,0.1,0,0,9e4,nan,9e4,9e4,0,0,1,0,0,0,0.2,0.5,0.5,0.5,0.5,4.0"
        )
    }

    #[test]
    fn parses_rows_and_keeps_nan_erpm() {
        let text = format!("{}\n{}\n{}\n", header(), row(0.0), row(0.01));
        let f = parse_loop_csv(&text, Path::new("x/run.csv")).unwrap();
        assert_eq!(f.name, "run");
        assert_eq!(f.len(), 2);
        assert_eq!(f.state[1].p_m.z, 1.0);
        assert_eq!(f.state[0].w_body_rad_s.x, 0.1);
        assert!(f.erpm[0][1].is_nan());
        assert_eq!(f.setpoint[0].yaw_rad, 0.2);
        assert_eq!(f.cmd[1].0, [0.5; 4]);
        assert_eq!(f.vbat_v[0], 4.0);
    }

    #[test]
    fn errors_name_file_line_and_column() {
        let bad = row(0.01).replacen("0.5", "nan", 1);
        let text = format!("{}\n{}\n{}\n", header(), row(0.0), bad);
        let e = format!(
            "{:#}",
            parse_loop_csv(&text, Path::new("run.csv")).unwrap_err()
        );
        assert!(e.contains("run.csv: line 3: column `cmd1`"), "{e}");
        let text = format!("{}\n{}\n", header().replace("vbat_v", "v"), row(0.0));
        let e = format!(
            "{:#}",
            parse_loop_csv(&text, Path::new("run.csv")).unwrap_err()
        );
        assert!(e.contains("missing column `vbat_v`"), "{e}");
        let text = format!("{}\n{}\n{}\n", header(), row(0.0), row(0.0));
        let e = format!(
            "{:#}",
            parse_loop_csv(&text, Path::new("run.csv")).unwrap_err()
        );
        assert!(e.contains("line 3: t_s"), "{e}");
    }
}
