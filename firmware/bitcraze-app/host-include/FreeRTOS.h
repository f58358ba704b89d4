/* Host stand-in for FreeRTOS.h: the tick type and M2T (1 tick per ms, as on the Crazyflie). */
#ifndef HF_HOST_FREERTOS_H
#define HF_HOST_FREERTOS_H

#include <stdint.h>

typedef uint32_t TickType_t;
#define M2T(X) ((TickType_t)(X))

#endif
