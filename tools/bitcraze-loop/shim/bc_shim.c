/*
 * hamflight's flat C face of Bitcraze's own flight code, for the bitcraze-loop study.
 *
 * Compiled by build.rs together with the Kalman core, the sensor low-pass filter, the four
 * controllers (PID, Mellinger, Lee, Brescianini) and the quadrotor power distribution of a
 * crazyflie-firmware checkout ($CRAZYFLIE_BASE). Nothing of Bitcraze's is copied here: this file
 * only calls their functions the way their estimator task and stabilizer loop do, and defines
 * the few CMSIS-DSP routines their code needs (arm_math.h beside this file).
 */
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "arm_math.h"
#include "cf_math.h"
#include "math3d.h"
#include "physicalConstants.h"
#include "axis3fSubSampler.h"
#include "controller_brescianini.h"
#include "controller_lee.h"
#include "controller_mellinger.h"
#include "controller_pid.h"
#include "filter.h"
#include "kalman_core.h"
#include "mm_pose.h"
#include "mm_position.h"
#include "platform_defaults.h"
#include "power_distribution.h"
#include "stabilizer_types.h"

/* ---- CMSIS-DSP stand-ins (row-major, as CMSIS) ---- */

arm_status arm_mat_trans_f32(const arm_matrix_instance_f32 *src, arm_matrix_instance_f32 *dst) {
  if (src->numRows != dst->numCols || src->numCols != dst->numRows) return ARM_MATH_SIZE_MISMATCH;
  for (int i = 0; i < src->numRows; i++)
    for (int j = 0; j < src->numCols; j++)
      dst->pData[j * dst->numCols + i] = src->pData[i * src->numCols + j];
  return ARM_MATH_SUCCESS;
}

arm_status arm_mat_mult_f32(const arm_matrix_instance_f32 *a, const arm_matrix_instance_f32 *b,
                            arm_matrix_instance_f32 *dst) {
  if (a->numCols != b->numRows || dst->numRows != a->numRows || dst->numCols != b->numCols)
    return ARM_MATH_SIZE_MISMATCH;
  for (int i = 0; i < a->numRows; i++)
    for (int j = 0; j < b->numCols; j++) {
      float s = 0.0f;
      for (int k = 0; k < a->numCols; k++) s += a->pData[i * a->numCols + k] * b->pData[k * b->numCols + j];
      dst->pData[i * dst->numCols + j] = s;
    }
  return ARM_MATH_SUCCESS;
}

arm_status arm_mat_scale_f32(const arm_matrix_instance_f32 *src, float32_t scale,
                             arm_matrix_instance_f32 *dst) {
  if (src->numRows != dst->numRows || src->numCols != dst->numCols) return ARM_MATH_SIZE_MISMATCH;
  for (int i = 0; i < src->numRows * src->numCols; i++) dst->pData[i] = src->pData[i] * scale;
  return ARM_MATH_SUCCESS;
}

/* Gauss-Jordan with partial pivoting; src is overwritten, as CMSIS does. */
arm_status arm_mat_inverse_f32(const arm_matrix_instance_f32 *src, arm_matrix_instance_f32 *dst) {
  int n = src->numRows;
  if (n != src->numCols || dst->numRows != n || dst->numCols != n) return ARM_MATH_SIZE_MISMATCH;
  float *a = src->pData, *x = dst->pData;
  for (int i = 0; i < n * n; i++) x[i] = (i / n == i % n) ? 1.0f : 0.0f;
  for (int c = 0; c < n; c++) {
    int p = c;
    for (int r = c + 1; r < n; r++)
      if (fabsf(a[r * n + c]) > fabsf(a[p * n + c])) p = r;
    if (a[p * n + c] == 0.0f) return ARM_MATH_SINGULAR;
    for (int k = 0; k < n; k++) {
      float t = a[c * n + k]; a[c * n + k] = a[p * n + k]; a[p * n + k] = t;
      t = x[c * n + k]; x[c * n + k] = x[p * n + k]; x[p * n + k] = t;
    }
    float d = a[c * n + c];
    for (int k = 0; k < n; k++) { a[c * n + k] /= d; x[c * n + k] /= d; }
    for (int r = 0; r < n; r++) {
      if (r == c) continue;
      float f = a[r * n + c];
      for (int k = 0; k < n; k++) { a[r * n + k] -= f * a[c * n + k]; x[r * n + k] -= f * x[c * n + k]; }
    }
  }
  return ARM_MATH_SUCCESS;
}

arm_status arm_sqrt_f32(float32_t in, float32_t *out) {
  if (in >= 0.0f) { *out = sqrtf(in); return ARM_MATH_SUCCESS; }
  *out = 0.0f;
  return ARM_MATH_ARGUMENT_ERROR;
}

float32_t arm_cos_f32(float32_t x) { return cosf(x); }
float32_t arm_sin_f32(float32_t x) { return sinf(x); }

void assertFail(char *exp, char *file, int line) {
  fprintf(stderr, "bitcraze assert failed: %s at %s:%d\n", exp, file, line);
  abort();
}

/* ---- The state every controller sees ---- */

/* Bitcraze's state_t, field by field, with the units it documents. */
typedef struct {
  float p_m[3];
  float v_m_s[3];
  float q_xyzw[4];
  float rpy_deg[3]; /* legacy CF2 convention: pitch inverted */
  float acc_g[3];   /* world, gravity removed */
} hf_bc_state;

static void state_to_bc(const hf_bc_state *s, state_t *out) {
  memset(out, 0, sizeof *out);
  out->position.x = s->p_m[0]; out->position.y = s->p_m[1]; out->position.z = s->p_m[2];
  out->velocity.x = s->v_m_s[0]; out->velocity.y = s->v_m_s[1]; out->velocity.z = s->v_m_s[2];
  out->attitudeQuaternion.x = s->q_xyzw[0]; out->attitudeQuaternion.y = s->q_xyzw[1];
  out->attitudeQuaternion.z = s->q_xyzw[2]; out->attitudeQuaternion.w = s->q_xyzw[3];
  out->attitude.roll = s->rpy_deg[0]; out->attitude.pitch = s->rpy_deg[1]; out->attitude.yaw = s->rpy_deg[2];
  out->acc.x = s->acc_g[0]; out->acc.y = s->acc_g[1]; out->acc.z = s->acc_g[2];
}

static void state_from_bc(const state_t *s, hf_bc_state *out) {
  out->p_m[0] = s->position.x; out->p_m[1] = s->position.y; out->p_m[2] = s->position.z;
  out->v_m_s[0] = s->velocity.x; out->v_m_s[1] = s->velocity.y; out->v_m_s[2] = s->velocity.z;
  out->q_xyzw[0] = s->attitudeQuaternion.x; out->q_xyzw[1] = s->attitudeQuaternion.y;
  out->q_xyzw[2] = s->attitudeQuaternion.z; out->q_xyzw[3] = s->attitudeQuaternion.w;
  out->rpy_deg[0] = s->attitude.roll; out->rpy_deg[1] = s->attitude.pitch; out->rpy_deg[2] = s->attitude.yaw;
  out->acc_g[0] = s->acc.x; out->acc_g[1] = s->acc.y; out->acc_g[2] = s->acc.z;
}

/* ---- The sensor task's low-pass filters (gyro and accelerometer, per axis) ---- */

typedef struct {
  lpf2pData gyro[3];
  lpf2pData acc[3];
} hf_bc_imu_filter;

hf_bc_imu_filter *hf_bc_imu_filter_new(float sample_hz, float gyro_cutoff_hz, float acc_cutoff_hz) {
  hf_bc_imu_filter *f = calloc(1, sizeof *f);
  if (!f) return NULL;
  for (int i = 0; i < 3; i++) {
    lpf2pInit(&f->gyro[i], sample_hz, gyro_cutoff_hz);
    lpf2pInit(&f->acc[i], sample_hz, acc_cutoff_hz);
  }
  return f;
}

void hf_bc_imu_filter_free(hf_bc_imu_filter *f) { free(f); }

/* In place: acc (g) and gyro (deg/s), body frame. */
void hf_bc_imu_filter_apply(hf_bc_imu_filter *f, float acc_g[3], float gyro_dps[3]) {
  for (int i = 0; i < 3; i++) {
    acc_g[i] = lpf2pApply(&f->acc[i], acc_g[i]);
    gyro_dps[i] = lpf2pApply(&f->gyro[i], gyro_dps[i]);
  }
}

/* ---- The Kalman estimator, driven as estimator_kalman.c's task drives it ---- */

#define HF_BC_PREDICT_MS 10 /* the task's 100 Hz prediction */

typedef struct {
  kalmanCoreData_t core;
  kalmanCoreParams_t params;
  Axis3fSubSampler_t acc;
  Axis3fSubSampler_t gyro;
  Axis3f acc_latest;
  uint32_t next_prediction_ms;
  state_t ext;
} hf_bc_kalman;

/* A pose (position, optionally attitude) from a motion-capture-like source. */
typedef struct {
  float p_m[3];
  float q_xyzw[4];
  float std_pos_m;
  float std_quat;
  int with_attitude;
} hf_bc_pose;

hf_bc_kalman *hf_bc_kalman_new(uint32_t now_ms, const float p0_m[3], float yaw0_rad) {
  hf_bc_kalman *k = calloc(1, sizeof *k);
  if (!k) return NULL;
  kalmanCoreDefaultParams(&k->params);
  k->params.initialX = p0_m[0];
  k->params.initialY = p0_m[1];
  k->params.initialZ = p0_m[2];
  k->params.initialYaw = yaw0_rad;
  axis3fSubSamplerInit(&k->acc, GRAVITY_MAGNITUDE);
  axis3fSubSamplerInit(&k->gyro, DEG_TO_RAD);
  kalmanCoreInit(&k->core, &k->params, now_ms);
  k->next_prediction_ms = now_ms + HF_BC_PREDICT_MS;
  return k;
}

void hf_bc_kalman_free(hf_bc_kalman *k) { free(k); }

/* One filtered IMU sample into the prediction's sub-samplers (acc in g, gyro in deg/s). */
void hf_bc_kalman_imu(hf_bc_kalman *k, const float acc_g[3], const float gyro_dps[3]) {
  Axis3f a = {.x = acc_g[0], .y = acc_g[1], .z = acc_g[2]};
  Axis3f g = {.x = gyro_dps[0], .y = gyro_dps[1], .z = gyro_dps[2]};
  axis3fSubSamplerAccumulate(&k->acc, &a);
  axis3fSubSamplerAccumulate(&k->gyro, &g);
  k->acc_latest = a;
}

/* One 1 kHz iteration of the estimator task: predict when due, process noise, the measurements
 * that arrived (`pose` may be NULL), finalize, externalize. Returns 0 if the core's state left
 * its bounds (the task would reset it; so do we). */
int hf_bc_kalman_step(hf_bc_kalman *k, uint32_t now_ms, int flying, const hf_bc_pose *pose,
                      hf_bc_state *out) {
  if (now_ms >= k->next_prediction_ms) {
    axis3fSubSamplerFinalize(&k->acc);
    axis3fSubSamplerFinalize(&k->gyro);
    kalmanCorePredict(&k->core, &k->params, &k->acc.subSample, &k->gyro.subSample, now_ms, flying != 0);
    k->next_prediction_ms = now_ms + HF_BC_PREDICT_MS;
  }
  kalmanCoreAddProcessNoise(&k->core, &k->params, now_ms);
  if (pose) {
    if (pose->with_attitude) {
      poseMeasurement_t m;
      memset(&m, 0, sizeof m);
      m.x = pose->p_m[0]; m.y = pose->p_m[1]; m.z = pose->p_m[2];
      m.quat.x = pose->q_xyzw[0]; m.quat.y = pose->q_xyzw[1];
      m.quat.z = pose->q_xyzw[2]; m.quat.w = pose->q_xyzw[3];
      m.stdDevPos = pose->std_pos_m;
      m.stdDevQuat = pose->std_quat;
      kalmanCoreUpdateWithPose(&k->core, &m);
    } else {
      positionMeasurement_t m;
      memset(&m, 0, sizeof m);
      m.x = pose->p_m[0]; m.y = pose->p_m[1]; m.z = pose->p_m[2];
      m.stdDev = pose->std_pos_m;
      kalmanCoreUpdateWithPosition(&k->core, &m);
    }
  }
  kalmanCoreFinalize(&k->core);
  int ok = 1;
  for (int i = 0; i < KC_STATE_DIM; i++) {
    float s = k->core.S[i];
    float lim = (i <= KC_STATE_Z) ? 100.0f : (i <= KC_STATE_PZ ? 10.0f : 1e3f);
    if (!isfinite(s) || fabsf(s) > lim) ok = 0;
  }
  kalmanCoreExternalizeState(&k->core, &k->ext, &k->acc_latest);
  state_from_bc(&k->ext, out);
  return ok;
}

/* ---- Controllers and power distribution ---- */

enum { HF_BC_PID = 0, HF_BC_MELLINGER = 1, HF_BC_LEE = 2, HF_BC_BRESCIANINI = 3 };

typedef struct {
  float p_m[3];
  float v_m_s[3];
  float a_m_s2[3];
  float j_m_s3[3];
  float yaw_deg;
} hf_bc_setpoint;

typedef struct {
  int kind;
  controllerMellinger_t mellinger;
  controllerLee_t lee;
  control_t control; /* held between the controller's own execution ticks */
} hf_bc_ctrl;

/* PID and Brescianini keep file-static state in Bitcraze's code: one flight at a time. */
hf_bc_ctrl *hf_bc_ctrl_new(int kind, float mass_kg) {
  hf_bc_ctrl *c = calloc(1, sizeof *c);
  if (!c) return NULL;
  c->kind = kind;
  switch (kind) {
    case HF_BC_PID: controllerPidInit(); break;
    case HF_BC_MELLINGER: controllerMellingerInit(&c->mellinger); c->mellinger.mass = mass_kg; break;
    case HF_BC_LEE: controllerLeeInit(&c->lee); c->lee.mass = mass_kg; break;
    case HF_BC_BRESCIANINI: controllerBrescianiniInit(); break;
    default: free(c); return NULL;
  }
  return c;
}

void hf_bc_ctrl_free(hf_bc_ctrl *c) { free(c); }

/* Bitcraze's power distribution and capping: control → per-motor thrust (N), through the
 * uint16 command it would write to the motors (a fraction of THRUST_MAX). Returns 1 if capped. */
static int distribute(const control_t *control, float motor_n[4]) {
  motors_thrust_uncapped_t unc;
  motors_thrust_pwm_t pwm;
  memset(&unc, 0, sizeof unc);
  memset(&pwm, 0, sizeof pwm);
  powerDistribution(control, &unc);
  int capped = powerDistributionCap(&unc, &pwm) ? 1 : 0;
  for (int i = 0; i < 4; i++) motor_n[i] = (float)pwm.list[i] / 65535.0f * THRUST_MAX;
  return capped;
}

/* One stabilizer tick (1 kHz) of a Bitcraze controller on the state `st` and the filtered
 * sensors, then power distribution. Returns 1 if the motors were capped. */
int hf_bc_ctrl_step(hf_bc_ctrl *c, const hf_bc_setpoint *sp, const float acc_g[3],
                    const float gyro_dps[3], const hf_bc_state *st, uint32_t tick, float motor_n[4]) {
  setpoint_t s;
  memset(&s, 0, sizeof s);
  s.mode.x = s.mode.y = s.mode.z = modeAbs;
  s.mode.yaw = modeAbs;
  s.mode.roll = s.mode.pitch = modeDisable;
  s.mode.quat = modeDisable;
  s.position.x = sp->p_m[0]; s.position.y = sp->p_m[1]; s.position.z = sp->p_m[2];
  s.velocity.x = sp->v_m_s[0]; s.velocity.y = sp->v_m_s[1]; s.velocity.z = sp->v_m_s[2];
  s.acceleration.x = sp->a_m_s2[0]; s.acceleration.y = sp->a_m_s2[1]; s.acceleration.z = sp->a_m_s2[2];
  s.jerk.x = sp->j_m_s3[0]; s.jerk.y = sp->j_m_s3[1]; s.jerk.z = sp->j_m_s3[2];
  s.attitude.yaw = sp->yaw_deg;
  s.velocity_body = false;
  s.timestamp = tick;

  sensorData_t sd;
  memset(&sd, 0, sizeof sd);
  sd.acc.x = acc_g[0]; sd.acc.y = acc_g[1]; sd.acc.z = acc_g[2];
  sd.gyro.x = gyro_dps[0]; sd.gyro.y = gyro_dps[1]; sd.gyro.z = gyro_dps[2];

  state_t state;
  state_to_bc(st, &state);
  const stabilizerStep_t step = tick;
  switch (c->kind) {
    case HF_BC_PID: controllerPid(&c->control, &s, &sd, &state, step); break;
    case HF_BC_MELLINGER: controllerMellinger(&c->mellinger, &c->control, &s, &sd, &state, step); break;
    case HF_BC_LEE: controllerLee(&c->lee, &c->control, &s, &sd, &state, step); break;
    case HF_BC_BRESCIANINI: controllerBrescianini(&c->control, &s, &sd, &state, step); break;
    default: break;
  }
  return distribute(&c->control, motor_n);
}

/* Power distribution of a wrench (N, N·m) in Bitcraze's force-torque mode: how the Crazyflie
 * app hands our controller's output to the motors. Returns 1 if capped. */
int hf_bc_power_force_torque(float thrust_n, const float torque_nm[3], float motor_n[4]) {
  control_t control;
  memset(&control, 0, sizeof control);
  control.controlMode = controlModeForceTorque;
  control.thrustSi = thrust_n;
  control.torqueX = torque_nm[0];
  control.torqueY = torque_nm[1];
  control.torqueZ = torque_nm[2];
  return distribute(&control, motor_n);
}

/* The platform facts Bitcraze's code assumes, for the study's table. */
void hf_bc_platform(float *arm_length_m, float *thrust_max_n, float *thrust2torque, float *cf_mass_kg) {
  *arm_length_m = ARM_LENGTH;
  *thrust_max_n = THRUST_MAX;
  *thrust2torque = THRUST2TORQUE;
  *cf_mass_kg = CF_MASS;
}
