//! The parameters set over CRTP before the take-off: the firmware's mixer constants
//! (`quadSysId.armLength`, `thrustToTorque`) set to the flown vehicle's and `--param`'s, found
//! by reading the parameter TOC, which also gives `kalman.resetEstimation`'s id for `--estimator-reset-s`.

use anyhow::{bail, Result};
use host_train::io::{param_toc_request, param_write_float, param_write_u8};
use host_train::Plant;

use crate::launch::Link;
use crate::Args;

pub struct Params {
    /// The parameters to set: the mixer's (none with `--stock-mixer`), then `--param`'s: full
    /// name, value, written as u8.
    pub mixer: Vec<(String, f32, bool)>,
    /// Their ids, from the TOC (scanned from id 0); then they are written by id.
    pub mixer_ids: Vec<Option<u16>>,
    toc_next: u16,
    toc_last_req: (u16, u64),
    /// When every mixer parameter's write was echoed (plant time).
    pub mixer_done_at: Option<f64>,
    /// `kalman.resetEstimation`'s id, once the TOC gave it.
    pub reset_id: Option<u16>,
}

impl Params {
    pub fn new(args: &Args, plant: &Plant) -> Self {
        // The firmware's mixer (quadSysId, read by power_distribution_sitl.c's force/torque
        // mode) configured for the vehicle it flies: arm·0.707 = the plant's rotor offset,
        // thrust-to-torque = km / kf.
        let mut mixer_params: Vec<(String, f32, bool)> = if args.stock_mixer {
            Vec::new()
        } else {
            vec![
                (
                    "quadSysId.armLength".into(),
                    (plant.params.arm_xy_m / std::f64::consts::FRAC_1_SQRT_2) as f32,
                    false,
                ),
                (
                    "quadSysId.thrustToTorque".into(),
                    (plant.params.km_nm_per_rpm2 / plant.params.kf_n_per_rpm2) as f32,
                    false,
                ),
            ]
        };
        mixer_params.extend(args.params.iter().cloned());
        Params {
            mixer_ids: vec![None; mixer_params.len()],
            mixer: mixer_params,
            toc_next: 0,
            toc_last_req: (u16::MAX, 0),
            mixer_done_at: None,
            reset_id: None,
        }
    }

    /// From the stabilizer loop's start (`stab_started_at`) until the mixer is set, every other
    /// millisecond: the TOC read item by item (a request repeated after 20 ms without its
    /// answer), then the writes (repeated every 20 ms until echoed). Fails if the TOC lacks a
    /// parameter, or after 30 s.
    pub fn set_up(
        &mut self,
        link: &Link,
        args: &Args,
        k: u64,
        t: f64,
        stab_started_at: Option<f64>,
    ) -> Result<()> {
        if let (Some(t0), None) = (stab_started_at, self.mixer_done_at) {
            if k.is_multiple_of(2) {
                let sh = link.shared.lock().unwrap();
                for (id, (name, ..)) in self.mixer_ids.iter_mut().zip(&self.mixer) {
                    if id.is_none() {
                        *id = sh.param_toc.iter().find(|(_, n)| n == name).map(|x| x.0);
                    }
                }
                if self.reset_id.is_none() {
                    self.reset_id = sh
                        .param_toc
                        .iter()
                        .find(|(_, n)| n == "kalman.resetEstimation")
                        .map(|x| x.0);
                }
                let toc_end = sh.param_toc_end;
                let have_next = sh.param_toc.iter().any(|x| x.0 == self.toc_next);
                let written: Vec<u16> = sh.param_written.iter().map(|w| w.0).collect();
                drop(sh);
                let need_reset = args.estimator_reset_s.is_some() && self.reset_id.is_none();
                if self.mixer_ids.iter().all(Option::is_some) && !need_reset {
                    let pending: Vec<(u16, f32, bool)> = self
                        .mixer_ids
                        .iter()
                        .zip(&self.mixer)
                        .filter_map(|(id, (_, v, u8))| id.map(|id| (id, *v, *u8)))
                        .filter(|(id, ..)| !written.contains(id))
                        .collect();
                    if pending.is_empty() {
                        self.mixer_done_at = Some(t);
                        println!(
                            "[{:6.2} s] mixer parameters set ({} TOC items read)",
                            link.t_start.elapsed().as_secs_f64(),
                            self.toc_next
                        );
                    } else if k.is_multiple_of(20) {
                        for (id, v, u8) in pending {
                            link.send(&if u8 {
                                param_write_u8(id, v as u8)
                            } else {
                                param_write_float(id, v)
                            });
                        }
                    }
                } else if toc_end && need_reset {
                    bail!("the firmware has no parameter kalman.resetEstimation");
                } else if toc_end {
                    let missing: Vec<&str> = self
                        .mixer_ids
                        .iter()
                        .zip(&self.mixer)
                        .filter(|(id, _)| id.is_none())
                        .map(|(_, p)| p.0.as_str())
                        .collect();
                    bail!("the firmware has no parameter {}", missing.join(", "));
                } else {
                    if have_next {
                        self.toc_next += 1;
                    }
                    if self.toc_last_req.0 != self.toc_next || k - self.toc_last_req.1 >= 20 {
                        link.send(&param_toc_request(self.toc_next));
                        self.toc_last_req = (self.toc_next, k);
                    }
                }
            }
            if t - t0 > args.settle_s + 30.0 {
                bail!("the mixer parameters were not set within 30 s");
            }
        }
        Ok(())
    }
}
