/* hamflight firmware-sitl: what the STM32 gives hamflight_oot.c and Linux does not.
 *
 * DWT->CYCCNT (include/stm32f4xx.h): CLOCK_MONOTONIC in 168 MHz cycles, counting once the shim
 * has set CYCCNTENA, as on the STM32 (the shim enables it in controllerOutOfTreeInit). */
#include <stdint.h>
#include <time.h>

#include "stm32f4xx.h"

static hf_sitl_dwt_t dwt;
hf_sitl_core_debug_t hf_sitl_core_debug;

hf_sitl_dwt_t *hf_sitl_dwt(void) {
  struct timespec ts;
  if ((dwt.CTRL & DWT_CTRL_CYCCNTENA_Msk) && clock_gettime(CLOCK_MONOTONIC, &ts) == 0) {
    const uint64_t ns = (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
    dwt.CYCCNT = (uint32_t)(ns * 168u / 1000u);
  }
  return &dwt;
}
