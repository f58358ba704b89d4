/* blob.S: the weight blob the harness checks, loads and flies (BLOB_PATH, from qemu-stack.sh). */
  .section .rodata.blob, "a"
  .balign 8
  .global blob_start, blob_end
blob_start:
  .incbin BLOB_PATH
blob_end:
