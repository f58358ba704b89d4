/* Host stand-in for FreeRTOS.h: the tick type, M2T (1 tick per ms, as on the Crazyflie, for
 * delays) and what semphr.h needs. Semaphore timeouts count host ticks of HF_HOST_TICK_MS. */
#ifndef HF_HOST_FREERTOS_H
#define HF_HOST_FREERTOS_H

#include <stdint.h>

typedef uint32_t TickType_t;
typedef long BaseType_t;
#define pdTRUE ((BaseType_t)1)
#define pdFALSE ((BaseType_t)0)
#define portMAX_DELAY ((TickType_t)0xffffffffUL)
#define M2T(X) ((TickType_t)(X))
#define HF_HOST_TICK_MS 200

#endif
