/*
 * hamflight.h: the C API of the hamflight flight core (libhamflight_bitcraze.a).
 *
 * The learned port-Hamiltonian model and the adaptive IDA-PBC law of "Physics-guided
 * Learning-based Adaptive Control on the SE(3) Manifold" (Duong & Atanasov), in Rust, behind a
 * small C ABI. The weights are compiled into the library (flash), so there is nothing to load.
 *
 * Conventions (those of the core, see src/model/state.rs and src/reference.rs):
 *   - SI units throughout: m, m/s, m/s^2, rad, rad/s, N, N*m, s.
 *   - World frame: z up (ENU-like, as the Crazyflie estimators use). Body frame: x forward,
 *     y left, z up (the Crazyflie's body frame).
 *   - rot[i][j] is entry (row i, column j) of R, the rotation that maps body-frame vectors to the
 *     world frame (columns of R are the body axes in world coordinates).
 *   - Velocities and angular velocities of the state are in the BODY frame; positions and the
 *     whole setpoint are in the WORLD frame.
 *
 * Threading: a controller is plain memory; calls on one controller must not overlap (the
 * Crazyflie calls it only from the stabilizer task). The functions never allocate, never block
 * and never panic; NULL pointers are reported, never dereferenced.
 *
 * A test (firmware/bitcraze-app/src/abi.rs, `header_layout_matches_rust`) compiles this header
 * with the host C compiler and checks every size, offset and constant below against the Rust
 * definitions, so the two cannot drift apart silently.
 */
#ifndef HAMFLIGHT_H
#define HAMFLIGHT_H

#include <stdbool.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Number of disturbance features p: the length of the adaptation estimate a. */
#define HF_FEATURES 6

/* Bytes of opaque storage a controller needs (the Rust side asserts its state fits). */
#define HF_CONTROLLER_STORAGE_BYTES 1816

/* ---- Fault and condition flags (hf_output_t.faults, hf_last_faults) ----
 * Any bit of HF_FAULT_MASK means the output is a zero wrench (motors off).
 * The HF_COND_* bits are conditions: the output is still valid and used. */
#define HF_FAULT_BAD_STATE (1u << 0)      /* a state component was NaN or infinite */
#define HF_FAULT_BAD_SETPOINT (1u << 1)   /* a setpoint component was NaN or infinite */
#define HF_FAULT_BAD_DT (1u << 2)         /* dt_s was not in (0, 0.1] s */
#define HF_FAULT_NUMERIC (1u << 3)        /* the model or the law produced a non-finite value */
#define HF_FAULT_NOT_INIT (1u << 4)       /* NULL pointer, or the controller was never hf_init'ed */
#define HF_FAULT_MASK 0x1Fu
#define HF_COND_SAT_YAW (1u << 8)         /* our mixer would scale yaw torque down */
#define HF_COND_SAT_ROLL_PITCH (1u << 9)  /* our mixer would scale roll/pitch torque down */
#define HF_COND_SAT_THRUST (1u << 10)     /* our mixer would shift the collective thrust */
#define HF_COND_TILT_LIMITED (1u << 11)   /* the tilt limit shaped the desired attitude */

/* Return values of hf_set_gains. */
#define HF_OK 0u
#define HF_ERR_BAD_GAINS 1u  /* a gain was NaN, infinite, negative, or max_tilt_rad not in (0, pi/2) */
#define HF_ERR_NULL 2u       /* NULL pointer, or the controller was never hf_init'ed */

/* Why a weight blob was refused (hf_blob_check, hf_model_load): one code per check of the
 * core's blob decoder (src/blob.rs), in file order, then the self test; the port terms' check
 * (format version 4) came later and has the next code. */
#define HF_ERR_BLOB_TRUNCATED 16u   /* shorter than its header says */
#define HF_ERR_BLOB_BAD_MAGIC 17u   /* not "HMFW" */
#define HF_ERR_BLOB_VERSION 18u     /* a format version this build cannot read */
#define HF_ERR_BLOB_SHAPE 19u       /* network shapes differ from this build's */
#define HF_ERR_BLOB_CRC 20u         /* the body's CRC-32 does not match */
#define HF_ERR_BLOB_TRAILING 21u    /* bytes after the CRC */
#define HF_ERR_BLOB_MALFORMED 22u   /* the body is not the expected parameters */
#define HF_ERR_BLOB_NON_FINITE 23u  /* a NaN or infinite parameter */
#define HF_ERR_BLOB_MASS 24u        /* mass outside 0.005..5 kg */
#define HF_ERR_BLOB_MOTOR_TAU 25u   /* motor time constant outside 0..1 s */
#define HF_ERR_SELF_TEST 26u        /* decoded, but its hover step fails the self test */
#define HF_ERR_BLOB_PORT 27u        /* port terms that cannot fly (gain, lag, negative dissipation) */

/* The largest weight blob this build reads (a current-version one), bytes. */
#define HF_BLOB_MAX_BYTES 9820u
/* Bytes of the upload slot (hf_model_t): max(HF_BLOB_MAX_BYTES, the decoded model), 8-aligned. */
#define HF_MODEL_STORAGE_BYTES 9824

/* Adaptation laws (hf_set_law). */
#define HF_LAW_GRADIENT 0u   /* the paper's gradient law on the tracking errors */
#define HF_LAW_COMPOSITE 1u  /* the composite law: also the model's prediction error, Kalman gain */

/* Opaque controller storage. Zero it (static storage is) or call hf_init before any other call:
 * a zeroed controller reports HF_FAULT_NOT_INIT and gives a zero wrench. */
typedef struct hf_controller {
  _Alignas(8) uint8_t opaque[HF_CONTROLLER_STORAGE_BYTES];
} hf_controller_t;

/* The vehicle state x = (q, zeta) as the core wants it (paper Sec. 2). 88 bytes. */
typedef struct hf_state {
  float p_m[3];          /* position p (m), world frame */
  float rot[3][3];       /* attitude R, body to world; rot[i][j] = R_ij */
  float v_body_m_s[3];   /* linear velocity v (m/s), BODY frame: v = R^T * (world velocity) */
  float w_body_rad_s[3]; /* angular velocity omega (rad/s), body frame (the gyro) */
  /* Measured specific force (accelerometer) in the body frame (m/s^2): what an IMU at rest
   * reads is +9.81 along body z. Passed to FlightController::step_measured: the composite
   * adaptation law uses it (velocity differences when invalid); the default gradient law does not. */
  float specific_force_body_m_s2[3];
  uint8_t specific_force_valid; /* nonzero: specific_force_body_m_s2 holds a measurement */
  uint8_t reserved[3];          /* zero */
} hf_state_t;

/* A flat-output setpoint (world frame). 56 bytes. */
typedef struct hf_setpoint {
  float p_m[3];          /* desired position p* (m) */
  float v_m_s[3];        /* desired velocity (m/s) */
  float a_m_s2[3];       /* desired acceleration (m/s^2), gravity not included */
  float j_m_s3[3];       /* desired jerk (m/s^3) */
  float yaw_rad;         /* desired yaw psi* (rad) about world z */
  float yaw_rate_rad_s;  /* desired yaw rate (rad/s) */
} hf_setpoint_t;

/* What one step produces. 20 bytes. */
typedef struct hf_output {
  float thrust_n;        /* collective thrust along body z (N); 0 on a fault */
  float torque_nm[3];    /* body torques about x, y, z (N*m); 0 on a fault */
  uint32_t faults;       /* HF_FAULT_* | HF_COND_* */
} hf_output_t;

/* Gains and adaptation rates (the core's Gains; defaults documented in src/control.rs). 40 bytes. */
typedef struct hf_gains {
  float k_p;           /* position stiffness (N/m) */
  float k_v;           /* velocity damping (N*s/m) */
  float k_r;           /* attitude stiffness (N*m/rad) */
  float k_w;           /* angular damping (N*m*s/rad) */
  float max_tilt_rad;  /* largest tilt of the desired thrust axis from world z (rad), (0, pi/2) */
  float c_p;           /* adaptation rate on the position error */
  float c_v;           /* adaptation rate on the velocity error */
  float c_r;           /* adaptation rate on the rotation error */
  float c_w;           /* adaptation rate on the angular-velocity error */
  float a_max;         /* projection radius: |a| never exceeds it */
} hf_gains_t;

/* The composite law's Kalman tuning, in the units of a (force features m/s^2, torque features
 * 1e-3 N*m). 16 bytes. */
typedef struct hf_composite {
  float q_force;   /* process noise Q of the force columns of a, per second (>= 0) */
  float q_torque;  /* process noise Q of the torque columns of a, per second (>= 0) */
  float r_force;   /* measurement variance R of the force rows, per sample (> 0) */
  float r_torque;  /* measurement variance R of the torque rows, per sample (> 0) */
} hf_composite_t;

/* The slot of a model received at run time: first the blob's bytes (write them into opaque[]),
 * then the model hf_model_load decodes from them in place. HF_MODEL_STORAGE_BYTES is the larger
 * of HF_BLOB_MAX_BYTES and the decoded model, 8-byte aligned. Zeroed (static storage is): empty.
 * It must outlive every controller that flies it (a static of the shim), and its bytes may be
 * written only while no controller flies it. */
typedef struct hf_model {
  _Alignas(8) uint8_t opaque[HF_MODEL_STORAGE_BYTES];
} hf_model_t;

/* What a checked weight blob says of itself. 16 bytes. */
typedef struct hf_blob_info {
  uint32_t crc;              /* CRC-32 of the body, as stored in the blob */
  uint32_t total_len_bytes;  /* the whole blob: header, body, CRC */
  float mass_kg;             /* the vehicle mass */
  uint16_t version;          /* the blob's format version */
  uint16_t reserved;         /* zero */
} hf_blob_info_t;

/* Initialise: the compiled-in model, default gains, adaptation on, a = 0. NULL is ignored. */
void hf_init(hf_controller_t *ctl);

/* Reset the adaptation estimate (a = 0). Gains and the adaptation switch are kept. */
void hf_reset(hf_controller_t *ctl);

/* One control step of length dt_s (s): the IDA-PBC wrench, then one step of the adaptation law
 * (if on). Writes *out (a zero wrench with HF_FAULT_* set on any fault) and returns out->faults.
 * out may not be NULL (if it is, nothing is written and HF_FAULT_NOT_INIT is returned). */
uint32_t hf_step(hf_controller_t *ctl, const hf_state_t *state, const hf_setpoint_t *setpoint,
                 float dt_s, hf_output_t *out);

/* Copy the gains into *out (zeros if ctl is not initialised). */
void hf_get_gains(const hf_controller_t *ctl, hf_gains_t *out);

/* Set the gains; HF_OK, or HF_ERR_BAD_GAINS / HF_ERR_NULL with the gains left unchanged. */
uint32_t hf_set_gains(hf_controller_t *ctl, const hf_gains_t *gains);

/* Select the adaptation law (HF_LAW_*): HF_OK, HF_ERR_BAD_GAINS for another value, HF_ERR_NULL.
 * A change of law resets the adaptation (a = 0, P restarted); the same law is a no-op. Switch
 * only while not flying: the shim applies hamflight.law only off the air. */
uint32_t hf_set_law(hf_controller_t *ctl, uint32_t law);
/* The law in use (HF_LAW_GRADIENT if ctl is not initialised). */
uint32_t hf_get_law(const hf_controller_t *ctl);

/* The composite law's Q and R: HF_OK, or HF_ERR_BAD_GAINS (Q < 0, R <= 0, NaN, infinite) /
 * HF_ERR_NULL with the tuning unchanged. Takes effect at the next step, whichever law runs. */
uint32_t hf_set_composite(hf_controller_t *ctl, const hf_composite_t *tuning);
/* Copy the composite law's Q and R into *out (zeros if ctl is not initialised). */
void hf_get_composite(const hf_controller_t *ctl, hf_composite_t *out);

/* The composite law's prediction error of its last update, eps = measured - predicted
 * disturbance force in the units of a, rows force x, y, z (m/s^2) then torque x, y, z
 * (1e-3 N*m); false (and zeros) before its first update, after a reset and under the gradient
 * law. */
bool hf_get_prediction_error(const hf_controller_t *ctl, float eps[6]);
/* The trace of the composite law's gain P (0 before its first update and after a reset). */
float hf_p_trace(const hf_controller_t *ctl);

/* Switch the adaptation law on or off (off freezes a; it does not reset it). */
void hf_set_adapt(hf_controller_t *ctl, bool on);
bool hf_get_adapt(const hf_controller_t *ctl);

/* Copy the adaptation estimate a (force features in m/s^2, torque features in 1e-3 N*m). */
void hf_get_estimate(const hf_controller_t *ctl, float a[HF_FEATURES]);

/* The faults and conditions of the last hf_step (HF_FAULT_NOT_INIT if none or not initialised). */
uint32_t hf_last_faults(const hf_controller_t *ctl);

/* One hover step of ctl itself with its model's default gains: true if it has no fault and its
 * thrust is within 20 % of m*g. Then ctl's gains are restored and a = 0. False if ctl is not
 * initialised. Only while nothing else steps ctl (the shim: in its app task, before the
 * stabilizer may use ctl, and in a swap). Needs a step's stack, no scratch controller. */
bool hf_self_test(hf_controller_t *ctl);

/* The compiled-in weight blob: its file name (NUL-terminated) and its body CRC-32 (IEEE). */
const char *hf_model_name(void);
uint32_t hf_model_crc(void);

/* The vehicle mass (kg) the model was built for. */
float hf_mass_kg(void);

/* ---- Weights received at run time (the shim's MEM_TYPE_APP upload) ----
 * All three never allocate and never panic; NULL pointers give HF_ERR_NULL. */

/* Every check of the blob decoder (format, version, shapes, length, CRC, finiteness, mass,
 * motor lag) on len bytes, writing nothing but *info (when HF_OK; info may be NULL). Small
 * stack: the shim runs it in the memory task. HF_OK or an HF_ERR_BLOB_* code. */
uint32_t hf_blob_check(const uint8_t *bytes, uint32_t len, hf_blob_info_t *info);

/* Decodes the blob held in the first len bytes of model->opaque, in place: every check of
 * hf_blob_check first, then the parameter block is moved down to where the model keeps it and
 * the scalars are written. HF_OK or an HF_ERR_BLOB_* code; on any error *model is left empty
 * (no controller may fly it) and the blob's bytes are gone. *model must not be in use by a
 * controller. No self test: hf_use_model runs it. */
uint32_t hf_model_load(hf_model_t *model, uint32_t len, hf_blob_info_t *info);

/* Flies ctl with *model (NULL: the compiled-in model), then runs hf_self_test on ctl: the gains
 * become the new model's defaults for its mass (hf_get_gains gives them), the law, the composite
 * tuning and the adaptation switch are kept, a = 0. HF_OK; HF_ERR_SELF_TEST if the self test
 * failed (ctl then flies the compiled-in model); HF_ERR_NULL (ctl not initialised, or *model
 * empty) with ctl unchanged. Only while not flying. */
uint32_t hf_use_model(hf_controller_t *ctl, const hf_model_t *model);

#ifdef __cplusplus
}
#endif

#endif /* HAMFLIGHT_H */
