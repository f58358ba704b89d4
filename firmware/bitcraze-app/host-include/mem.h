/* Host stand-in for Bitcraze's mem.h (src/modules/interface/mem.h): the memory type and the
 * handler definition the shim registers, with the field order and types of crazyflie-firmware
 * at 2a18fc29. memoryRegisterHandler is host_harness.c's: it keeps the definition for the
 * tests, which call it as crtp_mem.c's memory task would. */
#ifndef __MEM_H__
#define __MEM_H__

#include <stdbool.h>
#include <stdint.h>

typedef enum {
  MEM_TYPE_APP = 0x18,
} MemoryType_t;

typedef struct {
  MemoryType_t type;
  uint32_t (*getSize)(const uint8_t internal_id);
  bool (*getSerialNbr)(const uint8_t internal_id, const uint8_t max_length, uint8_t *len,
                       uint8_t *buffer);
  bool (*read)(const uint8_t internal_id, const uint32_t memAddr, const uint8_t readLen,
               uint8_t *buffer);
  bool (*write)(const uint8_t internal_id, const uint32_t memAddr, const uint8_t writeLen,
                const uint8_t *buffer);
  uint8_t internal_id;
} MemoryHandlerDef_t;

void memoryRegisterHandler(const MemoryHandlerDef_t *handlerDef);

#endif
