/* A board's key file (docs/BOARD.md, "Keyed boards"): what `vmac board
 * enroll --out FILE` writes and `vmac-board --key-file` / `--key-dir`
 * read. The format: 32 hex digits (either case), the board's 16-byte key,
 * optionally followed by one newline, and nothing else. Not portable
 * firmware: POSIX only. */
#ifndef VMAC_POSIX_KEYFILE_H
#define VMAC_POSIX_KEYFILE_H

#include <stddef.h>
#include <stdint.h>

#include "../../core/proto/auth.h"

/* Read the key in path into key. Returns 0, or -1 with a reason naming
 * path in err (missing, unreadable, not a regular file, not 32 hex digits
 * and at most one newline). A file that group or others may read or change
 * is used, with a warning on stderr, as ssh does for a private key. The
 * text read is wiped before returning. */
int keyfile_read(const char *path, uint8_t key[VMAC_KEY_LEN], char *err, size_t errlen);

#endif
