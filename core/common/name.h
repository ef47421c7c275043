/* What a name of a device, a machine or a driver may be, wherever one
 * comes from outside (a URL, a recording's header): 1 to max bytes of
 * [A-Za-z0-9._-], not starting with '.', so that no name is "." or ".."
 * and none can be taken for a path. Header only. */
#ifndef VMAC_NAME_H
#define VMAC_NAME_H

#include <stddef.h>

static inline int vmac_valid_name(const char *s, size_t max)
{
	size_t n = 0;
	if (*s == '.')
		return 0;
	for (; *s; s++, n++)
		if (n >= max || !((*s >= 'a' && *s <= 'z') || (*s >= 'A' && *s <= 'Z') || (*s >= '0' && *s <= '9') ||
		                  *s == '-' || *s == '_' || *s == '.'))
			return 0;
	return n > 0;
}

#endif
