//! The study's logged training flights: hover, circles and spirals, calm and under wind.

use super::*;

/// One logged training flight: a trajectory and a disturbance on the study's vehicle.
#[derive(Clone, Debug)]
pub struct PlannedFlight {
    /// Short name (the log's file stem).
    pub name: &'static str,
    /// The path.
    pub trajectory: Trajectory,
    /// The disturbance (none for the calm flights).
    pub disturbance: DisturbanceSpec,
    /// Flown in calm air: imported with `--calm` (a_j = 0).
    pub calm: bool,
    /// Desired yaw rate (rad/s): excites the yaw axis, so that J_z is identifiable.
    pub yaw_rate_rad_s: f64,
}

fn wind(w: [f64; 3]) -> DisturbanceSpec {
    DisturbanceSpec {
        wind_m_s2: w,
        ..DisturbanceSpec::default()
    }
}

/// The logged flights: hover, circles and spirals, calm and under wind (see the module docs).
pub fn flight_plan() -> Vec<PlannedFlight> {
    let hover = |z: f64| Trajectory::Hover {
        position_m: [0.0, 0.0, z],
    };
    let circle = |r: f64, period: f64| Trajectory::Circle {
        center_m: [0.0, 0.0, 0.8],
        radius_m: r,
        period_s: period,
    };
    let spiral = |r: f64, period: f64, climb: f64| Trajectory::Spiral {
        center_m: [0.0, 0.0, 0.5],
        radius_m: r,
        period_s: period,
        climb_m_s: climb,
    };
    vec![
        PlannedFlight {
            name: "hover-calm",
            trajectory: hover(1.0),
            disturbance: DisturbanceSpec::default(),
            calm: true,
            yaw_rate_rad_s: 0.8,
        },
        PlannedFlight {
            name: "circle-calm",
            trajectory: circle(0.6, 6.0),
            disturbance: DisturbanceSpec::default(),
            calm: true,
            yaw_rate_rad_s: 0.0,
        },
        PlannedFlight {
            name: "spiral-calm",
            trajectory: spiral(0.4, 5.0, 0.04),
            disturbance: DisturbanceSpec::default(),
            calm: true,
            yaw_rate_rad_s: -0.4,
        },
        PlannedFlight {
            name: "hover-wind",
            trajectory: hover(0.8),
            disturbance: wind([0.5, -0.4, 0.0]),
            calm: false,
            yaw_rate_rad_s: -0.6,
        },
        PlannedFlight {
            name: "circle-wind",
            trajectory: circle(0.5, 8.0),
            disturbance: wind([-0.6, 0.3, 0.0]),
            calm: false,
            yaw_rate_rad_s: 0.5,
        },
        PlannedFlight {
            name: "spiral-wind",
            trajectory: spiral(0.5, 7.0, 0.03),
            disturbance: wind([0.4, 0.6, 0.0]),
            calm: false,
            yaw_rate_rad_s: 0.0,
        },
        PlannedFlight {
            name: "circle-gust",
            trajectory: circle(0.4, 5.0),
            disturbance: DisturbanceSpec {
                wind_sines: vec![WindSine {
                    amplitude_m_s2: [0.4, 0.0, 0.0],
                    frequency_hz: 0.3,
                    phase_rad: 0.0,
                }],
                wind_steps: vec![WindStep {
                    wind_m_s2: [0.0, 0.5, 0.0],
                    from_s: 3.0,
                    until_s: None,
                }],
                ..DisturbanceSpec::default()
            },
            calm: false,
            yaw_rate_rad_s: 0.3,
        },
        PlannedFlight {
            name: "spiral-weak-rotor",
            trajectory: spiral(0.5, 6.0, 0.02),
            disturbance: DisturbanceSpec {
                wind_m_s2: [-0.3, -0.5, 0.0],
                rotor_efficiency: [0.9, 1.0, 1.0, 1.0],
                ..DisturbanceSpec::default()
            },
            calm: false,
            yaw_rate_rad_s: 0.0,
        },
    ]
}
