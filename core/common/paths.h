/* Where vmac's shipped files are: the folder holding scripts/ and stdlib/
 * (and core/vtest/runner.lua, tests/drivers/), found from the running
 * binary, so that a program runs the same from any working folder. Two
 * layouts, tried in this order:
 *   installed    PREFIX/bin/vmacd        -> PREFIX/share/vmac (make install, the .deb)
 *   source tree  ROOT/build/bin/vmacd,   -> ROOT (the first folder above the
 *                ROOT/build/asan/bin/vmac    binary that holds scripts/drivers/)
 * Used by vmacd and vmac; docs/SERVICE.md, "Install layout". */
#ifndef VMAC_PATHS_H
#define VMAC_PATHS_H

#include <stddef.h>

/* The root folder for the program at exe (an absolute path; the file itself
 * need not exist) into out (no trailing slash). 0; -ENOENT when neither
 * layout holds there; -ENAMETOOLONG when the folder does not fit in len. */
int vmac_root_dir_of(const char *exe, char *out, size_t len);

/* The root folder of the running program (/proc/self/exe, symbolic links
 * resolved) into out; where neither layout holds, VMAC_FALLBACK_ROOT
 * (/usr/local/share/vmac unless the build says otherwise). */
void vmac_root_dir(char *out, size_t len);

#endif
