/*
 * hamflight_oot.c: hamflight as the out-of-tree controller of Bitcraze's crazyflie-firmware.
 *
 * The stabilizer calls controllerOutOfTree() at every 1 kHz tick. This shim converts Bitcraze's
 * estimate and setpoint into the core's conventions (include/hamflight.h), runs the core at
 * 500 Hz (HAMFLIGHT_RATE_HZ = RATE_1000_HZ for 1 kHz), handles the flight phases and hands
 * Bitcraze's power distribution a force/torque command (controlModeForceTorque).
 *
 * Conversions (stabilizer_types.h):
 *   - attitude: state->attitudeQuaternion (x, y, z, w; body to world) -> R. state->attitude
 *     (degrees, legacy inverted pitch) is not used.
 *   - body rates: sensors->gyro (deg/s, body) -> rad/s.
 *   - velocity: state->velocity is world frame; the core wants body frame: v = R^T v_world.
 *   - accelerometer: sensors->acc (Gs, body) -> specific force in m/s^2, always marked valid:
 *     the composite adaptation law's force rows use it (hamflight.law = 1, the default); the
 *     paper's gradient law does not read it.
 *   - setpoint, per axis x, y, z (setpoint->mode.x/y/z):
 *       modeAbs      p* = position, with velocity, acceleration and jerk as feedforward (a
 *                    setpoint without jerk but with desired body rates, as a full-state one:
 *                    the jerk rebuilt from them, see setpointJerk);
 *       modeVelocity the velocity is integrated into p* (the cfclient joystick, cflib velocity
 *                    and hover commands), p* kept within `hamflight.leash` m of the estimate
 *                    so that it cannot run away from a vehicle that cannot follow; velocity is
 *                    the feedforward. velocity_body rotates (vx, vy) by the current yaw, as
 *                    Bitcraze's own position controller does;
 *       modeDisable  p* holds its last value on that axis (the position at engagement at
 *                    first). This controller has no attitude mode: roll/pitch setpoints of a
 *                    manual mode are not followed, the vehicle holds its position instead.
 *     yaw (setpoint->mode.yaw): modeAbs attitude.yaw (deg) with attitudeRate.yaw (deg/s) as
 *     feedforward; modeVelocity integrates attitudeRate.yaw; otherwise attitudeQuaternion's
 *     yaw if mode.quat is modeAbs, else the last yaw reference.
 *
 * Flight phases, at every executed tick:
 *   - OFF: !supervisorCanFly() (not armed, locked, crashed, tumbled), or a stop setpoint: z in
 *     modeDisable with thrust below 1000 (the commander's null setpoint when no setpoint
 *     arrives, cflib's stop and zero-thrust attitude setpoints). Output zero, adaptation reset,
 *     the next engagement starts over. Checked at every 1 kHz tick, not only at the control rate.
 *   - GROUND: engaged (the position and yaw at that tick become the reference until the setpoint
 *     says otherwise, and z_ground := the estimated z), not yet airborne. Output live,
 *     ADAPTATION FROZEN at a = 0.
 *   - AIRBORNE: latched once supervisorIsFlying() and z - z_ground >= `hamflight.airHeight`
 *     (0.05 m). Only then does the adaptation run (if `hamflight.adapt`), so that ground contact
 *     (the floor pushing back while thrust builds up) is never learned as a disturbance.
 *     supervisorIsFlying() alone is not enough: it turns true as soon as a motor spins over idle.
 *   - Touch-down: airborne, with the vehicle and its setpoint both within airHeight of z_ground
 *     (a landing), the adaptation is held (a kept, not learned), so that the floor pushing back
 *     is not learned either.
 *   - LANDED: airborne and supervisorIsFlying() turned false (Bitcraze says so after 2 s of low
 *     thrust): a is reset, back to GROUND with z_ground := the estimated z.
 *
 * Stack: the core's step runs inline, in the stabilizer task (1,800 bytes in all,
 * STABILIZER_TASK_STACKSIZE in Bitcraze's config.h). Its worst case, measured from the Rust
 * object by ci-check.sh (stack-estimate.py), is about 1.1 KB including controllerOutOfTree's
 * own frame; build-in-tree.sh checks controllerOutOfTree in the linked cf2.elf. The app task
 * (CONFIG_APP_STACKSIZE words, app-config) does what needs more: at boot hf_init (which builds
 * the controller in place, but the vehicle's default gains are too deep for the system task's
 * 1,200 B, where controllerOutOfTreeInit first runs) and hf_self_test(&ctl), which steps ctl
 * itself before the stabilizer may use it; later the model swaps of an upload or a revert
 * (decode in place and self test on ctl, about 2 ms, on the ground only).
 * controllerOutOfTreeInit stays light. Until the self test has passed, the output is zero with
 * HF_SHIM_NOT_READY in the faults log; during a swap the stabilizer does not touch the
 * controller and outputs zero with HF_SHIM_SWAPPING. The hand-over is one atomic byte (swapJob):
 * the stabilizer sets it, the app task polls it every HF_SWAP_POLL_MS and clears it when done.
 *
 * Parameters (group hamflight): kp kv kR kw maxTilt cp cv cR cw aMax (the core's gains and
 * adaptation rates, SI), adapt (0/1), reset (write 1: a = 0), airHeight (m), leash (m),
 * law (0 the paper's gradient law, 1 the composite law, the default; a write takes effect only while not
 * airborne, and resets a), qF qT rF rT (the composite law's Q and R: force and torque columns
 * and rows, in a's units; refused values revert).
 *
 * Weights over the radio (MEM_TYPE_APP, see "Upload" below and README.md): a client writes a
 * weight blob into a RAM slot; the memory task checks it at the commit; the app task decodes it
 * in place, self-tests it and makes it fly at the first tick the controller is not airborne.
 * Parameter revert (write 1) goes back to the compiled-in blob the same way. RAM only: every
 * boot flies the compiled-in blob.
 * Logs (group hamflight): a0..a5, faults (HF_FAULT_* | HF_COND_*), sat (bit 0 yaw, 1 roll/pitch,
 * 2 thrust, 3 tilt limit), phase (0 off, 1 ground, 2 airborne), thrust (N), tx ty tz (N*m),
 * cycles (DWT cycles of the last hf_step), law (the law in use), e0..e5 (the composite law's
 * prediction error: force rows m/s^2, torque rows 1e-3 N*m; 0 under the gradient law), pTrace
 * (the trace of its gain P).
 */
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <string.h>

/* controller.h declares the OOT entry points under CONFIG_CONTROLLER_OOT. */
#include "autoconf.h"

#include "FreeRTOS.h"
#include "app.h"
#include "controller.h"
#include "log.h"
#include "mem.h"
#include "param.h"
#include "stabilizer_types.h"
#include "stm32f4xx.h"
#include "static_mem.h"
#include "supervisor.h"
#include "task.h"

#define DEBUG_MODULE "HAMFLIGHT"
#include "debug.h"

#include "hamflight.h"

#ifndef HAMFLIGHT_RATE_HZ
#define HAMFLIGHT_RATE_HZ RATE_500_HZ
#endif
#if HAMFLIGHT_RATE_HZ != RATE_500_HZ && HAMFLIGHT_RATE_HZ != RATE_1000_HZ
#error "HAMFLIGHT_RATE_HZ must be RATE_500_HZ or RATE_1000_HZ"
#endif

/* 1: the weights upload over the radio (MEM_TYPE_APP, "Upload" below; 9.6 KB of RAM);
 * 0: compiled out (the revert parameter and the blob logs stay; the compiled-in blob flies). */
#ifndef HAMFLIGHT_UPLOAD
#define HAMFLIGHT_UPLOAD 1
#endif

/* The adaptation law at boot (the hamflight.law parameter's default): HF_LAW_GRADIENT or
 * HF_LAW_COMPOSITE. */
#ifndef HAMFLIGHT_DEFAULT_LAW
#define HAMFLIGHT_DEFAULT_LAW HF_LAW_COMPOSITE
#endif

/* The helpers controllerOutOfTree calls before the step stay out of line: their temporaries
 * then do not sit in its frame under the step's (see "Stack" at the top). */
#define HF_NOINLINE __attribute__((noinline))

#define HF_DT_S (1.0f / (float)HAMFLIGHT_RATE_HZ)
#define HF_DEG_TO_RAD 0.017453292519943295f
#define HF_PI 3.14159265358979f
/* Bitcraze's accelerometer unit (G) in m/s^2 (its GRAVITY_MAGNITUDE). */
#define HF_G_M_S2 9.81f
/* Below this setpoint thrust (Bitcraze's 0..65535 scale), a setpoint without z is a stop. */
#define HF_STOP_THRUST 1000.0f
#define HF_DEFAULT_LEASH_M 0.3f

/* Shim-level fault bit of the faults log: the app task's boot self test has not passed (yet,
 * or it failed): zero output. */
#define HF_SHIM_NOT_READY (1u << 16)
/* Shim-level bit of the faults log: the app task is swapping the model (zero output, on the
 * ground only). */
#define HF_SHIM_SWAPPING (1u << 17)
/* How often the app task looks for a swap to do (ms). */
#define HF_SWAP_POLL_MS 10

enum { HF_PHASE_OFF = 0, HF_PHASE_GROUND = 1, HF_PHASE_AIRBORNE = 2 };

static hf_controller_t ctl;
static bool isInit;
/* The step's inputs and the parameters' gains live in the core-coupled memory (CPU only, no DMA
 * touches them): their 184 B of RAM go to the app task's stack (app-config). */
NO_DMA_CCM_SAFE_ZERO_INIT static hf_state_t hfState;
NO_DMA_CCM_SAFE_ZERO_INIT static hf_setpoint_t hfSetpoint;
static hf_output_t hfOut;

/* Flight phase. */
static uint8_t phase = HF_PHASE_OFF;
static float groundZ;
/* The controller was stopped while airborne (see disengage). */
static bool offWhileAirborne;
/* The reference the setpoint modes build: position (world) and yaw. */
static float refP[3];
static float refYaw;

/* Parameters. */
NO_DMA_CCM_SAFE_ZERO_INIT static hf_gains_t gains;
static uint8_t adaptOn = 1;
static uint8_t resetRequest;
static float airborneHeightM = 0.05f;
static float leashM = HF_DEFAULT_LEASH_M;
static uint8_t lawParam = (uint8_t)HAMFLIGHT_DEFAULT_LAW;
static hf_composite_t composite;

/* Logs. */
static float logA[HF_FEATURES];
static uint32_t logFaults;
static uint8_t logSat;
static uint32_t logCycles;
static uint8_t logLaw;
static float logEps[6];
static float logPTrace;

/* ---- Upload: weights over the radio (MEM_TYPE_APP) ----
 *
 * Address layout of the memory (little-endian; cflib: cf.mem.get_mems(MemoryElement.TYPE_APP),
 * cf.mem.read / cf.mem.write, 24 bytes per packet):
 *   0x0000..0x003F  info, read-only (HF_UP_INFO_BYTES):
 *     0x00 u32 magic "HFUP"     0x04 u16 layout version (2)
 *     0x06 u8  active source (0 compiled-in, 1 uploaded)
 *     0x07 u8  upload state (HF_UP_*)        0x08 u32 active blob's CRC-32
 *     0x0C f32 active mass (kg)              0x10 u16 active blob's format version
 *     0x12 u8  last error (HF_ERR_BLOB_*, HF_ERR_SELF_TEST, HF_UP_ERR_BUSY_*; 0 none)
 *     0x13 u8  zero
 *     0x14 u32 capacity (HF_BLOB_MAX_BYTES)
 *     0x18 u32 length announced by the last BEGIN
 *     0x1C u32 CRC-32 of the last upload that passed the commit check (0 none)
 *     0x20 char[32] active blob's name, NUL-padded ("uploaded" for an upload)
 *   0x0040          control, write-only, one packet each:
 *     01 + u32 len  BEGIN: a new upload of len bytes (1..capacity); the slot is zeroed
 *     02            COMMIT: every byte has been sent; the memory task checks the bytes in the
 *                   slot (hf_blob_check: format, CRC, length, finiteness, mass, motor lag, port)
 *   0x1000 + off    data: writes fill the slot's bytes [off..] (only between BEGIN and COMMIT,
 *                   inside len; any order, repeats allowed); reads give them back from BEGIN
 *                   until the swap starts (RECEIVING, PENDING, REJECTED at the commit) and are
 *                   refused from then on: the swap decodes the bytes in place.
 * ONE slot (hf_model_t, HF_MODEL_STORAGE_BYTES) holds first the upload's bytes, then the model
 * that flies: the swap decodes it in place (hf_model_load moves the parameter block down over
 * the header), so an uploaded model that flies occupies the slot. Hence BEGIN while the state is
 * ACTIVE (an uploaded model flies):
 *   - airborne: refused, upError HF_UP_ERR_BUSY_FLYING ("busy: an uploaded model is flying;
 *     land first");
 *   - not airborne: refused, upError HF_UP_ERR_BUSY_REVERTING, and the compiled-in model is
 *     asked to fly again (as the revert parameter); once it does (state IDLE, within a few ticks
 *     and HF_SWAP_POLL_MS) a BEGIN is accepted. A client retries BEGIN until then.
 * While the compiled-in model flies, an upload works at any time, in flight too (the swap waits
 * for the ground).
 * The end of an upload is the COMMIT, not a byte count: a chunk that never arrived is a zero
 * in the slot and fails the CRC (a torn upload), and a blob whose own header length disagrees
 * with len fails the length check. Writes are refused (EIO to the client) outside a session
 * or the window, while the app task is swapping, and (BEGIN) while an uploaded model flies.
 * States: IDLE -> BEGIN -> RECEIVING -> COMMIT -> PENDING (checked) or REJECTED; PENDING ->
 * (first tick not airborne) SWAPPING -> ACTIVE, or REJECTED if the self test fails (the slot is
 * then zeroed and the compiled-in blob flies); ACTIVE -> (revert, or a BEGIN on the ground)
 * IDLE with the compiled-in blob flying. A new BEGIN while PENDING drops the pending upload. The
 * flying model is never touched by an upload: the slot is written only while it does not fly,
 * and it flies only after every check and the self test passed. */
#define HF_UP_INFO_BYTES 0x40u
#define HF_UP_CONTROL_ADDR 0x40u
#define HF_UP_DATA_ADDR 0x1000u
#define HF_UP_MAGIC 0x50554648u /* "HFUP" */
#define HF_UP_LAYOUT_VERSION 2u
#define HF_UP_CMD_BEGIN 1u
#define HF_UP_CMD_COMMIT 2u
enum {
  HF_UP_IDLE = 0,
  HF_UP_RECEIVING = 1,
  HF_UP_PENDING = 2,
  HF_UP_SWAPPING = 3,
  HF_UP_ACTIVE = 4,
  HF_UP_REJECTED = 5
};
/* Refusals of a BEGIN while an uploaded model flies (the info block's last error; above the
 * core's HF_ERR_* codes). */
#define HF_UP_ERR_BUSY_FLYING 64u    /* busy: an uploaded model is flying; land first */
#define HF_UP_ERR_BUSY_REVERTING 65u /* busy: handing back to the compiled-in model; retry BEGIN */
/* What the app task is asked to do (swapJob). */
enum { HF_JOB_NONE = 0, HF_JOB_LOAD = 1, HF_JOB_REVERT = 2 };

static uint8_t upState = HF_UP_IDLE; /* HF_UP_*, changed with __atomic (memory task, stabilizer) */
static uint8_t upError;
static uint8_t revertRequest; /* parameter: write 1 to fly the compiled-in blob again */
/* HF_JOB_*, with __atomic: set by the stabilizer (only when HF_JOB_NONE), cleared by the app
 * task when the swap is done. While it is not HF_JOB_NONE the app task owns the controller. */
static uint8_t swapJob = HF_JOB_NONE;
/* The app task's boot self test passed (__atomic). */
static bool ready;

static uint8_t jobLoad(void) { return __atomic_load_n(&swapJob, __ATOMIC_SEQ_CST); }
static void jobStore(uint8_t v) { __atomic_store_n(&swapJob, v, __ATOMIC_SEQ_CST); }
static bool swapping(void) { return jobLoad() != HF_JOB_NONE; }
static bool isReady(void) { return __atomic_load_n(&ready, __ATOMIC_SEQ_CST); }
/* The active blob (logs blobSrc, blobCrc). */
static uint8_t activeSource; /* 0 compiled-in, 1 uploaded */
static uint32_t activeCrc;
static float activeMassKg;
static uint16_t activeVersion;

static bool upSwap(uint8_t from, uint8_t to) {
  return __atomic_compare_exchange_n(&upState, &from, to, false, __ATOMIC_SEQ_CST,
                                     __ATOMIC_SEQ_CST);
}

/* The vehicle is airborne, or stopped in flight and still flying (see disengage). Read by the
 * memory task too (one byte each). */
static bool airborneNow(void) {
  return phase == HF_PHASE_AIRBORNE || (offWhileAirborne && supervisorIsFlying());
}

#if HAMFLIGHT_UPLOAD
/* RAM: the one slot (HF_MODEL_STORAGE_BYTES): the upload's bytes, then the model decoded from
 * them in place. */
static hf_model_t slot;
/* The slot holds the upload's bytes (from BEGIN until the swap decodes them): data reads. */
static bool slotHoldsBytes;
static uint32_t upLen;       /* announced by BEGIN */
static uint32_t upStagedCrc; /* of the last upload that passed the commit check */
static bool memRegistered;    /* the MEM_TYPE_APP handler is registered */
static uint8_t upLoad(void) { return __atomic_load_n(&upState, __ATOMIC_SEQ_CST); }
static void upStore(uint8_t v) { __atomic_store_n(&upState, v, __ATOMIC_SEQ_CST); }

static void putU32(uint8_t *b, uint32_t v) {
  b[0] = (uint8_t)v;
  b[1] = (uint8_t)(v >> 8);
  b[2] = (uint8_t)(v >> 16);
  b[3] = (uint8_t)(v >> 24);
}

static uint32_t upMemSize(const uint8_t internalId) {
  (void)internalId;
  return HF_UP_DATA_ADDR + HF_BLOB_MAX_BYTES;
}

static void upInfo(uint8_t info[HF_UP_INFO_BYTES]) {
  memset(info, 0, HF_UP_INFO_BYTES);
  putU32(&info[0x00], HF_UP_MAGIC);
  info[0x04] = (uint8_t)HF_UP_LAYOUT_VERSION;
  info[0x06] = activeSource;
  info[0x07] = upLoad();
  putU32(&info[0x08], activeCrc);
  uint32_t massBits;
  memcpy(&massBits, &activeMassKg, sizeof(massBits));
  putU32(&info[0x0C], massBits);
  info[0x10] = (uint8_t)activeVersion;
  info[0x11] = (uint8_t)(activeVersion >> 8);
  info[0x12] = upError;
  putU32(&info[0x14], HF_BLOB_MAX_BYTES);
  putU32(&info[0x18], upLen);
  putU32(&info[0x1C], upStagedCrc);
  const char *name = activeSource ? "uploaded" : hf_model_name();
  for (uint32_t i = 0; i < 31u && name[i] != '\0'; i++) {
    info[0x20 + i] = (uint8_t)name[i];
  }
}

/* The memory task reads: the info block or the slot's upload bytes, each whole within its region. */
static bool upMemRead(const uint8_t internalId, const uint32_t memAddr, const uint8_t readLen,
                      uint8_t *buffer) {
  (void)internalId;
  if (memAddr <= HF_UP_INFO_BYTES && readLen <= HF_UP_INFO_BYTES - memAddr) {
    uint8_t info[HF_UP_INFO_BYTES];
    upInfo(info);
    memcpy(buffer, &info[memAddr], readLen);
    return true;
  }
  if (memAddr >= HF_UP_DATA_ADDR && memAddr - HF_UP_DATA_ADDR <= HF_BLOB_MAX_BYTES &&
      readLen <= HF_BLOB_MAX_BYTES - (memAddr - HF_UP_DATA_ADDR) &&
      __atomic_load_n(&slotHoldsBytes, __ATOMIC_SEQ_CST) && upLoad() != HF_UP_SWAPPING) {
    memcpy(buffer, &slot.opaque[memAddr - HF_UP_DATA_ADDR], readLen);
    return true;
  }
  return false;
}

/* BEGIN: from any state but SWAPPING and ACTIVE (the slot flies: see "Upload"). Once the state
 * is RECEIVING no swap can start, so the slot is the memory task's until the COMMIT. */
static bool upBegin(uint32_t len) {
  if (len == 0u || len > HF_BLOB_MAX_BYTES) {
    return false;
  }
  uint8_t s = upLoad();
  do {
    if (s == HF_UP_SWAPPING) {
      return false;
    }
    if (s == HF_UP_ACTIVE) {
      if (airborneNow()) {
        upError = HF_UP_ERR_BUSY_FLYING;
      } else {
        upError = HF_UP_ERR_BUSY_REVERTING;
        revertRequest = 1; /* the stabilizer hands the app task a revert at its next tick */
      }
      return false;
    }
  } while (!__atomic_compare_exchange_n(&upState, &s, (uint8_t)HF_UP_RECEIVING, false,
                                        __ATOMIC_SEQ_CST, __ATOMIC_SEQ_CST));
  memset(&slot, 0, sizeof(slot));
  __atomic_store_n(&slotHoldsBytes, true, __ATOMIC_SEQ_CST);
  upLen = len;
  upError = 0;
  upStagedCrc = 0;
  return true;
}

/* COMMIT: the memory task checks the staged bytes (low priority: the flight never waits). */
static bool upCommit(void) {
  if (upLoad() != HF_UP_RECEIVING) {
    return false;
  }
  hf_blob_info_t info;
  const uint32_t err = hf_blob_check(slot.opaque, upLen, &info);
  if (err == HF_OK) {
    upStagedCrc = info.crc;
    upStore(HF_UP_PENDING);
    DEBUG_PRINT("upload of %u B checked, crc %08X: flies once not airborne\n",
                (unsigned int)upLen, (unsigned int)info.crc);
  } else {
    upError = (uint8_t)err;
    upStore(HF_UP_REJECTED);
    DEBUG_PRINT("upload of %u B rejected: error %u\n", (unsigned int)upLen, (unsigned int)err);
  }
  return true;
}

static bool upMemWrite(const uint8_t internalId, const uint32_t memAddr, const uint8_t writeLen,
                       const uint8_t *buffer) {
  (void)internalId;
  if (memAddr == HF_UP_CONTROL_ADDR && writeLen >= 1u) {
    if (buffer[0] == HF_UP_CMD_BEGIN && writeLen == 5u) {
      const uint32_t len = (uint32_t)buffer[1] | ((uint32_t)buffer[2] << 8) |
                           ((uint32_t)buffer[3] << 16) | ((uint32_t)buffer[4] << 24);
      return upBegin(len);
    }
    if (buffer[0] == HF_UP_CMD_COMMIT && writeLen == 1u) {
      return upCommit();
    }
    return false;
  }
  if (memAddr >= HF_UP_DATA_ADDR && upLoad() == HF_UP_RECEIVING &&
      memAddr - HF_UP_DATA_ADDR <= upLen && writeLen <= upLen - (memAddr - HF_UP_DATA_ADDR)) {
    memcpy(&slot.opaque[memAddr - HF_UP_DATA_ADDR], buffer, writeLen);
    return true;
  }
  return false;
}

static const MemoryHandlerDef_t upMemDef = {
    .type = MEM_TYPE_APP,
    .getSize = upMemSize,
    .read = upMemRead,
    .write = upMemWrite,
};
#endif /* HAMFLIGHT_UPLOAD */

static void setActiveBuiltin(void) {
  activeSource = 0;
  activeCrc = hf_model_crc();
  activeMassKg = hf_mass_kg();
  activeVersion = 0; /* compiled in: decoded at build time */
}

static void printActive(void) {
  const int massG = (int)(activeMassKg * 1000.0f + 0.5f);
  if (activeSource) {
    DEBUG_PRINT("active blob: uploaded crc %08X, %d g\n", (unsigned int)activeCrc, massG);
  } else {
    DEBUG_PRINT("active blob: compiled-in %s crc %08X, %d g\n", hf_model_name(),
                (unsigned int)activeCrc, massG);
  }
}

/* The app task's swap (HF_JOB_LOAD, HF_JOB_REVERT), with the controller to itself: the
 * stabilizer started it while not airborne and outputs zero until it is done. The self tests
 * (hf_use_model) step ctl itself: no scratch controller on this task's stack. */
static void serveSwap(uint8_t job) {
  (void)hf_use_model(&ctl, NULL); /* nothing flies the slot while it is loaded */
  setActiveBuiltin();
#if HAMFLIGHT_UPLOAD
  /* A revert (or a BEGIN on the ground) while an upload flew: the slot is free again. */
  (void)upSwap(HF_UP_ACTIVE, HF_UP_IDLE);
  if (job == HF_JOB_LOAD) {
    /* The bytes are decoded in place: from here on the data region reads are refused. */
    __atomic_store_n(&slotHoldsBytes, false, __ATOMIC_SEQ_CST);
    hf_blob_info_t info;
    uint32_t err = hf_model_load(&slot, upLen, &info);
    if (err == HF_OK) {
      err = hf_use_model(&ctl, &slot); /* the self test, on ctl; the compiled-in model if it fails */
    }
    if (err == HF_OK) {
      activeSource = 1;
      activeCrc = info.crc;
      activeMassKg = info.mass_kg;
      activeVersion = info.version;
      upStore(HF_UP_ACTIVE);
    } else {
      memset(&slot, 0, sizeof(slot)); /* empty: nothing may fly it */
      upError = (uint8_t)err;
      upStore(HF_UP_REJECTED);
      DEBUG_PRINT("upload rejected at load: error %u\n", (unsigned int)err);
    }
  }
#endif
  hf_get_gains(&ctl, &gains); /* the parameters follow the new model's gains */
  hf_set_adapt(&ctl, false);
  printActive();
}

/* One step of the core on the inputs in hfState/hfSetpoint: the only deep call, inline in the
 * stabilizer task. */
static void serveStep(void) {
  const uint32_t start = DWT->CYCCNT;
  hf_step(&ctl, &hfState, &hfSetpoint, HF_DT_S, &hfOut);
  logCycles = DWT->CYCCNT - start;
}

static void enableCycleCounter(void) {
  CoreDebug->DEMCR |= CoreDebug_DEMCR_TRCENA_Msk;
  DWT->CTRL |= DWT_CTRL_CYCCNTENA_Msk;
}

static void zeroWrench(void) {
  hfOut.thrust_n = 0.0f;
  hfOut.torque_nm[0] = 0.0f;
  hfOut.torque_nm[1] = 0.0f;
  hfOut.torque_nm[2] = 0.0f;
  hfOut.faults = 0;
}

static void zeroOutput(control_t *control) {
  control->controlMode = controlModeForceTorque;
  control->thrustSi = 0.0f;
  control->torque[0] = 0.0f;
  control->torque[1] = 0.0f;
  control->torque[2] = 0.0f;
  zeroWrench();
}

static void disengage(void) {
  hf_reset(&ctl);
  hf_set_adapt(&ctl, false);
  /* A stop in flight (a stop setpoint for one tick, e.g. cflib's on closing a link) must not make
   * the next engagement take the current height for the ground: it would never be airborne again
   * (no adaptation, swaps in flight). */
  offWhileAirborne = offWhileAirborne || phase == HF_PHASE_AIRBORNE;
  phase = HF_PHASE_OFF;
}

/* Hands the app task a pending swap (an upload that passed its check, or a revert) if the
 * vehicle is not airborne; true if it did (the caller outputs zero). */
static HF_NOINLINE bool startSwapIfDue(void) {
  if (!isInit || airborneNow() || swapping()) {
    return false;
  }
  uint8_t next;
  if (revertRequest) {
    revertRequest = 0;
    (void)upSwap(HF_UP_PENDING, HF_UP_IDLE); /* a revert also drops a pending upload */
    next = HF_JOB_REVERT;
  } else if (upSwap(HF_UP_PENDING, HF_UP_SWAPPING)) {
    next = HF_JOB_LOAD;
  } else {
    return false;
  }
  disengage(); /* the next engagement starts over with the new model */
  jobStore(next);
  return true;
}

static float wrapPi(float a) {
  if (!(fabsf(a) <= 64.0f)) {
    return 0.0f; /* non-finite or absurd: restart from 0 */
  }
  while (a > HF_PI) {
    a -= 2.0f * HF_PI;
  }
  while (a <= -HF_PI) {
    a += 2.0f * HF_PI;
  }
  return a;
}

/* R from a quaternion (x, y, z, w), body to world. With s = 2/|q|^2 the formula is exact for a
 * quaternion of any non-zero length; a degenerate one gives NaN, which the core reports as
 * HF_FAULT_BAD_STATE. */
static void quatToRot(float x, float y, float z, float w, float r[3][3]) {
  const float n2 = x * x + y * y + z * z + w * w;
  const float s = (n2 > 0.25f && n2 < 4.0f) ? 2.0f / n2 : NAN;
  r[0][0] = 1.0f - s * (y * y + z * z);
  r[0][1] = s * (x * y - z * w);
  r[0][2] = s * (x * z + y * w);
  r[1][0] = s * (x * y + z * w);
  r[1][1] = 1.0f - s * (x * x + z * z);
  r[1][2] = s * (y * z - x * w);
  r[2][0] = s * (x * z - y * w);
  r[2][1] = s * (y * z + x * w);
  r[2][2] = 1.0f - s * (x * x + y * y);
}

static float yawOfRot(const float r[3][3]) { return atan2f(r[1][0], r[0][0]); }

static HF_NOINLINE void convertState(const state_t *state, const sensorData_t *sensors, hf_state_t *s) {
  const quaternion_t *q = &state->attitudeQuaternion;
  quatToRot(q->x, q->y, q->z, q->w, s->rot);
  s->p_m[0] = state->position.x;
  s->p_m[1] = state->position.y;
  s->p_m[2] = state->position.z;
  const float vw[3] = {state->velocity.x, state->velocity.y, state->velocity.z};
  for (int i = 0; i < 3; i++) {
    /* (R^T v)_i = sum_j R_ji v_j */
    s->v_body_m_s[i] = s->rot[0][i] * vw[0] + s->rot[1][i] * vw[1] + s->rot[2][i] * vw[2];
  }
  s->w_body_rad_s[0] = sensors->gyro.x * HF_DEG_TO_RAD;
  s->w_body_rad_s[1] = sensors->gyro.y * HF_DEG_TO_RAD;
  s->w_body_rad_s[2] = sensors->gyro.z * HF_DEG_TO_RAD;
  s->specific_force_body_m_s2[0] = sensors->acc.x * HF_G_M_S2;
  s->specific_force_body_m_s2[1] = sensors->acc.y * HF_G_M_S2;
  s->specific_force_body_m_s2[2] = sensors->acc.z * HF_G_M_S2;
  s->specific_force_valid = 1;
}

static float clampf(float v, float lo, float hi) { return v < lo ? lo : (v > hi ? hi : v); }

/* The feed-forward jerk (world, m/s^3) of a setpoint, used on its modeAbs axes:
 *   - setpoint->jerk when it is not zero (Bitcraze's high-level commander fills it);
 *   - else, when x, y and z are all modeAbs and roll and pitch are modeDisable, the jerk rebuilt
 *     from the desired body rates attitudeRate.roll/pitch (deg/s) the setpoint carries as
 *     feed-forward: a full-state setpoint (cflib's send_full_state_setpoint, Crazyswarm's
 *     cmdFullState; crtp_commander_generic.c's fullStateDecoder sets the jerk to 0) and the
 *     high-level commander both send them. (With roll/pitch in modeVelocity they are a manual
 *     rate command, which this controller does not follow.) They are the flatness rates of
 *     pptraj.c's poly4d_eval (and Crazyswarm's uav_trajectory): z_b along t = a + g e3,
 *     y_b = z_b x (cos yaw, sin yaw, 0) normalised, x_b = y_b x z_b, h = the jerk's part across
 *     z_b over |t|, w_x = -h.y_b, w_y = h.x_b. The desired attitude's rate needs only that part:
 *     j = |t| (w_y x_b - w_x y_b). yaw is the shim's yaw reference (attitude.yaw, or the yaw of
 *     a full-state setpoint's quaternion);
 *   - zero rates (position, velocity and hover setpoints, a full-state setpoint without rates)
 *     give zero. */
static void setpointJerk(const setpoint_t *sp, const float acc[3], float yaw, float jerk[3]) {
  const float given[3] = {sp->jerk.x, sp->jerk.y, sp->jerk.z};
  for (int i = 0; i < 3; i++) {
    jerk[i] = given[i];
  }
  if (given[0] != 0.0f || given[1] != 0.0f || given[2] != 0.0f) {
    return;
  }
  if (sp->mode.x != modeAbs || sp->mode.y != modeAbs || sp->mode.z != modeAbs ||
      sp->mode.roll != modeDisable || sp->mode.pitch != modeDisable) {
    return;
  }
  const float wx = sp->attitudeRate.roll * HF_DEG_TO_RAD;
  const float wy = sp->attitudeRate.pitch * HF_DEG_TO_RAD;
  const float t[3] = {acc[0], acc[1], acc[2] + HF_G_M_S2}; /* pptraj.h's GRAV */
  const float tn = sqrtf(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
  if (!(tn > 1e-3f) || (wx == 0.0f && wy == 0.0f)) {
    return;
  }
  const float zb[3] = {t[0] / tn, t[1] / tn, t[2] / tn};
  const float xw[3] = {cosf(yaw), sinf(yaw), 0.0f};
  float yb[3] = {zb[1] * xw[2] - zb[2] * xw[1], zb[2] * xw[0] - zb[0] * xw[2],
                 zb[0] * xw[1] - zb[1] * xw[0]};
  const float yn = sqrtf(yb[0] * yb[0] + yb[1] * yb[1] + yb[2] * yb[2]);
  if (!(yn > 1e-6f)) {
    return; /* thrust along the heading: no body frame */
  }
  for (int i = 0; i < 3; i++) {
    yb[i] /= yn;
  }
  const float xb[3] = {yb[1] * zb[2] - yb[2] * zb[1], yb[2] * zb[0] - yb[0] * zb[2],
                       yb[0] * zb[1] - yb[1] * zb[0]};
  for (int i = 0; i < 3; i++) {
    jerk[i] = tn * (wy * xb[i] - wx * yb[i]);
  }
}

static HF_NOINLINE void convertSetpoint(const setpoint_t *sp, const hf_state_t *s, hf_setpoint_t *out) {
  /* Yaw. */
  float yawRate = 0.0f;
  if (sp->mode.yaw == modeAbs) {
    refYaw = wrapPi(sp->attitude.yaw * HF_DEG_TO_RAD);
    yawRate = sp->attitudeRate.yaw * HF_DEG_TO_RAD;
  } else if (sp->mode.yaw == modeVelocity) {
    yawRate = sp->attitudeRate.yaw * HF_DEG_TO_RAD;
    refYaw = wrapPi(refYaw + yawRate * HF_DT_S);
  } else if (sp->mode.quat == modeAbs) {
    const quaternion_t *q = &sp->attitudeQuaternion;
    float r[3][3];
    quatToRot(q->x, q->y, q->z, q->w, r);
    refYaw = wrapPi(yawOfRot(r));
  }
  out->yaw_rad = refYaw;
  out->yaw_rate_rad_s = yawRate;

  /* Position, per axis. */
  const stab_mode_t mode[3] = {sp->mode.x, sp->mode.y, sp->mode.z};
  const float pos[3] = {sp->position.x, sp->position.y, sp->position.z};
  const float acc[3] = {sp->acceleration.x, sp->acceleration.y, sp->acceleration.z};
  float jerk[3];
  setpointJerk(sp, acc, refYaw, jerk);
  float vel[3] = {sp->velocity.x, sp->velocity.y, sp->velocity.z};
  if (sp->velocity_body) {
    const float psi = yawOfRot(s->rot);
    const float c = cosf(psi);
    const float sn = sinf(psi);
    const float vx = vel[0];
    vel[0] = c * vx - sn * vel[1];
    vel[1] = sn * vx + c * vel[1];
  }
  const float leash = (leashM > 0.0f && leashM < 100.0f) ? leashM : HF_DEFAULT_LEASH_M;
  for (int i = 0; i < 3; i++) {
    out->v_m_s[i] = 0.0f;
    out->a_m_s2[i] = 0.0f;
    out->j_m_s3[i] = 0.0f;
    if (mode[i] == modeAbs) {
      refP[i] = pos[i];
      out->v_m_s[i] = vel[i];
      out->a_m_s2[i] = acc[i];
      out->j_m_s3[i] = jerk[i];
    } else if (mode[i] == modeVelocity) {
      refP[i] = clampf(refP[i] + vel[i] * HF_DT_S, s->p_m[i] - leash, s->p_m[i] + leash);
      out->v_m_s[i] = vel[i];
    }
    out->p_m[i] = refP[i];
  }
}

/* Apply parameter writes: gains and the composite law's Q and R (refused ones are reverted to
 * what the core holds), the law (only while not airborne: a switch resets a), reset. */
static HF_NOINLINE void applyParams(void) {
  if (hf_set_gains(&ctl, &gains) != HF_OK) {
    hf_get_gains(&ctl, &gains);
  }
  if (hf_set_composite(&ctl, &composite) != HF_OK) {
    hf_get_composite(&ctl, &composite);
  }
  if (phase != HF_PHASE_AIRBORNE && lawParam != hf_get_law(&ctl) &&
      hf_set_law(&ctl, lawParam) != HF_OK) {
    lawParam = (uint8_t)hf_get_law(&ctl);
  }
  if (resetRequest) {
    hf_reset(&ctl);
    resetRequest = 0;
  }
}

/* GROUND / AIRBORNE / LANDED (see the top of the file). */
static HF_NOINLINE void updatePhase(const hf_state_t *s) {
  const bool flying = supervisorIsFlying();
  if (phase == HF_PHASE_OFF) {
    if (offWhileAirborne && flying) {
      /* Re-engaged in flight after a stop: airborne again, over the ground it took off from. */
      phase = HF_PHASE_AIRBORNE;
    } else {
      phase = HF_PHASE_GROUND;
      groundZ = s->p_m[2];
    }
    offWhileAirborne = false;
    for (int i = 0; i < 3; i++) {
      refP[i] = s->p_m[i];
    }
    refYaw = yawOfRot(s->rot);
    hf_reset(&ctl);
  }
  if (phase == HF_PHASE_GROUND && flying && s->p_m[2] - groundZ >= airborneHeightM) {
    phase = HF_PHASE_AIRBORNE;
  } else if (phase == HF_PHASE_AIRBORNE && !flying) {
    phase = HF_PHASE_GROUND;
    groundZ = s->p_m[2];
    hf_reset(&ctl);
  }
}

/* The adaptation runs while AIRBORNE, except on the way down to the ground: when both the
 * vehicle and its setpoint are within airHeight of z_ground, the floor may push back (a
 * landing's touch-down, before the supervisor says landed) and the estimate is held, as it is
 * before the take-off. */
static void updateAdaptation(const hf_state_t *s, const hf_setpoint_t *sp) {
  const bool landing = s->p_m[2] - groundZ < airborneHeightM &&
                       sp->p_m[2] - groundZ < airborneHeightM;
  hf_set_adapt(&ctl, adaptOn && phase == HF_PHASE_AIRBORNE && !landing);
}

static HF_NOINLINE void updateLogs(void) {
  hf_get_estimate(&ctl, logA);
  (void)hf_get_prediction_error(&ctl, logEps);
  logPTrace = hf_p_trace(&ctl);
  logLaw = (uint8_t)hf_get_law(&ctl);
  logFaults = hfOut.faults;
  logSat = (uint8_t)(((hfOut.faults & HF_COND_SAT_YAW) ? 1u : 0u) |
                     ((hfOut.faults & HF_COND_SAT_ROLL_PITCH) ? 2u : 0u) |
                     ((hfOut.faults & HF_COND_SAT_THRUST) ? 4u : 0u) |
                     ((hfOut.faults & HF_COND_TILT_LIMITED) ? 8u : 0u));
}

void controllerOutOfTreeInit(void) {
  if (!isInit) {
    /* The controller itself is built by the app task (initController). */
    enableCycleCounter();
    setActiveBuiltin();
    /* Memory handlers may only be registered before crtpMemInit() (its task blocks further
     * registrations, and a late one fails an ASSERT). With CONFIG_CONTROLLER_OOT the
     * stabilizer auto-selects this controller in stabilizerInit(), which the system task runs
     * after memInit() and before crtpMemInit() (crazyflie-firmware 2a18fc29, system.c): register
     * there. A first init from any other task (the controller selected later by parameter)
     * cannot register: the upload is then unavailable and the console says so. */
#if HAMFLIGHT_UPLOAD
    if (strcmp(pcTaskGetName(NULL), "SYSTEM") == 0) { /* SYSTEM_TASK_NAME, config.h */
      memoryRegisterHandler(&upMemDef);
      memRegistered = true;
    }
#endif
    isInit = true;
  }
  /* Before the app task has built and tested the controller, or while it swaps the model, the
   * app task owns the controller: then only mark the phase (the controller starts, and a swap
   * ends, with a = 0 anyway). */
  if (isReady() && !swapping()) {
    disengage();
  } else {
    phase = HF_PHASE_OFF;
  }
  offWhileAirborne = false; /* an init starts over: the next engagement finds the ground */
  zeroWrench();
  updateLogs();
  DEBUG_PRINT("model %s crc %08X, %d g, %d Hz\n", hf_model_name(), (unsigned int)hf_model_crc(),
              (int)(hf_mass_kg() * 1000.0f + 0.5f), (int)HAMFLIGHT_RATE_HZ);
  printActive();
#if HAMFLIGHT_UPLOAD
  if (!memRegistered) {
    DEBUG_PRINT("weights upload unavailable: first selected after boot\n");
  }
#else
  DEBUG_PRINT("weights upload compiled out (HAMFLIGHT_UPLOAD=0)\n");
#endif
}

/* Light: it may run on a small stack. The app task runs hf_self_test() when it starts. */
bool controllerOutOfTreeTest(void) { return isInit && hf_model_crc() != 0u; }

void controllerOutOfTree(control_t *control, const setpoint_t *setpoint,
                         const sensorData_t *sensors, const state_t *state,
                         const stabilizerStep_t tick) {
  /* Before the self test passed, and while the app task swaps the model: off. */
  if (!isReady() || swapping()) {
    zeroOutput(control);
    hfOut.faults = isReady() ? HF_SHIM_SWAPPING : HF_SHIM_NOT_READY;
    logFaults = hfOut.faults;
    return;
  }
  /* A new model (or the compiled-in one again) only while not airborne. */
  if (startSwapIfDue()) {
    zeroOutput(control);
    hfOut.faults = HF_SHIM_SWAPPING;
    logFaults = hfOut.faults;
    return;
  }
  logFaults &= ~HF_SHIM_SWAPPING; /* a swap that ended: its flag goes */
  /* Off is checked at every 1 kHz tick, so a stop acts within 1 ms whatever the rate. */
  if (!isInit || !supervisorCanFly() ||
      (setpoint->mode.z == modeDisable && !(setpoint->thrust >= HF_STOP_THRUST))) {
    zeroOutput(control);
    if (isInit && phase != HF_PHASE_OFF) {
      disengage();
      updateLogs();
    }
    return;
  }
  if (!RATE_DO_EXECUTE(HAMFLIGHT_RATE_HZ, tick)) {
    return;
  }
  applyParams();
  convertState(state, sensors, &hfState);
  updatePhase(&hfState);
  convertSetpoint(setpoint, &hfState, &hfSetpoint);
  updateAdaptation(&hfState, &hfSetpoint);

  serveStep();

  control->controlMode = controlModeForceTorque;
  control->thrustSi = hfOut.thrust_n;
  control->torque[0] = hfOut.torque_nm[0];
  control->torque[1] = hfOut.torque_nm[1];
  control->torque[2] = hfOut.torque_nm[2];
  updateLogs();
}

/* Builds the controller (in place) and gives the parameters its defaults. In the app task: the
 * default gains for the vehicle take more stack than the system task has (1,200 B), where
 * controllerOutOfTreeInit first runs. */
static void initController(void) {
  hf_init(&ctl);
  if (hf_set_law(&ctl, lawParam) != HF_OK) {
    lawParam = (uint8_t)hf_get_law(&ctl);
  }
  hf_get_gains(&ctl, &gains);
  hf_get_composite(&ctl, &composite);
  hf_set_adapt(&ctl, false);
}

/* The app task: the controller and its boot self test, then the model swaps (see "Stack" at the
 * top). */
void appMain(void) {
  DEBUG_PRINT("select with param stabilizer.controller = %d (out of tree)\n",
              (int)ControllerTypeOot);
  initController();
  if (!hf_self_test(&ctl)) { /* steps ctl itself: the stabilizer does not use it before ready */
    DEBUG_PRINT("self test FAILED: the controller stays off\n");
    for (;;) {
      vTaskDelay(M2T(60000));
    }
  }
  __atomic_store_n(&ready, true, __ATOMIC_SEQ_CST);
  for (;;) {
    vTaskDelay(M2T(HF_SWAP_POLL_MS));
    const uint8_t job = jobLoad();
    if (job != HF_JOB_NONE) {
      serveSwap(job);
      jobStore(HF_JOB_NONE);
    }
  }
}

PARAM_GROUP_START(hamflight)
PARAM_ADD(PARAM_FLOAT, kp, &gains.k_p)
PARAM_ADD(PARAM_FLOAT, kv, &gains.k_v)
PARAM_ADD(PARAM_FLOAT, kR, &gains.k_r)
PARAM_ADD(PARAM_FLOAT, kw, &gains.k_w)
PARAM_ADD(PARAM_FLOAT, maxTilt, &gains.max_tilt_rad)
PARAM_ADD(PARAM_FLOAT, cp, &gains.c_p)
PARAM_ADD(PARAM_FLOAT, cv, &gains.c_v)
PARAM_ADD(PARAM_FLOAT, cR, &gains.c_r)
PARAM_ADD(PARAM_FLOAT, cw, &gains.c_w)
PARAM_ADD(PARAM_FLOAT, aMax, &gains.a_max)
PARAM_ADD(PARAM_UINT8, adapt, &adaptOn)
PARAM_ADD(PARAM_UINT8, reset, &resetRequest)
PARAM_ADD(PARAM_FLOAT, airHeight, &airborneHeightM)
PARAM_ADD(PARAM_FLOAT, leash, &leashM)
PARAM_ADD(PARAM_UINT8, law, &lawParam)
PARAM_ADD(PARAM_FLOAT, qF, &composite.q_force)
PARAM_ADD(PARAM_FLOAT, qT, &composite.q_torque)
PARAM_ADD(PARAM_FLOAT, rF, &composite.r_force)
PARAM_ADD(PARAM_FLOAT, rT, &composite.r_torque)
PARAM_ADD(PARAM_UINT8, revert, &revertRequest)
PARAM_GROUP_STOP(hamflight)

LOG_GROUP_START(hamflight)
LOG_ADD(LOG_FLOAT, a0, &logA[0])
LOG_ADD(LOG_FLOAT, a1, &logA[1])
LOG_ADD(LOG_FLOAT, a2, &logA[2])
LOG_ADD(LOG_FLOAT, a3, &logA[3])
LOG_ADD(LOG_FLOAT, a4, &logA[4])
LOG_ADD(LOG_FLOAT, a5, &logA[5])
LOG_ADD(LOG_UINT32, faults, &logFaults)
LOG_ADD(LOG_UINT8, sat, &logSat)
LOG_ADD(LOG_UINT8, phase, &phase)
LOG_ADD(LOG_FLOAT, thrust, &hfOut.thrust_n)
LOG_ADD(LOG_FLOAT, tx, &hfOut.torque_nm[0])
LOG_ADD(LOG_FLOAT, ty, &hfOut.torque_nm[1])
LOG_ADD(LOG_FLOAT, tz, &hfOut.torque_nm[2])
LOG_ADD(LOG_UINT32, cycles, &logCycles)
LOG_ADD(LOG_UINT8, law, &logLaw)
LOG_ADD(LOG_FLOAT, e0, &logEps[0])
LOG_ADD(LOG_FLOAT, e1, &logEps[1])
LOG_ADD(LOG_FLOAT, e2, &logEps[2])
LOG_ADD(LOG_FLOAT, e3, &logEps[3])
LOG_ADD(LOG_FLOAT, e4, &logEps[4])
LOG_ADD(LOG_FLOAT, e5, &logEps[5])
LOG_ADD(LOG_FLOAT, pTrace, &logPTrace)
LOG_ADD(LOG_UINT8, blobSrc, &activeSource)
LOG_ADD(LOG_UINT32, blobCrc, &activeCrc)
LOG_ADD(LOG_UINT8, upState, &upState)
LOG_ADD(LOG_UINT8, upError, &upError)
LOG_GROUP_STOP(hamflight)
