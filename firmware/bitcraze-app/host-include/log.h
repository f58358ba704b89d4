/* Host stand-in for Bitcraze's log.h: the macros the shim uses, into a searchable table. */
#ifndef __LOG_H__
#define __LOG_H__

#include "hf_host_registry.h"

#define LOG_UINT8 1
#define LOG_UINT16 2
#define LOG_UINT32 3
#define LOG_INT8 4
#define LOG_INT16 5
#define LOG_INT32 6
#define LOG_FLOAT 7

#define LOG_GROUP_START(NAME)                             \
  static const struct hf_host_var hf_host_logs_##NAME[] = { \
      {HF_HOST_GROUP_START, #NAME, 0},

#define LOG_ADD(TYPE, NAME, ADDRESS) {(TYPE), #NAME, (void *)(ADDRESS)},

#define LOG_GROUP_STOP(NAME)                                                  \
  {HF_HOST_GROUP_STOP, #NAME, 0},                                               \
  };                                                                            \
  __attribute__((constructor)) static void hf_host_register_logs_##NAME(void) { \
    hf_host_register(0, hf_host_logs_##NAME);                                 \
  }

#endif
