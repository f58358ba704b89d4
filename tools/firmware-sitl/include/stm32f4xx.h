/* hamflight firmware-sitl: the two Cortex-M debug registers hamflight_oot.c touches, on Linux.
 *
 * The shim times each hf_step with the DWT cycle counter (log hamflight.cycles). In the SITL
 * process DWT->CYCCNT reads the host's CLOCK_MONOTONIC scaled to 168 MHz (sitl_glue.c), so
 * hamflight.cycles is the host's wall time of one step in STM32F405-cycle units (16,800 = 100 us):
 * a host cost, not the STM32's. Only hamflight_oot.c sees this header. */
#ifndef HF_SITL_STM32F4XX_H
#define HF_SITL_STM32F4XX_H

#include <stdint.h>

typedef struct {
  volatile uint32_t CTRL;
  volatile uint32_t CYCCNT;
} hf_sitl_dwt_t;

typedef struct {
  volatile uint32_t DEMCR;
} hf_sitl_core_debug_t;

hf_sitl_dwt_t *hf_sitl_dwt(void);
extern hf_sitl_core_debug_t hf_sitl_core_debug;

#define DWT (hf_sitl_dwt())
#define CoreDebug (&hf_sitl_core_debug)
#define DWT_CTRL_CYCCNTENA_Msk (1UL << 0)
#define CoreDebug_DEMCR_TRCENA_Msk (1UL << 24)

#endif
