/* Host stand-in for the firmware's generated autoconf.h: the options the shim depends on. */
#ifndef HF_HOST_AUTOCONF_H
#define HF_HOST_AUTOCONF_H

#define CONFIG_CONTROLLER_OOT 1

#endif
