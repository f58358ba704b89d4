//! Files and links (layer 1): atomic writing, the flight log, the uSD-card deck log, the dataset
//! and CrazySim's UDP link to the SITL Crazyflie firmware (`crtp`).
//!
//! Front door: code outside `host-train/src` imports these from here, never from a submodule
//! (`tools/front-door.py` checks it): [`write_atomic`], [`write_json_atomic`]; [`FlightLog`];
//! the loop logs' [`LoopFlight`], [`read_loop_csv`], [`read_loop_dir`] and the onboard records
//! [`OnboardState`], [`OnboardSetpoint`], [`MotorCommands`];
//! the dataset's [`Dataset`], [`Flight`], [`Realization`], [`RealizationMeta`], [`Sample`],
//! [`VehicleDescription`], [`WindowSpec`], [`load_dataset`], [`load_dataset_manifest`],
//! [`save_dataset`], [`dataset_windows`], [`sample_segments`], [`realization_file`],
//! [`DATASET_FORMAT`], [`DATASET_FORMAT_V1`], [`DATASET_CSV_HEADER`] (`dataset::{load,
//! load_manifest, save, windows, segments, FORMAT, FORMAT_V1, CSV_HEADER}`); the uSD log's
//! [`parse_usd`] (`usdlog::parse`), [`ParseOptions`], [`UsdError`], [`UsdWriter`], [`Var`],
//! [`VarType`], [`EventType`], [`crc32`], [`FIXED_FREQUENCY_ID`], [`LEE_COMMAND_VARS`],
//! [`USD_STATE_VARS`], [`USD_ACC_VARS`]; the firmware link's packets ([`imu_packet`], [`parse_motor`],
//! [`full_state_setpoint_packet`], [`flatness_body_rates`], [`CrtpSetpoint`], ...: the list
//! below), and its lock-step
//! ([`CrtpLockstep`], [`CrtpTick`], [`parse_tick_done`], [`crtp_await_handshake`]); the
//! high-level commander's uploaded trajectories ([`Poly4d`], [`poly4d_trajectory_eval`],
//! [`crtp_mem_write_packets`], [`parse_crtp_mem_answer`], [`hl_define_trajectory_packet`],
//! [`hl_start_trajectory_packet`], [`parse_hl_answer`], ...).

pub mod crtp;
pub mod dataset;
pub mod files;
pub mod flightlog;
pub mod loop_log;
pub mod usdlog;

// The layer's front door: what code outside host-train/src uses, by these names.
pub use crtp::{
    await_handshake as crtp_await_handshake, parse_tick_done, tick_done_packet,
    Lockstep as CrtpLockstep, Tick as CrtpTick, CH_SIM_TICK_DONE as CRTP_CH_SIM_TICK_DONE,
};
pub use crtp::{
    ext_pose_packet, flatness_body_rates, force_to_pwm, full_state_setpoint_packet,
    full_state_setpoint_packet_with_rates, header as crtp_header, hl_go_to_packet, hl_land_packet,
    hl_stop_packet, hl_takeoff_packet, imu_packet, motor_packet, param_toc_request,
    param_write_float, param_write_u8, parse_ext_pose, parse_imu, parse_motor, parse_param_answer,
    parse_setpoint, port_channel as crtp_port_channel, position_setpoint_packet, pwm_to_force_n,
    pwm_to_rpm, quat_compress, quat_decompress, stop_setpoint_packet, ParamAnswer,
    Setpoint as CrtpSetpoint, DEG_PER_LSB as IMU_DEG_PER_LSB, G_PER_LSB as IMU_G_PER_LSB,
    HANDSHAKE as CRTP_HANDSHAKE, PORT_COMMANDER_GENERIC as CRTP_PORT_COMMANDER_GENERIC,
    PORT_LOCALIZATION as CRTP_PORT_LOCALIZATION, PORT_PARAM as CRTP_PORT_PARAM,
    PORT_SETPOINT_HL as CRTP_PORT_SETPOINT_HL, PORT_SIM as CRTP_PORT_SIM,
};
// The high-level commander's uploaded trajectories: the memory port and the poly4d pieces.
pub use crtp::{
    hl_define_trajectory_packet, hl_start_trajectory_packet,
    mem_count_request as crtp_mem_count_request, mem_info_request as crtp_mem_info_request,
    mem_read_request as crtp_mem_read_request, mem_write_packet as crtp_mem_write_packet,
    mem_write_packets as crtp_mem_write_packets, parse_hl_answer,
    parse_mem_answer as parse_crtp_mem_answer, poly4d_trajectory_eval, MemAnswer as CrtpMemAnswer,
    Poly4d, PolyEval as Poly4dEval, HL_TRAJECTORY_IDS, MEM_CHUNK as CRTP_MEM_CHUNK,
    MEM_TYPE_TRAJ as CRTP_MEM_TYPE_TRAJ, POLY4D_BYTES, PORT_MEM as CRTP_PORT_MEM,
    TRAJECTORY_MEMORY_BYTES,
};
pub use dataset::{
    load as load_dataset, load_manifest as load_dataset_manifest, realization_file,
    save as save_dataset, segments as sample_segments, windows as dataset_windows, Dataset, Flight,
    Realization, RealizationMeta, Sample, VehicleDescription, WindowSpec,
};
pub use dataset::{
    CSV_HEADER as DATASET_CSV_HEADER, FORMAT as DATASET_FORMAT, FORMAT_V1 as DATASET_FORMAT_V1,
};
pub use files::{write_atomic, write_json_atomic};
pub use flightlog::FlightLog;
pub use loop_log::{
    read_loop_csv, read_loop_dir, LoopFlight, MotorCommands, OnboardSetpoint, OnboardState,
};
pub use usdlog::{
    crc32, parse as parse_usd, EventType, ParseOptions, UsdError, UsdWriter, Var, VarType,
    FIXED_FREQUENCY_ID, LEE_COMMAND_VARS, USD_ACC_VARS, USD_STATE_VARS,
};
