/*
 * Host stand-in for the CMSIS device header: only the DWT cycle counter and the debug enable the
 * shim touches. Every access through DWT refreshes CYCCNT from the host's monotonic clock,
 * scaled to the Crazyflie's 168 MHz, so the shim's cycle log reads a plausible number on the host.
 */
#ifndef HF_HOST_STM32F4XX_H
#define HF_HOST_STM32F4XX_H

#include <stdint.h>

typedef struct {
  volatile uint32_t CTRL;
  volatile uint32_t CYCCNT;
} hf_host_dwt_t;

typedef struct {
  volatile uint32_t DEMCR;
} hf_host_core_debug_t;

hf_host_dwt_t *hf_host_dwt(void);
extern hf_host_core_debug_t hf_host_core_debug;

#define DWT (hf_host_dwt())
#define CoreDebug (&hf_host_core_debug)
#define DWT_CTRL_CYCCNTENA_Msk (1UL << 0)
#define CoreDebug_DEMCR_TRCENA_Msk (1UL << 24)

#endif
