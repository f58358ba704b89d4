//! The flight's record: one sample every 10 ms, written as flight.csv and drawn as flight.svg.

use std::io::Write;
use std::path::Path;

use anyhow::Result;
use nalgebra::Vector3;
use plotters::prelude::*;

/// One logged sample (every 10 ms of plant time).
pub struct Sample {
    pub t_s: f64,
    pub phase: &'static str,
    pub p: Vector3<f64>,
    pub sp: Vector3<f64>,
    pub rpy_deg: Vector3<f64>,
    pub pwm: [u16; 4],
    pub wall_s: f64,
}

pub fn write_csv(path: &Path, samples: &[Sample]) -> Result<()> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(
        f,
        "t_s,wall_s,phase,x,y,z,sp_x,sp_y,sp_z,err_m,roll_deg,pitch_deg,yaw_deg,m1,m2,m3,m4"
    )?;
    for s in samples {
        writeln!(
            f,
            "{:.3},{:.4},{},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.3},{:.3},{:.3},{},{},{},{}",
            s.t_s,
            s.wall_s,
            s.phase,
            s.p.x,
            s.p.y,
            s.p.z,
            s.sp.x,
            s.sp.y,
            s.sp.z,
            (s.p - s.sp).norm(),
            s.rpy_deg.x,
            s.rpy_deg.y,
            s.rpy_deg.z,
            s.pwm[0],
            s.pwm[1],
            s.pwm[2],
            s.pwm[3]
        )?;
    }
    Ok(())
}

pub fn plot(path: &Path, samples: &[Sample], name: &str) -> Result<()> {
    let pe = |e: &dyn std::fmt::Debug| anyhow::anyhow!("plotting failed: {e:?}");
    let flown: Vec<&Sample> = samples.iter().filter(|s| s.sp.x.is_finite()).collect();
    if flown.is_empty() {
        return Ok(());
    }
    let (t0, t1) = (flown[0].t_s, flown[flown.len() - 1].t_s);
    let zmax = flown.iter().map(|s| s.p.z.max(s.sp.z)).fold(0.1, f64::max) * 1.1;
    let emax = flown
        .iter()
        .map(|s| (s.p - s.sp).norm() * 100.0)
        .fold(1.0, f64::max)
        * 1.1;
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1000, 700)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| pe(&e))?;
        let (top, bottom) = root.split_vertically(350);
        let mut c = ChartBuilder::on(&top)
            .caption(
                format!("{name}: Crazyflie firmware (SITL) + hamflight on the host-train plant"),
                ("sans-serif", 18),
            )
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(50)
            .build_cartesian_2d(t0..t1, -0.1..zmax)
            .map_err(|e| pe(&e))?;
        c.configure_mesh()
            .x_desc("plant time (s)")
            .y_desc("z (m)")
            .draw()
            .map_err(|e| pe(&e))?;
        c.draw_series(LineSeries::new(
            flown.iter().map(|s| (s.t_s, s.sp.z)),
            &RGBColor(120, 120, 120),
        ))
        .map_err(|e| pe(&e))?
        .label("setpoint z")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(120, 120, 120)));
        c.draw_series(LineSeries::new(
            flown.iter().map(|s| (s.t_s, s.p.z)),
            &RGBColor(31, 119, 180),
        ))
        .map_err(|e| pe(&e))?
        .label("flown z")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(31, 119, 180)));
        c.configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|e| pe(&e))?;
        let mut c = ChartBuilder::on(&bottom)
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(50)
            .build_cartesian_2d(t0..t1, 0.0..emax)
            .map_err(|e| pe(&e))?;
        c.configure_mesh()
            .x_desc("plant time (s)")
            .y_desc("|p - p_sp| (cm)")
            .draw()
            .map_err(|e| pe(&e))?;
        c.draw_series(LineSeries::new(
            flown.iter().map(|s| (s.t_s, (s.p - s.sp).norm() * 100.0)),
            &RGBColor(214, 39, 40),
        ))
        .map_err(|e| pe(&e))?;
        root.present().map_err(|e| pe(&e))?;
    }
    std::fs::write(path, buf)?;
    Ok(())
}
