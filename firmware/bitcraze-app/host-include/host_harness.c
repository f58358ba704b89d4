/*
 * host_harness.c: drives the real hamflight_oot.c on the host the way crazyflie-firmware's
 * stabilizer does, and implements the stubs of the stand-in headers. Host tests only (see
 * README.md); the Rust tests declare these functions in host-train/tests/bitcraze_oot/ffi.rs.
 */
#define _POSIX_C_SOURCE 200809L

#include <pthread.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

#include "app.h"
#include "controller.h"
#include "hf_host_registry.h"
#include "mem.h"
#include "stabilizer_types.h"
#include "stm32f4xx.h"
#include "supervisor.h"
#include "task.h"

/* ---- stubs ---- */

static bool canFly;
static bool isFlying;

bool supervisorCanFly(void) { return canFly; }
bool supervisorIsFlying(void) { return isFlying; }

char *pcTaskGetName(void *task) {
  (void)task;
  static char name[] = "SYSTEM";
  return name;
}

/* hf_host_stall_app_task: while on, the app task (appMain's thread) does not come back from
 * vTaskDelay, as a starved task would not. */
static pthread_t appThread;
static bool appStarted;
static pthread_mutex_t stallMutex = PTHREAD_MUTEX_INITIALIZER;
static pthread_cond_t stallCond = PTHREAD_COND_INITIALIZER;
static bool stalled;

void vTaskDelay(const TickType_t ticks) {
  const struct timespec ts = {(time_t)(ticks / 1000u), (long)(ticks % 1000u) * 1000000L};
  nanosleep(&ts, NULL);
  if (appStarted && pthread_equal(pthread_self(), appThread)) {
    pthread_mutex_lock(&stallMutex);
    while (stalled) {
      pthread_cond_wait(&stallCond, &stallMutex);
    }
    pthread_mutex_unlock(&stallMutex);
  }
}

/* ---- the memory subsystem: the one handler the shim registers, driven as crtp_mem.c's
 * memory task drives it (memId, address, length, buffer) ---- */

static const MemoryHandlerDef_t *memHandler;
static int memRegistrations;

void memoryRegisterHandler(const MemoryHandlerDef_t *handlerDef) {
  memHandler = handlerDef;
  memRegistrations++;
}

/* The registered handler's type (-1: none) and how often a handler was registered. */
int hf_host_mem_type(void) { return memHandler ? (int)memHandler->type : -1; }
int hf_host_mem_registrations(void) { return memRegistrations; }
uint32_t hf_host_mem_size(void) {
  return memHandler ? memHandler->getSize(memHandler->internal_id) : 0u;
}

/* A read or write packet of the memory protocol: false is the EIO status the client gets. */
bool hf_host_mem_read(uint32_t addr, uint8_t len, uint8_t *buffer) {
  return memHandler && memHandler->read &&
         memHandler->read(memHandler->internal_id, addr, len, buffer);
}
bool hf_host_mem_write(uint32_t addr, uint8_t len, const uint8_t *buffer) {
  return memHandler && memHandler->write &&
         memHandler->write(memHandler->internal_id, addr, len, buffer);
}

/* ---- the app task ---- */

static void *appTaskMain(void *arg) {
  (void)arg;
  appMain();
  return NULL;
}

/* Starts appMain (the shim's app task: boot self test, model swaps) in a thread, once per
 * process. */
void hf_host_start_app_task(void) {
  if (!appStarted) {
    appStarted = pthread_create(&appThread, NULL, appTaskMain, NULL) == 0;
  }
}

/* While on, the app task hangs in its next vTaskDelay (a starved task). */
void hf_host_stall_app_task(bool on) {
  pthread_mutex_lock(&stallMutex);
  stalled = on;
  pthread_cond_broadcast(&stallCond);
  pthread_mutex_unlock(&stallMutex);
}

static hf_host_dwt_t dwt;
hf_host_core_debug_t hf_host_core_debug;

hf_host_dwt_t *hf_host_dwt(void) {
  struct timespec ts;
  if ((dwt.CTRL & DWT_CTRL_CYCCNTENA_Msk) && clock_gettime(CLOCK_MONOTONIC, &ts) == 0) {
    const uint64_t ns = (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
    dwt.CYCCNT = (uint32_t)(ns * 168u / 1000u);
  }
  return &dwt;
}

static char debugText[4096];
static size_t debugLen;

int hf_host_debug_printf(const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  const size_t room = sizeof(debugText) - debugLen;
  const int n = vsnprintf(debugText + debugLen, room, fmt, ap);
  va_end(ap);
  if (n > 0) {
    debugLen += ((size_t)n < room) ? (size_t)n : room - 1;
  }
  return n;
}

/* ---- the stabilizer's data ---- */

static state_t state;
static sensorData_t sensors;
static setpoint_t setpoint;
static control_t control;

void hf_host_reset(void) {
  memset(&state, 0, sizeof(state));
  memset(&sensors, 0, sizeof(sensors));
  memset(&setpoint, 0, sizeof(setpoint));
  memset(&control, 0, sizeof(control));
  state.attitudeQuaternion.w = 1.0f;
  canFly = false;
  isFlying = false;
  debugLen = 0;
  debugText[0] = '\0';
}

void hf_host_set_supervisor(bool can_fly, bool is_flying) {
  canFly = can_fly;
  isFlying = is_flying;
}

/* The estimate as Bitcraze's estimators give it: position (m), quaternion (x, y, z, w) body to
 * world, world velocity (m/s); the IMU as the sensors task gives it: gyro (deg/s), acc (G). */
void hf_host_set_state(const float p[3], const float q_xyzw[4], const float v_world[3],
                       const float gyro_deg_s[3], const float acc_g[3]) {
  state.position.x = p[0];
  state.position.y = p[1];
  state.position.z = p[2];
  state.attitudeQuaternion.x = q_xyzw[0];
  state.attitudeQuaternion.y = q_xyzw[1];
  state.attitudeQuaternion.z = q_xyzw[2];
  state.attitudeQuaternion.w = q_xyzw[3];
  state.velocity.x = v_world[0];
  state.velocity.y = v_world[1];
  state.velocity.z = v_world[2];
  sensors.gyro.x = gyro_deg_s[0];
  sensors.gyro.y = gyro_deg_s[1];
  sensors.gyro.z = gyro_deg_s[2];
  sensors.acc.x = acc_g[0];
  sensors.acc.y = acc_g[1];
  sensors.acc.z = acc_g[2];
}

/* A setpoint as the commander gives it. modes: x, y, z, yaw (0 disable, 1 abs, 2 velocity). */
void hf_host_set_setpoint(const int modes[4], const float p[3], const float v[3], const float a[3],
                          const float j[3], float yaw_deg, float yaw_rate_deg_s, float thrust,
                          bool velocity_body) {
  memset(&setpoint, 0, sizeof(setpoint));
  setpoint.mode.x = (stab_mode_t)modes[0];
  setpoint.mode.y = (stab_mode_t)modes[1];
  setpoint.mode.z = (stab_mode_t)modes[2];
  setpoint.mode.yaw = (stab_mode_t)modes[3];
  setpoint.position.x = p[0];
  setpoint.position.y = p[1];
  setpoint.position.z = p[2];
  setpoint.velocity.x = v[0];
  setpoint.velocity.y = v[1];
  setpoint.velocity.z = v[2];
  setpoint.acceleration.x = a[0];
  setpoint.acceleration.y = a[1];
  setpoint.acceleration.z = a[2];
  setpoint.jerk.x = j[0];
  setpoint.jerk.y = j[1];
  setpoint.jerk.z = j[2];
  setpoint.attitude.yaw = yaw_deg;
  setpoint.attitudeRate.yaw = yaw_rate_deg_s;
  setpoint.thrust = thrust;
  setpoint.velocity_body = velocity_body;
}

/* The attitude part of the setpoint hf_host_set_setpoint made (call it after that one): the
 * modes of roll, pitch and the quaternion (0 disable, 1 abs, 2 velocity), the body rates roll
 * and pitch (deg/s; the yaw rate is hf_host_set_setpoint's) and the quaternion (x, y, z, w), as
 * crtp_commander_generic.c's full-state decoder and the high-level commander fill them. */
void hf_host_set_setpoint_attitude(const int modes_rpq[3], float roll_rate_deg_s,
                                   float pitch_rate_deg_s, const float q_xyzw[4]) {
  setpoint.mode.roll = (stab_mode_t)modes_rpq[0];
  setpoint.mode.pitch = (stab_mode_t)modes_rpq[1];
  setpoint.mode.quat = (stab_mode_t)modes_rpq[2];
  setpoint.attitudeRate.roll = roll_rate_deg_s;
  setpoint.attitudeRate.pitch = pitch_rate_deg_s;
  setpoint.attitudeQuaternion.x = q_xyzw[0];
  setpoint.attitudeQuaternion.y = q_xyzw[1];
  setpoint.attitudeQuaternion.z = q_xyzw[2];
  setpoint.attitudeQuaternion.w = q_xyzw[3];
}

/* The commander's null setpoint (no setpoint for too long, or a stop). */
void hf_host_set_null_setpoint(void) { memset(&setpoint, 0, sizeof(setpoint)); }

/* One stabilizer tick: calls the controller, then reports control_t: thrustSi, torque[0..2]
 * into wrench[0..3]; returns controlMode. */
int hf_host_tick(uint32_t tick, float wrench[4]) {
  controllerOutOfTree(&control, &setpoint, &sensors, &state, tick);
  wrench[0] = control.thrustSi;
  wrench[1] = control.torque[0];
  wrench[2] = control.torque[1];
  wrench[3] = control.torque[2];
  return (int)control.controlMode;
}

/* ---- params and logs by name ---- */

#define HF_HOST_MAX_GROUPS 8

static const struct hf_host_var *paramGroups[HF_HOST_MAX_GROUPS];
static const struct hf_host_var *logGroups[HF_HOST_MAX_GROUPS];

void hf_host_register(int param, const struct hf_host_var *group) {
  const struct hf_host_var **groups = param ? paramGroups : logGroups;
  for (int i = 0; i < HF_HOST_MAX_GROUPS; i++) {
    if (groups[i] == NULL) {
      groups[i] = group;
      return;
    }
  }
}

/* The address of parameter (param nonzero) or log variable group.name, with its type in *type;
 * NULL if there is none. */
void *hf_host_find(int param, const char *group, const char *name, uint32_t *type) {
  const struct hf_host_var *const *groups = param ? paramGroups : logGroups;
  for (int i = 0; i < HF_HOST_MAX_GROUPS && groups[i] != NULL; i++) {
    const struct hf_host_var *v = groups[i];
    if (strcmp(v->name, group) != 0) {
      continue;
    }
    for (v++; v->type != HF_HOST_GROUP_STOP; v++) {
      if (strcmp(v->name, name) == 0) {
        if (type) {
          *type = v->type;
        }
        return v->address;
      }
    }
  }
  return NULL;
}

const char *hf_host_debug_text(void) { return debugText; }
