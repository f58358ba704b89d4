/* hamflight firmware-sitl: stand-in for crazyflie-firmware's Kconfig-generated autoconf.h.
 *
 * CrazySim's SITL build (sitl_make/CMakeLists.txt) has no Kconfig: its configuration is a list of
 * -D flags, and its own sources skip autoconf.h under CONFIG_PLATFORM_SITL. hamflight_oot.c
 * includes autoconf.h unconditionally; this file satisfies that include for the SITL build only
 * (it is on the include path of hamflight_oot.c alone, see CMakeLists.txt). The CONFIG_* values
 * themselves (CONFIG_CONTROLLER_OOT, CONFIG_APP_*) are compile definitions of the whole cf2 target,
 * as firmware/bitcraze-app/app-config sets them for the STM32 build. */
#ifndef HF_SITL_AUTOCONF_H
#define HF_SITL_AUTOCONF_H

#ifndef CONFIG_CONTROLLER_OOT
#error "firmware-sitl: CONFIG_CONTROLLER_OOT must be defined for the whole cf2 target"
#endif

#endif
