/* Host stand-in for Bitcraze's controller.h (hamflight host tests; see README.md). */
#ifndef __CONTROLLER_H__
#define __CONTROLLER_H__

#include "autoconf.h"
#include "stabilizer_types.h"

typedef enum {
  ControllerTypeAutoSelect,
  ControllerTypePID,
  ControllerTypeMellinger,
  ControllerTypeINDI,
  ControllerTypeBrescianini,
  ControllerTypeLee,
#ifdef CONFIG_CONTROLLER_OOT
  ControllerTypeOot,
#endif
  ControllerType_COUNT,
} ControllerType;

#ifdef CONFIG_CONTROLLER_OOT
void controllerOutOfTreeInit(void);
bool controllerOutOfTreeTest(void);
void controllerOutOfTree(control_t *control, const setpoint_t *setpoint,
                         const sensorData_t *sensors, const state_t *state,
                         const stabilizerStep_t stabilizerStep);
#endif

#endif
