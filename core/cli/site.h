/* vmac site: every vmac host on one MQTT broker, its devices and their last
 * values, from the broker alone (docs/CLI.md, "vmac site"). */
#ifndef VMAC_CLI_SITE_H
#define VMAC_CLI_SITE_H

int vmac_site_main(int argc, char **argv);

#endif
