/* Host stand-in for Bitcraze's imu_types.h (hamflight host tests; see README.md). */
#ifndef IMU_TYPES_H_
#define IMU_TYPES_H_

#include <stdint.h>

typedef union {
  struct {
    float x;
    float y;
    float z;
  };
  float axis[3];
} Axis3f;

#endif
