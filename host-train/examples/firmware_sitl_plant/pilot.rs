//! The pilot's packets: cflib's streamed setpoints, the high-level commander's commands, and with
//! `--pilot trajectory` the figure of eight's upload and its start.

use anyhow::{bail, Context, Result};
use host_train::io::{
    flatness_body_rates, full_state_setpoint_packet, full_state_setpoint_packet_with_rates,
    hl_go_to_packet, hl_land_packet, hl_start_trajectory_packet, hl_stop_packet, hl_takeoff_packet,
    poly4d_trajectory_eval, position_setpoint_packet, stop_setpoint_packet, Poly4d,
};
use host_train::TrajectoryPoint;
use nalgebra::Vector3;

use crate::launch::Link;
use crate::trajectory::{figure_eight, figure_eight_pieces, Upload, HL_CMD_START_TRAJECTORY};
use crate::{Args, Pilot, SetpointKind};

/// `--pilot trajectory`: the figure of eight's pieces, flown relative to p*(0); other pilots:
/// none.
pub fn figure_pieces(args: &Args, yaw0: f64) -> Result<Vec<Poly4d>> {
    Ok(if args.pilot == Pilot::Trajectory {
        if !(args.traj_time_scale > 0.0 && args.traj_s > 0.0 && args.upload_s > 0.0) {
            bail!("--traj-s, --traj-time-scale and --upload-s must be positive");
        }
        figure_eight_pieces(
            args.traj_size_m,
            args.traj_s,
            args.traj_pieces as usize,
            yaw0,
        )
    } else {
        Vec::new()
    })
}

/// What the pilot has sent, and what the firmware answered.
pub struct Piloting {
    /// p*(0): where the high-level commander takes off to and hovers, and its yaw.
    hover_m: Vector3<f64>,
    yaw0: f64,
    /// The trajectory's upload (`--pilot trajectory`).
    pub upload: Option<Upload>,
    /// The upload's first and last millisecond (plant time).
    pub upload_began_at: Option<f64>,
    pub upload_done_at: Option<f64>,
    /// The start_trajectory sends (plant time of the last, how many) and its answer.
    pub traj_start: Option<(f64, u32)>,
    pub traj_start_answered: Option<f64>,
    /// The high-level pilot: the phase it last commanded, and how often.
    hl_phase: (&'static str, u32),
    /// Stop setpoints sent (the stream's end).
    stop_sent: u32,
}

impl Piloting {
    /// With trajectory pieces: their upload, and a line on how closely they follow the figure.
    pub fn new(args: &Args, pieces: &[Poly4d], hover_m: Vector3<f64>, yaw0: f64) -> Result<Self> {
        let traj_scale = args.traj_time_scale;
        let upload = if pieces.is_empty() {
            None
        } else {
            let up = Upload::new(pieces, 0)?;
            // how closely the f32 pieces follow the analytic figure, and the figure's peak speed
            let (mut fit_max, mut v_max) = (0.0f64, 0.0f64);
            for i in 0..=10_000 {
                let tau = args.traj_s * i as f64 / 10_000.0;
                let e = poly4d_trajectory_eval(pieces, tau).expect("pieces");
                let f = figure_eight(args.traj_size_m, args.traj_s, tau);
                let fp = Vector3::new(f[0][0], f[1][0], f[2][0]);
                fit_max = fit_max.max((e.p_m - fp).norm());
                v_max = v_max.max(e.v_m_s.norm());
            }
            println!(
                "trajectory: figure of eight {:.2} x {:.2} m in {} s, {} poly4d pieces, {} B in {} \
                 memory writes; the pieces within {:.3} mm of the figure; peak speed {:.2} m/s \
                 (time scale {traj_scale})",
                2.0 * args.traj_size_m,
                args.traj_size_m,
                args.traj_s,
                pieces.len(),
                up.bytes(),
                up.bytes().div_ceil(host_train::io::CRTP_MEM_CHUNK),
                fit_max * 1e3,
                v_max / traj_scale
            );
            Some(up)
        };
        Ok(Piloting {
            hover_m,
            yaw0,
            upload,
            upload_began_at: None,
            upload_done_at: None,
            traj_start: None,
            traj_start_answered: None,
            hl_phase: ("", 0),
            stop_sent: 0,
        })
    }

    /// During the "upload" phase: the upload's next packet, if any, in a millisecond `free` of
    /// pose and setpoint (it goes before cflib's packets).
    pub fn upload_packet(
        &mut self,
        link: &Link,
        k: u64,
        t: f64,
        phase: &str,
        link_up: bool,
        free: bool,
    ) -> Result<Option<Vec<u8>>> {
        let mut upload_pk = None;
        if let (Some(up), "upload", true) = (&mut self.upload, phase, link_up) {
            self.upload_began_at.get_or_insert(t);
            if free {
                let sh = link.shared.lock().unwrap();
                upload_pk = up
                    .next_packet(k, &sh)
                    .with_context(|| format!("plant t = {t:.3} s"))?;
            }
            if up.done() && self.upload_done_at.is_none() {
                self.upload_done_at = Some(t);
                println!(
                    "[{:6.2} s] trajectory uploaded to memory {} ({} B, {} writes, {} packets of \
                     which {} repeats) and defined, plant t = {t:.3} s",
                    link.t_start.elapsed().as_secs_f64(),
                    up.mem_id.unwrap_or(0),
                    up.bytes(),
                    up.writes(),
                    up.packets,
                    up.repeats
                );
            }
        }
        Ok(upload_pk)
    }

    /// The high-level commander flies its own plan: each phase's command three times (a
    /// command is not acknowledged, and a repeat 10 ms later changes nothing). The phase that
    /// holds the hover point: the high-level pilot's hold, the trajectory pilot's upload.
    pub fn high_level(
        &mut self,
        link: &Link,
        args: &Args,
        phase: &'static str,
        setpoint_now: bool,
        link_up: bool,
    ) {
        let hl_hold_phase = match args.pilot {
            Pilot::HighLevel => Some("hold"),
            Pilot::Trajectory if link_up => Some("upload"),
            _ => None,
        };
        if let (true, Some(hold_phase)) = (setpoint_now, hl_hold_phase) {
            if self.hl_phase.0 != phase {
                self.hl_phase = (phase, 0);
            }
            let pk = match phase {
                "takeoff" => Some(hl_takeoff_packet(self.hover_m.z, self.yaw0, args.takeoff_s)),
                p if p == hold_phase => Some(hl_go_to_packet(&self.hover_m, self.yaw0, 1.0)),
                "land" => Some(hl_land_packet(0.0, self.yaw0, args.land_s)),
                "stop" => Some(hl_stop_packet()),
                _ => None,
            };
            if let (Some(pk), true) = (pk, self.hl_phase.1 < 3) {
                link.send(&pk);
                self.hl_phase.1 += 1;
            }
        }
    }

    /// `--pilot trajectory`, in the "trajectory" phase: the upload must be done;
    /// start_trajectory once (a repeat would restart it), relative to the hover point; its
    /// answer within 100 ms, else sent again (up to three times).
    pub fn start_trajectory(
        &mut self,
        link: &Link,
        args: &Args,
        t: f64,
        phase: &str,
        link_up: bool,
    ) -> Result<()> {
        if args.pilot == Pilot::Trajectory && link_up && phase == "trajectory" {
            if let Some(up) = &self.upload {
                if !up.done() {
                    bail!(
                        "the trajectory upload did not finish within --upload-s {} s \
                         (plant t = {t:.3} s): {}",
                        args.upload_s,
                        up.status()
                    );
                }
            }
            let answer = link
                .shared
                .lock()
                .unwrap()
                .hl_answers
                .iter()
                .find(|a| a.0 == HL_CMD_START_TRAJECTORY)
                .copied();
            match (answer, self.traj_start) {
                (Some((_, 0)), _) => {
                    self.traj_start_answered.get_or_insert(t);
                }
                (Some((_, e)), _) => {
                    bail!("start_trajectory refused by the firmware (error {e})")
                }
                (None, Some((t0, n))) if n >= 3 && t - t0 >= 0.1 => {
                    bail!("start_trajectory not answered after 3 sends 100 ms apart")
                }
                (None, Some((t0, n))) if t - t0 >= 0.1 => {
                    self.traj_start = Some((t, n + 1));
                }
                (None, None) => self.traj_start = Some((t, 1)),
                (None, Some(_)) => {}
            }
            if self.traj_start.is_some_and(|s| s.0 == t) {
                let pk = hl_start_trajectory_packet(0, args.traj_time_scale as f32, true, false);
                link.send(&pk);
            }
        }
        Ok(())
    }

    /// `--pilot stream`: the setpoint as cflib streams it (`--setpoint`); after the flight, the
    /// stop setpoint five times.
    pub fn stream(
        &mut self,
        link: &Link,
        args: &Args,
        phase: &str,
        setpoint: &Option<TrajectoryPoint>,
        setpoint_now: bool,
    ) {
        if setpoint_now && args.pilot == Pilot::Stream {
            match setpoint {
                Some(sp) => {
                    let pk = match args.setpoint {
                        SetpointKind::FullState => full_state_setpoint_packet(
                            &sp.p_m,
                            &sp.v_m_s,
                            &sp.a_m_s2,
                            sp.yaw_rad,
                            sp.yaw_rate_rad_s,
                        ),
                        SetpointKind::FullStateRates => full_state_setpoint_packet_with_rates(
                            &sp.p_m,
                            &sp.v_m_s,
                            &sp.a_m_s2,
                            sp.yaw_rad,
                            &flatness_body_rates(
                                &sp.a_m_s2,
                                &sp.j_m_s3,
                                sp.yaw_rad,
                                sp.yaw_rate_rad_s,
                            ),
                        ),
                        SetpointKind::Position => {
                            position_setpoint_packet(&sp.p_m, sp.yaw_rad.to_degrees())
                        }
                    };
                    link.send(&pk);
                }
                None if phase == "stop" && self.stop_sent < 5 => {
                    link.send(&stop_setpoint_packet());
                    self.stop_sent += 1;
                }
                None => {}
            }
        }
    }
}
