/* vmac events: follow a host's event stream (GET /api/events, docs/CLI.md). */
#ifndef VMAC_CLI_EVENTS_H
#define VMAC_CLI_EVENTS_H

int vmac_events_main(int argc, char **argv);

#endif
