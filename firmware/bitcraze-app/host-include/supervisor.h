/* Host stand-in for Bitcraze's supervisor.h: answers what the test set (host_harness.c). */
#ifndef __SUPERVISOR_H__
#define __SUPERVISOR_H__

#include <stdbool.h>

bool supervisorCanFly(void);
bool supervisorIsFlying(void);

#endif
