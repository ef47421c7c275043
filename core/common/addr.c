/* See addr.h. */
#include "addr.h"

#include <arpa/inet.h>
#include <errno.h>
#include <stdlib.h>
#include <string.h>

int vmac_addr_parse(const char *text, struct in_addr *addr, uint16_t *port)
{
	char host[64], *end;
	const char *colon = strrchr(text, ':');
	size_t n;
	long p;
	if (!colon || colon == text || (n = (size_t)(colon - text)) >= sizeof(host))
		return -EINVAL;
	memcpy(host, text, n);
	host[n] = '\0';
	errno = 0;
	p = strtol(colon + 1, &end, 10);
	if (errno || *end || end == colon + 1 || p < 0 || p > 65535 || inet_pton(AF_INET, host, addr) != 1)
		return -EINVAL;
	*port = (uint16_t)p;
	return 0;
}
