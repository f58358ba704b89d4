/* Stand-in for Bitcraze's static_mem.h (host builds): the CCM placement is the STM32's. */
#pragma once
#define NO_DMA_CCM_SAFE_ZERO_INIT
