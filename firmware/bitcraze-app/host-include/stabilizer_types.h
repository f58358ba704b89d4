/*
 * Host stand-in for Bitcraze's stabilizer_types.h (hamflight host tests; see README.md): the
 * types hamflight_oot.c uses, with Bitcraze's field order and types.
 */
#ifndef __STABILIZER_TYPES_H__
#define __STABILIZER_TYPES_H__

#include <stdbool.h>
#include <stdint.h>

#include "imu_types.h"

typedef uint32_t stabilizerStep_t;

typedef struct attitude_s {
  uint32_t timestamp;
  float roll;
  float pitch;
  float yaw;
} attitude_t;

struct vec3_s {
  uint32_t timestamp;
  float x;
  float y;
  float z;
};

typedef struct vec3_s vector_t;
typedef struct vec3_s point_t;
typedef struct vec3_s velocity_t;
typedef struct vec3_s acc_t;
typedef struct vec3_s jerk_t;

typedef struct quaternion_s {
  union {
    struct {
      float q0;
      float q1;
      float q2;
      float q3;
    };
    struct {
      float x;
      float y;
      float z;
      float w;
    };
  };
} quaternion_t;

typedef struct baro_s {
  float pressure;
  float temperature;
  float asl;
} baro_t;

typedef struct sensorData_s {
  Axis3f acc;   /* Gs */
  Axis3f gyro;  /* deg/s */
  Axis3f mag;   /* gauss */
  baro_t baro;
  uint64_t interruptTimestamp;
} sensorData_t;

typedef struct state_s {
  attitude_t attitude;             /* deg, legacy inverted pitch */
  quaternion_t attitudeQuaternion; /* body to world */
  point_t position;                /* m */
  velocity_t velocity;             /* m/s, world */
  acc_t acc;                       /* Gs, without gravity on z */
} state_t;

#define STABILIZER_NR_OF_MOTORS 4

typedef enum control_mode_e {
  controlModeLegacy = 0,
  controlModeForceTorque = 1,
  controlModeForce = 2,
} control_mode_t;

typedef struct control_s {
  union {
    struct {
      int16_t roll;
      int16_t pitch;
      int16_t yaw;
      float thrust;
    };
    struct {
      float thrustSi; /* N */
      union {
        float torque[3]; /* N*m */
        struct {
          float torqueX;
          float torqueY;
          float torqueZ;
        };
      };
    };
    float normalizedForces[STABILIZER_NR_OF_MOTORS];
  };
  control_mode_t controlMode;
} control_t;

typedef enum mode_e {
  modeDisable = 0,
  modeAbs,
  modeVelocity
} stab_mode_t;

typedef struct {
  stab_mode_t x;
  stab_mode_t y;
  stab_mode_t z;
  stab_mode_t roll;
  stab_mode_t pitch;
  stab_mode_t yaw;
  stab_mode_t quat;
} setpoint_mode_t;

typedef struct setpoint_s {
  uint32_t timestamp;
  attitude_t attitude;     /* deg */
  attitude_t attitudeRate; /* deg/s */
  quaternion_t attitudeQuaternion;
  float thrust;
  point_t position;        /* m */
  velocity_t velocity;     /* m/s */
  acc_t acceleration;      /* m/s^2 */
  jerk_t jerk;             /* m/s^3 */
  bool velocity_body;
  setpoint_mode_t mode;
} setpoint_t;

#define RATE_1000_HZ 1000
#define RATE_500_HZ 500
#define RATE_250_HZ 250
#define RATE_100_HZ 100
#define RATE_MAIN_LOOP RATE_1000_HZ
#define ATTITUDE_RATE RATE_500_HZ

#define RATE_DO_EXECUTE(RATE_HZ, TICK) ((TICK % (RATE_MAIN_LOOP / RATE_HZ)) == 0)

#endif
