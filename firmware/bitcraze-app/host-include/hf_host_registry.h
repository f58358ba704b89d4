/*
 * The host's param/log table: the PARAM_* and LOG_* macros (param.h, log.h) build one array per
 * group, as Bitcraze's do, and a constructor registers each array with host_harness.c, which
 * finds variables by group and name. (Bitcraze collects its arrays in .param.* and .log.*
 * linker sections; a host linker may discard such sections, constructors it keeps.)
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

/* Registers a group's array (param nonzero: parameters, else logs); called by constructors. */
void hf_host_register(int param, const struct hf_host_var *group);

#endif
