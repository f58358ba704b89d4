/* hamflight's stand-in for the handful of CMSIS-DSP declarations Bitcraze's Kalman core and
 * controllers use (cf_math.h), so that a crazyflie-firmware checkout without its vendor/CMSIS
 * submodule compiles on the host. The definitions are ours, in bc_shim.c. */
#ifndef HF_ARM_MATH_STANDIN_H
#define HF_ARM_MATH_STANDIN_H
#include <math.h>
#include <stdint.h>

typedef float float32_t;
#ifndef PI
#define PI 3.14159265358979f
#endif

typedef enum {
  ARM_MATH_SUCCESS = 0,
  ARM_MATH_ARGUMENT_ERROR = -1,
  ARM_MATH_LENGTH_ERROR = -2,
  ARM_MATH_SIZE_MISMATCH = -3,
  ARM_MATH_NANINF = -4,
  ARM_MATH_SINGULAR = -5,
  ARM_MATH_TEST_FAILURE = -6
} arm_status;

typedef struct {
  uint16_t numRows;
  uint16_t numCols;
  float32_t *pData;
} arm_matrix_instance_f32;

arm_status arm_mat_trans_f32(const arm_matrix_instance_f32 *src, arm_matrix_instance_f32 *dst);
arm_status arm_mat_mult_f32(const arm_matrix_instance_f32 *a, const arm_matrix_instance_f32 *b,
                            arm_matrix_instance_f32 *dst);
arm_status arm_mat_scale_f32(const arm_matrix_instance_f32 *src, float32_t scale,
                             arm_matrix_instance_f32 *dst);
arm_status arm_mat_inverse_f32(const arm_matrix_instance_f32 *src, arm_matrix_instance_f32 *dst);
arm_status arm_sqrt_f32(float32_t in, float32_t *out);
float32_t arm_cos_f32(float32_t x);
float32_t arm_sin_f32(float32_t x);
#endif
