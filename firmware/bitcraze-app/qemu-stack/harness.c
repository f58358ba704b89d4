/*
 * harness.c: the measured stack high-water marks of the Crazyflie library's entry points, on a
 * Cortex-M4F (QEMU's netduinoplus2), linked with the very hamflight_rust.o that Bitcraze's build
 * links. Run by qemu-stack.sh, which sets each figure against stack-estimate.py's static bound
 * of the same function in the same ELF.
 *
 * Each measurement paints WINDOW bytes below the caller's stack pointer (below the painter's own
 * frame), makes one call and finds the lowest word that lost the paint: the call's stack from
 * its `bl` (return address, frames, callees' frames), as much of it as this run wrote. The calls
 * are the shim's: hf_init and hf_self_test (the app task at boot), hf_step (the stabilizer task)
 * under both laws with the accelerometer, over a paper-spiral flight near the reference and over
 * off-nominal inputs (far and fast: saturation and the tilt limit; yaw across +-pi; a huge yaw
 * reference; a non-finite state; a bad dt), hf_blob_check (the memory task's COMMIT),
 * hf_model_load and hf_use_model (the app task's swap), then the same flights on the uploaded
 * model (its port terms), and hf_use_model(NULL) (the revert).
 *
 * Bare metal: its own vector table and reset, no libc (memcpy and memset below), output and exit
 * over semihosting. Prints one line, `STACK name=bytes ...`, and exits 0; exits 1 on a failed
 * call.
 */
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "hamflight.h"

#define PAINT 0xCCCCCCCCu
#define WINDOW 4096u
#define DT_S 0.002f
#define FLIGHT_STEPS 2000u
#define STRESS_STEPS 400u

extern uint32_t _sbss, _ebss, _stack_top;
extern const uint8_t blob_start[], blob_end[];

static hf_controller_t ctl;
static hf_model_t slot;

/* ---- freestanding support ---- */

void *memcpy(void *dst, const void *src, size_t n) {
  uint8_t *d = dst;
  const uint8_t *s = src;
  while (n--) {
    *d++ = *s++;
  }
  return dst;
}

void *memset(void *dst, int c, size_t n) {
  uint8_t *d = dst;
  while (n--) {
    *d++ = (uint8_t)c;
  }
  return dst;
}

static int semihost(int op, const void *arg) {
  register int r0 __asm__("r0") = op;
  register const void *r1 __asm__("r1") = arg;
  __asm__ volatile("bkpt 0xab" : "+r"(r0) : "r"(r1) : "memory");
  return r0;
}

static void put(const char *s) { (void)semihost(0x04, s); /* SYS_WRITE0 */ }

static void put_u32(uint32_t v) {
  char buf[11];
  char *p = buf + sizeof buf - 1;
  *p = 0;
  do {
    *--p = (char)('0' + v % 10u);
    v /= 10u;
  } while (v != 0u);
  put(p);
}

static void __attribute__((noreturn)) quit(bool ok) {
  /* SYS_EXIT: ADP_Stopped_ApplicationExit (QEMU exits 0), ADP_Stopped_RunTimeErrorUnknown (1). */
  (void)semihost(0x18, (const void *)(uintptr_t)(ok ? 0x20026u : 0x20023u));
  for (;;) {
  }
}

static void __attribute__((noreturn)) fail(const char *what) {
  put("qemu-stack: FAIL: ");
  put(what);
  put("\n");
  quit(false);
}

/* ---- the probe ---- */

static inline uintptr_t sp_now(void) {
  uintptr_t sp;
  __asm__ volatile("mov %0, sp" : "=r"(sp)::"memory");
  return sp;
}

/* Paints [bottom, a margin below this function's own stack pointer). */
static void __attribute__((noinline)) paint_below(uintptr_t bottom) {
  const uintptr_t top = (sp_now() - 32u) & ~(uintptr_t)3u;
  for (uintptr_t p = bottom; p < top; p += 4u) {
    *(volatile uint32_t *)p = PAINT;
  }
}

/* Bytes between sp and the lowest word of [bottom, sp) that lost the paint. */
static uint32_t used_below(uintptr_t bottom, uintptr_t sp) {
  uintptr_t p = bottom;
  while (p < sp && *(volatile uint32_t *)p == PAINT) {
    p += 4u;
  }
  return (uint32_t)(sp - p);
}

/* Runs CALL once and raises DEEPEST to the stack it took below this frame. */
#define MEASURE(deepest, call)                                              \
  do {                                                                      \
    const uintptr_t sp_ = sp_now();                                         \
    const uintptr_t bottom_ = (sp_ - WINDOW) & ~(uintptr_t)3u;              \
    paint_below(bottom_);                                                   \
    call;                                                                   \
    const uint32_t used_ = used_below(bottom_, sp_);                        \
    if (used_ > (deepest)) {                                                \
      (deepest) = used_;                                                    \
    }                                                                       \
  } while (0)

/* ---- the inputs ---- */

/* sin and cos in float for any finite x (reduced to [-pi/2, pi/2], Taylor to x^15). */
static void sin_cos(float x, float *s, float *c) {
  const float pi = 3.14159265f;
  const float two_pi = 6.28318531f;
  x -= two_pi * (float)(int32_t)(x / two_pi);
  if (x > pi) {
    x -= two_pi;
  } else if (x < -pi) {
    x += two_pi;
  }
  float sign_c = 1.0f;
  if (x > 0.5f * pi) {
    x = pi - x;
    sign_c = -1.0f;
  } else if (x < -0.5f * pi) {
    x = -pi - x;
    sign_c = -1.0f;
  }
  const float x2 = x * x;
  float ts = x;
  float tc = 1.0f;
  float sum_s = x;
  float sum_c = 1.0f;
  for (int n = 1; n <= 7; n++) {
    ts *= -x2 / (float)((2 * n) * (2 * n + 1));
    tc *= -x2 / (float)((2 * n - 1) * (2 * n));
    sum_s += ts;
    sum_c += tc;
  }
  *s = sum_s;
  *c = sign_c * sum_c;
}

/* R = Rz(yaw) Ry(pitch) Rx(roll), body to world (nalgebra's from_euler_angles). */
static void rot_from_euler(float roll, float pitch, float yaw, float r[3][3]) {
  float sr, cr, sp, cp, sy, cy;
  sin_cos(roll, &sr, &cr);
  sin_cos(pitch, &sp, &cp);
  sin_cos(yaw, &sy, &cy);
  r[0][0] = cy * cp;
  r[0][1] = cy * sp * sr - sy * cr;
  r[0][2] = cy * sp * cr + sy * sr;
  r[1][0] = sy * cp;
  r[1][1] = sy * sp * sr + cy * cr;
  r[1][2] = sy * sp * cr - cy * sr;
  r[2][0] = -sp;
  r[2][1] = cp * sr;
  r[2][2] = cp * cr;
}

static void vec3(float v[3], float x, float y, float z) {
  v[0] = x;
  v[1] = y;
  v[2] = z;
}

/* Step k of the firmware bench's paper spiral: the state a few centimetres and degrees off the
 * reference, the accelerometer valid (the shim passes it). */
static void flight(uint32_t k, hf_state_t *st, hf_setpoint_t *sp) {
  const float t = (float)k * DT_S;
  const float w = 6.28318531f / 10.0f;
  float s, c;
  sin_cos(w * t, &s, &c);
  memset(st, 0, sizeof *st);
  memset(sp, 0, sizeof *sp);
  vec3(sp->p_m, 0.5f * c, 0.5f * s, 0.5f + 0.03f * t);
  vec3(sp->v_m_s, -0.5f * w * s, 0.5f * w * c, 0.03f);
  vec3(sp->a_m_s2, -0.5f * w * w * c, -0.5f * w * w * s, 0.0f);
  vec3(sp->j_m_s3, 0.5f * w * w * w * s, -0.5f * w * w * w * c, 0.0f);
  vec3(st->p_m, sp->p_m[0] + 0.02f * s, sp->p_m[1] - 0.01f * c, sp->p_m[2] + 0.005f);
  rot_from_euler(0.05f * s, -0.04f * c, 0.1f * s, st->rot);
  vec3(st->v_body_m_s, sp->v_m_s[0] + 0.01f, sp->v_m_s[1] - 0.02f, sp->v_m_s[2]);
  vec3(st->w_body_rad_s, 0.2f * c, -0.1f * s, 0.05f);
  vec3(st->specific_force_body_m_s2, 0.3f, -0.2f, 9.6f);
  st->specific_force_valid = 1;
}

/* Off the flight, a block of 50 steps each: far and fast twice (every rotor at a limit, the tilt
 * limit), yaw across +-pi with a fast yaw reference, a huge yaw reference, a non-finite state, a
 * bad dt, the flight without the accelerometer, the flight. */
static float stress(uint32_t k, hf_state_t *st, hf_setpoint_t *sp) {
  const float t = (float)k * DT_S;
  float dt_s = DT_S;
  flight(k, st, sp);
  switch (k / 50u) {
    case 0:
      st->p_m[0] += 2.0f;
      st->p_m[1] -= 1.5f;
      st->p_m[2] -= 1.0f;
      vec3(st->v_body_m_s, -3.0f, 2.0f, 1.5f);
      rot_from_euler(0.9f, -0.7f, 0.3f, st->rot);
      vec3(st->w_body_rad_s, 6.0f, -5.0f, 3.0f);
      break;
    case 1:
      st->p_m[0] -= 2.0f;
      st->p_m[1] += 1.5f;
      st->p_m[2] += 1.0f;
      rot_from_euler(-1.2f, 1.0f, -2.5f, st->rot);
      vec3(st->w_body_rad_s, -8.0f, 7.0f, -4.0f);
      break;
    case 2:
      rot_from_euler(0.0f, 0.0f, -3.1f + 0.01f * t, st->rot);
      sp->yaw_rad = 3.1f;
      sp->yaw_rate_rad_s = 4.0f;
      break;
    case 3:
      sp->yaw_rad = 1.0e5f + t;
      break;
    case 4:
      st->p_m[0] = __builtin_nanf("");
      break;
    case 5:
      dt_s = 0.0f;
      break;
    case 6:
      st->specific_force_valid = 0;
      break;
    default:
      break;
  }
  return dt_s;
}

/* ---- the measurements ---- */

struct step_stack {
  uint32_t flight;
  uint32_t stress;
};

/* hf_step over the flight and the off-nominal inputs, under `law`, on whatever ctl flies. */
static struct step_stack steps(uint32_t law) {
  struct step_stack r = {0, 0};
  hf_state_t st;
  hf_setpoint_t sp;
  hf_output_t out;
  if (hf_set_law(&ctl, law) != HF_OK) {
    fail("hf_set_law");
  }
  for (uint32_t k = 0; k < FLIGHT_STEPS; k++) {
    flight(k, &st, &sp);
    MEASURE(r.flight, (void)hf_step(&ctl, &st, &sp, DT_S, &out));
    if ((out.faults & HF_FAULT_MASK) != 0u) {
      fail("a fault in the flight");
    }
  }
  for (uint32_t k = 0; k < STRESS_STEPS; k++) {
    const float dt_s = stress(k, &st, &sp);
    MEASURE(r.stress, (void)hf_step(&ctl, &st, &sp, dt_s, &out));
  }
  hf_reset(&ctl);
  return r;
}

static void field(const char *name, uint32_t bytes) {
  put(" ");
  put(name);
  put("=");
  put_u32(bytes);
}

int main(void) {
  uint32_t init = 0, self_test = 0, check = 0, load = 0, use = 0, revert = 0;
  bool ok = false;

  MEASURE(init, hf_init(&ctl));
  MEASURE(self_test, ok = hf_self_test(&ctl));
  if (!ok) {
    fail("hf_self_test");
  }
  const struct step_stack gradient = steps(HF_LAW_GRADIENT);
  const struct step_stack composite = steps(HF_LAW_COMPOSITE);

  const uint32_t len = (uint32_t)(blob_end - blob_start);
  if (len > sizeof slot.opaque) {
    fail("the blob does not fit the slot");
  }
  hf_blob_info_t info;
  uint32_t err = 0;
  MEASURE(check, err = hf_blob_check(blob_start, len, &info));
  if (err != HF_OK) {
    fail("hf_blob_check");
  }
  memcpy(slot.opaque, blob_start, len);
  MEASURE(load, err = hf_model_load(&slot, len, &info));
  if (err != HF_OK) {
    fail("hf_model_load");
  }
  MEASURE(use, err = hf_use_model(&ctl, &slot));
  if (err != HF_OK) {
    fail("hf_use_model");
  }
  const struct step_stack up_gradient = steps(HF_LAW_GRADIENT);
  const struct step_stack up_composite = steps(HF_LAW_COMPOSITE);
  MEASURE(revert, err = hf_use_model(&ctl, NULL));
  if (err != HF_OK) {
    fail("hf_use_model(NULL)");
  }

  put("STACK");
  field("hf_init", init);
  field("hf_self_test", self_test);
  field("hf_step_gradient", gradient.flight);
  field("hf_step_gradient_stress", gradient.stress);
  field("hf_step_composite", composite.flight);
  field("hf_step_composite_stress", composite.stress);
  field("hf_step_uploaded_gradient", up_gradient.flight);
  field("hf_step_uploaded_gradient_stress", up_gradient.stress);
  field("hf_step_uploaded_composite", up_composite.flight);
  field("hf_step_uploaded_composite_stress", up_composite.stress);
  field("hf_blob_check", check);
  field("hf_model_load", load);
  field("hf_use_model", use);
  field("hf_use_model_revert", revert);
  field("window", WINDOW);
  put("\n");
  quit(true);
}

/* ---- reset ---- */

void reset_handler(void) {
  for (uint32_t *p = &_sbss; p < &_ebss; p++) {
    *p = 0u;
  }
  /* CP10 and CP11 full access: the FPU (the Rust object and this file are hard-float). */
  *(volatile uint32_t *)0xE000ED88u |= 0xFu << 20;
  __asm__ volatile("dsb\n\tisb" ::: "memory");
  (void)main();
  quit(false);
}

static void __attribute__((noreturn)) fault_handler(void) { fail("a fault exception"); }

/* The initial stack pointer, then reset, NMI, hard fault, MemManage, bus and usage faults. */
__attribute__((section(".vectors"), used)) static const uintptr_t vectors[] = {
    (uintptr_t)&_stack_top,     (uintptr_t)reset_handler, (uintptr_t)fault_handler,
    (uintptr_t)fault_handler,   (uintptr_t)fault_handler, (uintptr_t)fault_handler,
    (uintptr_t)fault_handler,
};
