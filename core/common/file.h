/* Reading a whole file of bounded size into memory: driver files, the
 * stdlib modules they require, the config file, TLS certificates and keys,
 * recordings, a driver a user uploads. */
#ifndef VMAC_FILE_H
#define VMAC_FILE_H

#include <stddef.h>

/* The whole of the file at path, at most max bytes: malloc'd (*len bytes
 * and a NUL after them), or NULL with err ("PATH: why") and *code: -errno of
 * the open ("PATH: cannot open: ..."), -ENOMEM, -EIO, or -EFBIG when it is larger than max. */
char *vmac_read_file(const char *path, size_t max, size_t *len, char *err, size_t errlen, int *code);

#endif
