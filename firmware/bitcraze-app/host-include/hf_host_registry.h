/*
 * The host's param/log table: PARAM_* and LOG_* macros (param.h, log.h) emit entries into the
 * linker sections hf_host_params and hf_host_logs, as Bitcraze's put theirs in .param.* and
 * .log.*; host_harness.c walks them by name.
 */
#ifndef HF_HOST_REGISTRY_H
#define HF_HOST_REGISTRY_H

#include <stdint.h>

#define HF_HOST_GROUP_START 0x100u
#define HF_HOST_GROUP_STOP 0x200u

struct hf_host_var {
  uint32_t type;     /* the PARAM_* / LOG_* type, or HF_HOST_GROUP_START / _STOP */
  const char *name;  /* variable name, or group name for the markers */
  void *address;
};

#endif
