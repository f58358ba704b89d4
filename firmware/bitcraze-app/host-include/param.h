/* Host stand-in for Bitcraze's param.h: the macros the shim uses, into a searchable table. */
#ifndef __PARAM_H__
#define __PARAM_H__

#include "hf_host_registry.h"

#define PARAM_1BYTE 0x00
#define PARAM_2BYTES 0x01
#define PARAM_4BYTES 0x02
#define PARAM_TYPE_INT (0x00 << 2)
#define PARAM_TYPE_FLOAT (0x01 << 2)
#define PARAM_SIGNED (0x00 << 3)
#define PARAM_UNSIGNED (0x01 << 3)
#define PARAM_UINT8 (PARAM_1BYTE | PARAM_TYPE_INT | PARAM_UNSIGNED)
#define PARAM_UINT32 (PARAM_4BYTES | PARAM_TYPE_INT | PARAM_UNSIGNED)
#define PARAM_FLOAT (PARAM_4BYTES | PARAM_TYPE_FLOAT | PARAM_SIGNED)

#define PARAM_GROUP_START(NAME)                             \
  static const struct hf_host_var hf_host_params_##NAME[] = { \
      {HF_HOST_GROUP_START, #NAME, 0},

#define PARAM_ADD(TYPE, NAME, ADDRESS) {(TYPE), #NAME, (void *)(ADDRESS)},

#define PARAM_GROUP_STOP(NAME)                                                  \
  {HF_HOST_GROUP_STOP, #NAME, 0},                                               \
  };                                                                            \
  __attribute__((constructor)) static void hf_host_register_params_##NAME(void) { \
    hf_host_register(1, hf_host_params_##NAME);                                 \
  }

#endif
