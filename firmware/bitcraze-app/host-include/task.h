/* Host stand-in for FreeRTOS's task.h. */
#ifndef HF_HOST_TASK_H
#define HF_HOST_TASK_H

#include "FreeRTOS.h"

void vTaskDelay(const TickType_t ticks);
/* The calling task's name (FreeRTOS): "SYSTEM" on the host, as in the firmware's boot init. */
char *pcTaskGetName(void *task);

#endif
