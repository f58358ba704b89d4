/*
 * bitcraze_layout.c: the layout of the Bitcraze types hamflight_oot.c uses. build-in-tree.sh
 * compiles it with arm-none-eabi-gcc twice, against the checkout's real headers and against
 * host-include/, and fails if the two lists differ.
 */
#include <stddef.h>
#include <stdint.h>

#include "stabilizer_types.h"

#define HF_LAYOUT(T, F) offsetof(T, F), sizeof(((T *)0)->F)

const uint32_t hf_bitcraze_layout[] = {
    sizeof(state_t),
    HF_LAYOUT(state_t, attitude),
    HF_LAYOUT(state_t, attitudeQuaternion),
    HF_LAYOUT(state_t, position),
    HF_LAYOUT(state_t, velocity),
    HF_LAYOUT(state_t, acc),
    sizeof(quaternion_t),
    HF_LAYOUT(quaternion_t, x),
    HF_LAYOUT(quaternion_t, y),
    HF_LAYOUT(quaternion_t, z),
    HF_LAYOUT(quaternion_t, w),
    sizeof(point_t),
    HF_LAYOUT(point_t, x),
    HF_LAYOUT(point_t, z),
    sizeof(sensorData_t),
    HF_LAYOUT(sensorData_t, acc),
    HF_LAYOUT(sensorData_t, gyro),
    HF_LAYOUT(sensorData_t, interruptTimestamp),
    sizeof(setpoint_t),
    HF_LAYOUT(setpoint_t, attitude),
    HF_LAYOUT(setpoint_t, attitudeRate),
    HF_LAYOUT(setpoint_t, attitudeQuaternion),
    HF_LAYOUT(setpoint_t, thrust),
    HF_LAYOUT(setpoint_t, position),
    HF_LAYOUT(setpoint_t, velocity),
    HF_LAYOUT(setpoint_t, acceleration),
    HF_LAYOUT(setpoint_t, jerk),
    HF_LAYOUT(setpoint_t, velocity_body),
    HF_LAYOUT(setpoint_t, mode),
    HF_LAYOUT(setpoint_t, mode.x),
    HF_LAYOUT(setpoint_t, mode.z),
    HF_LAYOUT(setpoint_t, mode.yaw),
    HF_LAYOUT(setpoint_t, mode.quat),
    sizeof(control_t),
    HF_LAYOUT(control_t, thrustSi),
    HF_LAYOUT(control_t, torque),
    HF_LAYOUT(control_t, torqueX),
    HF_LAYOUT(control_t, torqueZ),
    HF_LAYOUT(control_t, controlMode),
    controlModeForceTorque,
    modeDisable,
    modeAbs,
    modeVelocity,
    RATE_500_HZ,
    RATE_1000_HZ,
    RATE_MAIN_LOOP,
};
