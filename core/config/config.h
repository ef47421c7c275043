/* Host configuration: embedded defaults, a Lua config file, command-line
 * flags (in that order of precedence, flags last). Keys: docs/HOST.md. */
#ifndef VMAC_CONFIG_H
#define VMAC_CONFIG_H

#define VMAC_PATH_MAX 1024
#define VMAC_CONFIG_DRIVER_SETTINGS 64
#include <stddef.h>
#include <stdint.h>

#include "../driver/driver.h"

/* One driver.NAME.KEY setting. */
struct vmac_config_driver_setting {
	char driver[VMAC_NAME_MAX + 1];
	struct vmac_driver_setting s;
};

struct vmac_config {
	char bus[64];                    /* "GROUP:PORT" (UDP) or "eth:IFACE" (raw Ethernet) */
	char iface[64];                  /* UDP: the local interface address */
	char http[64];                   /* "ADDR:PORT" of the status/API server */
	char metrics_http[64];           /* "ADDR:PORT": GET /metrics without a token there too ("" = off) */
	char drivers_dir[VMAC_PATH_MAX]; /* searched first for NAME.lua and cycles/NAME/ ("" = none) */
	char scripts_dir[VMAC_PATH_MAX]; /* the shipped scripts/ (drivers/ and cycles/ below it) */
	char stdlib_dir[VMAC_PATH_MAX];  /* the Lua standard library drivers require() from */
	char state_dir[VMAC_PATH_MAX];
	char tls_cert[VMAC_PATH_MAX];     /* PEM certificate (chain): the API serves HTTPS ("" = plain HTTP) */
	char tls_key[VMAC_PATH_MAX];      /* its PEM private key */
	char deploy_keys[VMAC_PATH_MAX];  /* minisign public keys trusted to sign bundles ("" = none) */
	char deploy_require_signature[8]; /* "auto" (on when deploy_keys is set), "yes", "no" */
	uint32_t slice_us;                /* one time slice; a slot is slices_per_slot of them */
	uint32_t slices_per_slot;         /* S: devices one slot can serve */
	uint32_t max_level;               /* K: a block is 2^K slots; levels are 0..K */
	uint32_t default_level;           /* a driver's level when its manifest names none */
	uint32_t
	    reply_deadline_us; /* a reply later than this after the send is a miss (capped at the device's period) */
	uint32_t discovery_period_ms;
	uint32_t clock_sync_ms; /* SYNC to every board this often (docs/TIME.md); 0 = off */
	uint32_t
	    timed_lead_us; /* a TIMED frame's instants at least this after its slot's planned start; 0: half a slot */
	uint32_t watchdog_ms; /* board comm-loss period set at REGISTER */
	uint32_t miss_limit;  /* consecutive misses that drop a device (1 = zero tolerance) */
	uint32_t sleep_s;     /* how long a board without a driver sleeps */
	uint32_t max_devices;
	uint32_t http_header_timeout_s;        /* a request's headers must be in within this */
	uint32_t http_body_timeout_s;          /* and its body within this after them */
	uint32_t http_connections_per_address; /* open API connections from one client address */
	uint32_t attach_max;                   /* devices attaching (driver asked for, not yet registered) at once */
	uint32_t attach_rate;                  /* new attaches a second, in bursts of at most attach_max */
	uint32_t driver_memory_kib;
	uint32_t driver_instructions;
	uint32_t driver_budget_us;   /* wall-clock per driver call; 0 = none */
	uint32_t driver_threads;     /* driver workers; 0 = one per CPU the host may use */
	uint32_t reload_probation_s; /* hot reload: a new version failing within this goes back (0 = none) */
	uint32_t checkpoint_s;       /* a machine's dev.state saved at least this often (0 = only when asked) */
	uint32_t checkpoint_kib;     /* largest checkpoint (encoded dev.state) */
	uint32_t recorder_s;         /* flight recorder: seconds of ticks kept per machine (0 = off) */
	uint32_t recordings_max;     /* recordings kept in the store (the oldest go) */
	int allow_jit;               /* honour a manifest's jit = true */
	int realtime;                /* try SCHED_FIFO and mlockall */
	int cpu_awake;               /* hold /dev/cpu_dma_latency at 0 while the bus runs */
	int cyclic;                  /* serve version-2 boards with the cyclic frame (else unicast UPDATEs) */
	char bus_trust[16];          /* "enrolled": only boards whose key the store holds; "open": any board too */
	/* MQTT (docs/MQTT.md; checked by core/mqtt/mqtt_settings.c): off while mqtt_url is "". */
	char mqtt_url[256];       /* mqtt://HOST:PORT or mqtts://HOST:PORT */
	char ui_url[200];         /* the web UI as a browser elsewhere reaches it ("": from http and the host name) */
	char mqtt_client_id[128]; /* "" = vmac-HOSTNAME */
	char mqtt_host_id[64];    /* this host in topics; "" = the host name */
	char mqtt_user[128];      /* "" = no user name */
	char mqtt_password[256];  /* never printed */
	char mqtt_password_file[VMAC_PATH_MAX]; /* the password, its first line */
	char mqtt_cafile[VMAC_PATH_MAX];        /* mqtts: the CA (PEM); "" = the system's */
	char mqtt_certfile[VMAC_PATH_MAX];      /* mqtts: a client certificate (PEM), with mqtt_keyfile */
	char mqtt_keyfile[VMAC_PATH_MAX];
	char mqtt_prefix[128];                /* topics: PREFIX/HOST/DEVICE/... */
	char mqtt_discovery_prefix[128];      /* Home Assistant's discovery prefix */
	char mqtt_discovery_mode[16];         /* "component" (one config per entity) or "device" (one per machine) */
	int mqtt_commands;                    /* accept operator input from the command topics */
	int mqtt_sparkplug;                   /* also speak Sparkplug B (an Edge Node; docs/MQTT.md) */
	char mqtt_sparkplug_group[128];       /* its group id: spBv1.0/GROUP/... */
	char mqtt_sparkplug_primary_host[64]; /* a Primary Host Application's id: births wait for its STATE */
	uint32_t mqtt_keepalive_s;
	struct vmac_config_driver_setting driver[VMAC_CONFIG_DRIVER_SETTINGS];
	int ndriver;
};

/* Length of one slot in microseconds. */
static inline uint32_t vmac_config_slot_us(const struct vmac_config *c)
{
	return c->slice_us * c->slices_per_slot;
}

void vmac_config_defaults(struct vmac_config *c);
/* scripts_dir and stdlib_dir: the shipped ones of the running program
 * (vmac_root_dir, core/common/paths.h), as vmacd, vmac test and vmac bundle
 * take them before any setting. */
void vmac_config_shipped_dirs(struct vmac_config *c);
/* Apply a Lua config file (plain assignments, evaluated with no library at
 * all; at most 64 KiB). Returns 0, or -1 with err naming the file, line and
 * key. vmac_config_load_text: the same for a file's len bytes already read,
 * name standing for the file in messages. */
int vmac_config_load(struct vmac_config *c, const char *path, char *err, size_t errlen);
int vmac_config_load_text(struct vmac_config *c, const char *name, const char *text, size_t len, char *err,
                          size_t errlen);
/* Apply one "key=value" (the same keys as the file). Returns 0 or -1. */
int vmac_config_set(struct vmac_config *c, const char *key, const char *value, char *err, size_t errlen);
/* The driver.NAME.KEY settings of one driver, copied to out (at most max);
 * returns how many. */
int vmac_config_driver_settings(const struct vmac_config *c, const char *driver, struct vmac_driver_setting *out,
                                int max);
/* Whether bus_trust lets a board without a key attach ("open"). */
int vmac_config_trust_open(const struct vmac_config *c);

/* Cross-field checks (deadline <= period, ...). Returns 0 or -1 with err. */
int vmac_config_check(const struct vmac_config *c, char *err, size_t errlen);

#endif
