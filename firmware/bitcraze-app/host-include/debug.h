/* Host stand-in for Bitcraze's debug.h: DEBUG_PRINT appends to a buffer the test reads. */
#ifndef DEBUG_H_
#define DEBUG_H_

#ifdef DEBUG_MODULE
#define DEBUG_FMT(fmt) DEBUG_MODULE ": " fmt
#else
#define DEBUG_FMT(fmt) fmt
#endif

int hf_host_debug_printf(const char *fmt, ...) __attribute__((format(printf, 1, 2)));

#define DEBUG_PRINT(fmt, ...) hf_host_debug_printf(DEBUG_FMT(fmt), ##__VA_ARGS__)

#endif
