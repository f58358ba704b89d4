/* Host stand-in for Bitcraze's app.h. */
#ifndef __APP_H__
#define __APP_H__

void appMain(void);

#endif
