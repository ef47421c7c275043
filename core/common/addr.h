/* "IPv4ADDR:PORT" as the command lines and config files write an address
 * (the bus group, the HTTP listener). One parser for all of them. */
#ifndef VMAC_ADDR_H
#define VMAC_ADDR_H

#include <netinet/in.h>
#include <stdint.h>

/* text as IPv4ADDR:PORT with PORT 0..65535: 0 and *addr, *port, or
 * -EINVAL. The caller checks what more it needs (a multicast group, a port
 * other than 0). */
int vmac_addr_parse(const char *text, struct in_addr *addr, uint16_t *port);

#endif
