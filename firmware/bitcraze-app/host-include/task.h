/* Host stand-in for FreeRTOS's task.h. */
#ifndef HF_HOST_TASK_H
#define HF_HOST_TASK_H

#include "FreeRTOS.h"

void vTaskDelay(const TickType_t ticks);

#endif
