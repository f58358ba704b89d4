/*
 * Host stand-in for FreeRTOS's semphr.h: binary semaphores on pthreads (host_harness.c), so the
 * host tests run the shim's hand-off to its worker task for real, with appMain in a thread. A host
 * tick is HF_HOST_TICK_MS long (FreeRTOS.h), so that a loaded machine never times out by accident.
 */
#ifndef HF_HOST_SEMPHR_H
#define HF_HOST_SEMPHR_H

#include <pthread.h>
#include <stdbool.h>

#include "FreeRTOS.h"

typedef struct {
  pthread_mutex_t mutex;
  pthread_cond_t cond;
  bool given;
} StaticSemaphore_t;

typedef StaticSemaphore_t *SemaphoreHandle_t;

SemaphoreHandle_t xSemaphoreCreateBinaryStatic(StaticSemaphore_t *buffer);
BaseType_t xSemaphoreGive(SemaphoreHandle_t sem);
BaseType_t xSemaphoreTake(SemaphoreHandle_t sem, TickType_t ticks);

#endif
