/* Where vmac's shipped files are: the folder holding scripts/ and stdlib/,
 * found from the running binary (build/bin/vmacd, build/asan/bin/vmac), else
 * the installed location. Used by vmacd and vmac. */
#ifndef VMAC_PATHS_H
#define VMAC_PATHS_H

#include <stddef.h>

/* Writes the root folder into out (no trailing slash). */
void vmac_root_dir(char *out, size_t len);

#endif
