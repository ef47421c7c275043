/* vmac-board: the generic peripheral board on POSIX. Runs one or more
 * boards, each with its own simulated plant, in one process on one socket
 * (UDP: plus the discovery listener); the board logic itself is
 * firmware/board.c, untouched by any OS. This file: options, set-up, the
 * loop and the exit; boards.c, dispatch.c and realtime.c do the rest. */
#include <arpa/inet.h>
#include <errno.h>
#include <getopt.h>
#include <inttypes.h>
#include <limits.h>
#include <poll.h>
#include <sched.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <time.h>
#include <unistd.h>

#include "../../core/common/version.h"
#include "boards.h"
#include "realtime.h"

/* The watchdogs, the plants and the printed lines are looked at this often
 * (and no more often, however many frames arrive) while any board is in a
 * session: resolution enough for watchdogs of tens of ms and for the
 * physics. While none is, no watchdog is armed and every output is off:
 * the plants (in steps of at most 10 ms however long the turn) and the
 * lines are looked at every HOUSEKEEP_IDLE_NS, so that a process of idle
 * or sleeping boards does not wake 200 times a second. A registration
 * brings the 5 ms pace back at once (the wait is computed every turn). */
#define HOUSEKEEP_NS 5000000
#define HOUSEKEEP_IDLE_NS 50000000
#define CLOCK_SYNC_NS 1000000000 /* resample realtime - monotonic for the kernel's stamps */
#define DEFAULT_BUS "239.255.86.77:5870"
#define DEFAULT_LATE_US 1000
#define LATE_US_MAX 60000000

static volatile sig_atomic_t stop_signal;

static void on_signal(int sig)
{
	stop_signal = sig;
}

static uint64_t now_ms(void)
{
	return (uint64_t)(vmac_now_ns() / 1000000);
}

static void usage(FILE *f)
{
	fprintf(f, "usage: vmac-board [options]\n"
	           "Run generic vmac I/O boards with simulated plants (see docs/BOARD.md).\n\n"
	           "  --plant KIND      washer, dishwasher, lights or generic (default generic)\n"
	           "  --plant-file FILE a plant model in Lua instead (docs/BOARD.md, \"Plant models\n"
	           "                    in Lua\"): each board runs its own, sandboxed\n"
	           "  --time-scale X    plant time runs X times as fast as the wall clock\n"
	           "                    (0.001..1000, default 1)\n"
	           "  --seed N          a Lua plant's math.random seed; board i gets N + i (default 1)\n"
	           "  --name NAME       board name, [A-Za-z0-9_-], at most 31 (default: the plant's name)\n"
	           "  --driver NAME     driver the board announces (default: the plant's driver)\n"
	           "  --bus GROUP:PORT  UDP: discovery multicast group and port (default " DEFAULT_BUS ")\n"
	           "  --bus eth:IFACE   raw Ethernet on interface IFACE (EtherType 0x88B5; needs CAP_NET_RAW);\n"
	           "                    each board has its own MAC 02:xx:xx:xx:hi:lo (printed at start)\n"
	           "  --iface ADDR      UDP: local interface address (default 127.0.0.1)\n"
	           "  --count N         run N independent boards, named NAME-1..NAME-N, on one socket\n"
	           "                    (1..65535, default 1)\n"
	           "  --major N         major id (default: hash of the name); --minor N (default 0)\n"
	           "  --protocol V      highest protocol version the boards speak: 1 or 2 (default 2)\n"
	           "  --key-file FILE   keyed: the board's 16-byte key, 32 hex digits (vmac board enroll\n"
	           "                    --out FILE writes it); it answers only a host that authenticates\n"
	           "  --key-dir DIR     keyed: each board NAME reads its key from DIR/NAME.key\n"
	           "  --clock-ppm P     simulate each board's clock: its counter runs P ppm fast (-500..500)\n"
	           "  --clock-offset S  ...and reads S seconds ahead of the host's clock (may be negative)\n"
	           "  --clock-jitter-us U  ...and stamps each frame's arrival late by a random delay of\n"
	           "                    mean U us (0..10000); --clock-seed N its random streams, board i\n"
	           "                    N + i (default 1). docs/TIME.md; without any, the counter is\n"
	           "                    CLOCK_MONOTONIC and stamps are the kernel's\n"
	           "  --io-log FILE     write one line per output change and input latch of a TIMED\n"
	           "                    CYCLIC frame to FILE: NAME out|latch HOW true=NS host=NS done=NS\n"
	           "                    digital=0xNN pwm=N clock=STATE (docs/BOARD.md, \"What it prints\")\n"
	           "  --cpu K           run on CPU K only\n"
	           "  --late-us N       print each reply that left more than N us after its request\n"
	           "                    came in (default 1000; 0: never)\n"
	           "  --commands        read operator actions from stdin: 'NAME ACTION VALUE'\n"
	           "                    (e.g. 'lights-1 toggle1 1', 'washer-1 door 0')\n"
	           "  --quiet           print only state changes other than \"known\", safety events\n"
	           "                    and late replies\n"
	           "  --no-realtime     do not ask for SCHED_FIFO and locked memory (asked for by\n"
	           "                    default; refused, one line on stderr and normal scheduling)\n"
	           "  --help, --version this text; the version\n\n"
	           "Prints one line per state change and output change on stdout, and when a board\n"
	           "starts acting at the host's instants or falls back to acting on arrival. On SIGINT or\n"
	           "SIGTERM every board turns its outputs off before the process exits, and prints\n"
	           "its frame counters (with --commands, 'status' prints them at any time).\n");
}

/* A whole number in min..max from text, or -1 with an error printed. */
static int parse_number(const char *option, const char *text, long min, long max, int base, long *out)
{
	char *end;
	long v;
	errno = 0;
	v = strtol(text, &end, base);
	if (!*text || *end || errno || v < min || v > max) {
		fprintf(stderr, "vmac-board: %s takes %ld..%ld, got '%s'\n", option, min, max, text);
		return -1;
	}
	*out = v;
	return 0;
}

/* --cpu K: 2 for a K this machine cannot run us on, 1 for another failure. */
static int pin_to_cpu(long cpu)
{
	cpu_set_t set;
	long cpus = sysconf(_SC_NPROCESSORS_CONF);
	CPU_ZERO(&set);
	CPU_SET((int)cpu, &set);
	if (sched_setaffinity(0, sizeof(set), &set) != 0) {
		if (errno == EINVAL) {
			fprintf(stderr,
			        "vmac-board: --cpu %ld: no such CPU, or not one this process may use "
			        "(this machine has CPUs 0..%ld)\n",
			        cpu, cpus - 1);
			return 2;
		}
		fprintf(stderr, "vmac-board: --cpu %ld: %s\n", cpu, strerror(errno));
		return 1;
	}
	return 0;
}

/* Keyed boards: a second start-up line, after the one tests wait for,
 * naming where the keys came from (never a key). */
static void print_keyed(const struct boards_config *cfg)
{
	if (cfg->key_file)
		printf("vmac-board: keyed: the board answers only a host that authenticates (key file %s)\n",
		       cfg->key_file);
	else if (cfg->key_dir)
		printf("vmac-board: keyed: %s answer only a host that authenticates (keys %s/NAME.key)\n",
		       cfg->count == 1 ? "the board" : "the boards", cfg->key_dir);
}

/* The start-up line: what runs, where, and on Ethernet each board's MAC
 * (a long run of boards: the first and the last, the rest follow from the
 * rule: the last two bytes are the board's number). */
static void print_start(const struct board_set *s, const struct boards_config *cfg, const char *bus, const char *iface,
                        const struct vmac_transport *t, long cpu)
{
	char mac[24], cpu_text[32] = "";
	int32_t i;
	if (cpu >= 0)
		snprintf(cpu_text, sizeof(cpu_text), ", CPU %ld", cpu);
	printf("vmac-board: %ld %s board%s on bus %s", cfg->count, vmac_sim_name(&s->boards[0].sim),
	       cfg->count == 1 ? "" : "s", bus);
	if (!s->eth) {
		printf(" (UDP), interface %s, protocol %u%s\n", iface, (unsigned)cfg->protocol, cpu_text);
		print_keyed(cfg);
		return;
	}
	printf(" (raw Ethernet, interface MAC %s), protocol %u%s, MAC", boards_mac_format(t->mac, mac, sizeof(mac)),
	       (unsigned)cfg->protocol, cpu_text);
	if (s->count <= BOARDS_LIST_MACS_MAX) {
		for (i = 0; i < s->count; i++)
			printf("%s %s %s", i ? "," : "", s->boards[i].board.id.board,
			       boards_mac_format(s->boards[i].mac, mac, sizeof(mac)));
		printf("\n");
		print_keyed(cfg);
		return;
	}
	printf(" %s %s", s->boards[0].board.id.board, boards_mac_format(s->boards[0].mac, mac, sizeof(mac)));
	printf(" .. %s %s (NAME-N has the last two bytes N)\n", s->boards[s->count - 1].board.id.board,
	       boards_mac_format(s->boards[s->count - 1].mac, mac, sizeof(mac)));
	print_keyed(cfg);
}

/* --commands: stdin read without stdio's buffer, so that a line waiting in
 * it never hides from poll. Returns 0, or -1 at end of input. */
static int read_commands(struct board_set *s)
{
	static char buf[512];
	static size_t used;
	ssize_t n = read(STDIN_FILENO, buf + used, sizeof(buf) - 1 - used);
	char *line, *nl;
	if (n < 0)
		return errno == EINTR || errno == EAGAIN ? 0 : -1;
	if (n == 0) {
		if (used > 0) { /* a last line without its newline */
			buf[used] = '\0';
			boards_command(s, buf);
			used = 0;
		}
		return -1;
	}
	used += (size_t)n;
	buf[used] = '\0';
	line = buf;
	while ((nl = strchr(line, '\n')) != NULL) {
		*nl = '\0';
		if (nl > line)
			boards_command(s, line);
		line = nl + 1;
	}
	used = (size_t)(buf + used - line);
	memmove(buf, line, used);
	if (used == sizeof(buf) - 1) { /* a line longer than any command: drop it */
		buf[used] = '\0';
		boards_command(s, buf);
		used = 0;
	}
	return 0;
}

/* What the options ask for. */
struct options {
	struct boards_config cfg;
	const char *bus, *iface;
	const char *io_log;        /* --io-log FILE, or NULL */
	struct vmac_bus_spec spec; /* from bus and iface */
	long cpu, late_us;         /* cpu -1: any */
	int commands, quiet, realtime;
};

/* The running process: its boards, its sockets and what poll watches
 * (the board socket, on UDP the discovery listener, with --commands stdin). */
struct runner {
	struct board_set set;
	struct vmac_transport transport;
	int transport_open, listen_fd;
	struct pollfd pfds[3];
	int nsock, nfds, commands;
	struct vmac_packet *pkts;
};

/* The --clock-* options without a letter of their own. */
enum { OPT_CLOCK_PPM = 0x100, OPT_CLOCK_OFFSET, OPT_CLOCK_JITTER, OPT_CLOCK_SEED, OPT_IO_LOG };

/* A --clock-* number in min..max into *out, the clocks then simulated.
 * Returns -1 to go on, or 2 with the error printed. */
static int clock_number(struct options *o, const char *option, const char *text, double min, double max, double *out)
{
	char *end;
	double v = strtod(text, &end);
	if (!*text || *end || !(v >= min && v <= max)) {
		fprintf(stderr, "vmac-board: %s takes a number %g..%g, got '%s'\n", option, min, max, text);
		return 2;
	}
	*out = v;
	o->cfg.clock.on = 1;
	return -1;
}

/* One option (getopt_long's opt and optarg) into o. Returns -1 to go on,
 * or the exit code: 0 after --help or --version, 2 for a wrong value. */
static int take_option(struct options *o, int opt, const char *arg)
{
	enum vmac_plant_kind kind;
	long number;
	char *end;
	switch (opt) {
	case 'p':
		if (vmac_plant_kind_from_name(arg, &kind) != 0) {
			fprintf(stderr,
			        "vmac-board: unknown plant '%s' (washer, dishwasher, lights, generic; a plant of "
			        "your own: --plant-file FILE)\n",
			        arg);
			return 2;
		}
		o->cfg.plant = arg;
		return -1;
	case 'f': o->cfg.plant_file = arg; return -1;
	case 'T':
		o->cfg.time_scale = strtod(arg, &end);
		if (!*arg || *end || !(o->cfg.time_scale >= 0.001 && o->cfg.time_scale <= 1000)) {
			fprintf(stderr, "vmac-board: --time-scale takes a number 0.001..1000, got '%s'\n", arg);
			return 2;
		}
		return -1;
	case 'S':
		if (parse_number("--seed", arg, 0, LONG_MAX, 0, &number) != 0)
			return 2;
		o->cfg.lua.seed = (uint64_t)number;
		return -1;
	case 'n': o->cfg.name = arg; return -1;
	case 'd': o->cfg.driver = arg; return -1;
	case 'b': o->bus = arg; return -1;
	case 'i': o->iface = arg; return -1;
	case 'c': return parse_number("--count", arg, 1, BOARDS_MAX, 10, &o->cfg.count) != 0 ? 2 : -1;
	case 'M': return parse_number("--major", arg, 0, 0xFFFFFFFFL, 0, &o->cfg.major) != 0 ? 2 : -1;
	case 'm': return parse_number("--minor", arg, 0, 0xFFFFFFFFL, 0, &o->cfg.minor) != 0 ? 2 : -1;
	case 'P':
		if (parse_number("--protocol", arg, VMAC_PROTO_VERSION_MIN, VMAC_PROTO_VERSION, 10, &number) != 0)
			return 2;
		o->cfg.protocol = (uint8_t)number;
		return -1;
	case 'u': return parse_number("--cpu", arg, 0, CPU_SETSIZE - 1, 10, &o->cpu) != 0 ? 2 : -1;
	case 'l': return parse_number("--late-us", arg, 0, LATE_US_MAX, 10, &o->late_us) != 0 ? 2 : -1;
	case 'C': o->commands = 1; return -1;
	case 'q': o->quiet = 1; return -1;
	case 'R': o->realtime = 0; return -1;
	case 'K': o->cfg.key_file = arg; return -1;
	case 'D': o->cfg.key_dir = arg; return -1;
	case OPT_CLOCK_PPM: return clock_number(o, "--clock-ppm", arg, -500, 500, &o->cfg.clock.ppm);
	case OPT_CLOCK_OFFSET: return clock_number(o, "--clock-offset", arg, -1e6, 1e6, &o->cfg.clock.offset_s);
	case OPT_CLOCK_JITTER: return clock_number(o, "--clock-jitter-us", arg, 0, 10000, &o->cfg.clock.jitter_us);
	case OPT_CLOCK_SEED:
		if (parse_number("--clock-seed", arg, 0, LONG_MAX, 0, &number) != 0)
			return 2;
		o->cfg.clock.seed = (uint64_t)number;
		o->cfg.clock.on = 1;
		return -1;
	case OPT_IO_LOG: o->io_log = arg; return -1;
	case 'h': usage(stdout); return 0;
	case 'V': printf("vmac-board %s\n", VMAC_VERSION_STRING); return 0;
	default: usage(stderr); return 2;
	}
}

/* The bus and the interface: the spec the transport opens. Returns -1 to
 * go on, or 2 with what is wrong printed. */
static int take_bus(struct options *o)
{
	if (vmac_bus_spec_parse(o->bus, &o->spec) != 0) {
		fprintf(stderr,
		        "vmac-board: --bus wants MULTICAST_GROUP:PORT (e.g. " DEFAULT_BUS ") or eth:IFACE (e.g. "
		        "eth:eth0), got '%s'\n",
		        o->bus);
		return 2;
	}
	o->cfg.eth = o->spec.kind == VMAC_TRANSPORT_ETH;
	if (o->cfg.eth && o->iface) {
		fprintf(stderr, "vmac-board: --iface is for a UDP bus; on raw Ethernet the interface is the one "
		                "in --bus eth:IFACE\n");
		return 2;
	}
	if (!o->iface)
		o->iface = "127.0.0.1";
	if (!o->cfg.eth && inet_pton(AF_INET, o->iface, &o->spec.iface) != 1) {
		fprintf(stderr, "vmac-board: --iface wants an IPv4 address, got '%s'\n", o->iface);
		return 2;
	}
	return -1;
}

/* The plant's names: the C plant's, or those the Lua plant's file gives
 * (loaded once here, so a file that does not load is refused before any
 * board starts). Returns -1 to go on, or 2 with the reason printed. */
static int take_plant(struct options *o)
{
	static char name[VMAC_NAME_MAX + 1], driver[VMAC_NAME_MAX + 1];
	struct vmac_sim sim;
	char err[VMAC_DRIVER_ERR_MAX], line[sizeof(err)];
	if (!o->cfg.plant_file) {
		vmac_sim_init_c(&sim, o->cfg.plant);
	} else if (vmac_sim_init_lua(&sim, o->cfg.plant_file, &o->cfg.lua, err, sizeof(err)) != 0) {
		fprintf(stderr, "vmac-board: --plant-file: %s\n", boards_one_line(err, line, sizeof(line)));
		return 2;
	}
	snprintf(name, sizeof(name), "%s", vmac_sim_name(&sim));
	snprintf(driver, sizeof(driver), "%s", vmac_sim_driver(&sim));
	vmac_sim_fini(&sim);
	if (!o->cfg.name)
		o->cfg.name = name;
	if (!o->cfg.driver)
		o->cfg.driver = driver;
	return -1;
}

/* The command line into o. Returns -1 to go on, or the exit code. */
static int parse_options(int argc, char **argv, struct options *o)
{
	static const struct option opts[] = {{"plant", required_argument, 0, 'p'},
	                                     {"name", required_argument, 0, 'n'},
	                                     {"plant-file", required_argument, 0, 'f'},
	                                     {"time-scale", required_argument, 0, 'T'},
	                                     {"seed", required_argument, 0, 'S'},
	                                     {"driver", required_argument, 0, 'd'},
	                                     {"bus", required_argument, 0, 'b'},
	                                     {"iface", required_argument, 0, 'i'},
	                                     {"count", required_argument, 0, 'c'},
	                                     {"major", required_argument, 0, 'M'},
	                                     {"minor", required_argument, 0, 'm'},
	                                     {"protocol", required_argument, 0, 'P'},
	                                     {"cpu", required_argument, 0, 'u'},
	                                     {"late-us", required_argument, 0, 'l'},
	                                     {"commands", no_argument, 0, 'C'},
	                                     {"quiet", no_argument, 0, 'q'},
	                                     {"no-realtime", no_argument, 0, 'R'},
	                                     {"key-file", required_argument, 0, 'K'},
	                                     {"key-dir", required_argument, 0, 'D'},
	                                     {"help", no_argument, 0, 'h'},
	                                     {"clock-ppm", required_argument, 0, OPT_CLOCK_PPM},
	                                     {"clock-offset", required_argument, 0, OPT_CLOCK_OFFSET},
	                                     {"clock-jitter-us", required_argument, 0, OPT_CLOCK_JITTER},
	                                     {"clock-seed", required_argument, 0, OPT_CLOCK_SEED},
	                                     {"io-log", required_argument, 0, OPT_IO_LOG},
	                                     {"version", no_argument, 0, 'V'},
	                                     {0, 0, 0, 0}};
	int opt, rc;

	memset(o, 0, sizeof(*o));
	o->cfg.plant = "generic";
	o->cfg.count = 1;
	o->cfg.major = -1;
	o->cfg.protocol = VMAC_PROTO_VERSION;
	o->cfg.time_scale = 1.0;
	o->cfg.clock.seed = 1;
	o->cfg.lua.seed = 1; /* no wall-clock budget: a busy machine must not fail a plant (BOARD.md) */
	o->bus = DEFAULT_BUS;
	o->cpu = -1;
	o->late_us = DEFAULT_LATE_US;
	o->realtime = 1;
	while ((opt = getopt_long(argc, argv, "h", opts, NULL)) != -1)
		if ((rc = take_option(o, opt, optarg)) >= 0)
			return rc;
	if (optind < argc) {
		fprintf(stderr, "vmac-board: unexpected argument '%s'\n", argv[optind]);
		return 2;
	}
	if ((rc = take_plant(o)) >= 0)
		return rc;
	if (o->cfg.key_file && o->cfg.key_dir) {
		fprintf(stderr, "vmac-board: --key-file and --key-dir both given: one board's key, or a folder "
		                "of NAME.key files, not both\n");
		return 2;
	}
	if (o->cfg.key_file && o->cfg.count > 1) {
		fprintf(stderr,
		        "vmac-board: --key-file is one board's key; each of --count %ld boards has its own "
		        "(--key-dir DIR: DIR/NAME-1.key..)\n",
		        o->cfg.count);
		return 2;
	}
	return take_bus(o);
}

/* One socket for every board; on UDP the discovery listener beside it;
 * with --commands, stdin. Returns 0, or -1 with the reason printed. */
static int open_sockets(struct runner *r, const struct options *o)
{
	char err[256];
	if (vmac_transport_open_board(&r->transport, &o->spec, err, sizeof(err)) < 0) {
		fprintf(stderr, "vmac-board: %s\n", err);
		return -1;
	}
	r->transport_open = 1;
	r->pfds[0].fd = r->transport.fd;
	r->pfds[0].events = POLLIN;
	r->nsock = 1;
	if (!o->cfg.eth) {
		r->listen_fd = vmac_transport_listen(&o->spec, err, sizeof(err));
		if (r->listen_fd < 0) {
			fprintf(stderr, "vmac-board: %s\n", err);
			return -1;
		}
		r->pfds[r->nsock].fd = r->listen_fd;
		r->pfds[r->nsock].events = POLLIN;
		r->nsock++;
	}
	r->nfds = r->nsock;
	r->commands = o->commands;
	if (o->commands) {
		r->pfds[r->nfds].fd = STDIN_FILENO;
		r->pfds[r->nfds].events = POLLIN;
		r->nfds++;
	}
	return 0;
}

static void catch_signals(void)
{
	struct sigaction sa;
	memset(&sa, 0, sizeof(sa));
	sa.sa_handler = on_signal;
	sigemptyset(&sa.sa_mask);
	sigaction(SIGINT, &sa, NULL);
	sigaction(SIGTERM, &sa, NULL);
	signal(SIGPIPE, SIG_IGN);
}

/* One batch per ready socket: a flood cannot hold off the watchdogs, and a
 * batch's replies leave together. t is now; a receive error is printed at
 * most once a second. */
static void receive_batches(struct runner *r, int64_t t, int64_t *last_error_ns)
{
	int k;
	for (k = 0; k < r->nsock; k++) {
		int n;
		if (!(r->pfds[k].revents & (POLLIN | POLLERR)))
			continue;
		n = vmac_transport_recv(&r->transport, r->pfds[k].fd, r->pkts, VMAC_TRANSPORT_BATCH);
		if (n > 0) {
			boards_dispatch(&r->set, r->pkts, n, now_ms());
			boards_flush(&r->set);
		} else if (n < 0 && t - *last_error_ns >= CLOCK_SYNC_NS) {
			fprintf(stderr, "vmac-board: receive: %s\n", strerror(-n));
			*last_error_ns = t;
		}
	}
}

/* The loop, until a signal. Returns 0, or 1 when poll fails. It wakes
 * for the housekeeping, for frames, and at the earliest instant a board
 * waits for (to the nanosecond: ppoll, the timer slack at its least). */
static int serve(struct runner *r)
{
	int64_t last_housekeep_ns, last_sync_ns, last_error_ns = 0;

	last_housekeep_ns = last_sync_ns = vmac_now_ns();
	while (!stop_signal) {
		int64_t pace_ns = r->set.known ? HOUSEKEEP_NS : HOUSEKEEP_IDLE_NS;
		int64_t t = vmac_now_ns(), wake_ns = last_housekeep_ns + pace_ns, wait_ns;
		int64_t instant_ns = boards_next_instant(&r->set, t);
		struct timespec ts;
		int ready;
		if (instant_ns < wake_ns)
			wake_ns = instant_ns;
		wait_ns = wake_ns > t ? wake_ns - t : 0;
		ts.tv_sec = (time_t)(wait_ns / 1000000000);
		ts.tv_nsec = (long)(wait_ns % 1000000000);
		ready = ppoll(r->pfds, (nfds_t)r->nfds, &ts, NULL);
		if (ready < 0 && errno != EINTR) {
			perror("vmac-board: poll");
			return 1;
		}
		/* The instants first: they wait for no frame. */
		if (instant_ns != INT64_MAX)
			boards_run_instants(&r->set, vmac_now_ns());
		/* Watchdogs first: frames that queued up while the process could
		 * not run (stopped, starved) must not revive a session that has
		 * already timed out. */
		t = vmac_now_ns();
		if (t - last_housekeep_ns >= pace_ns) {
			boards_clock_poll(&r->set, t);
			boards_housekeep(&r->set, (uint64_t)(t / 1000000));
			if (r->set.io_log)
				fflush(r->set.io_log);
			last_housekeep_ns = t;
			if (t - last_sync_ns >= CLOCK_SYNC_NS) {
				vmac_transport_clock_sync(&r->transport);
				last_sync_ns = t;
			}
		}
		if (ready <= 0)
			continue;
		receive_batches(r, t, &last_error_ns);
		if (r->commands && (r->pfds[r->nsock].revents & (POLLIN | POLLHUP)) && read_commands(&r->set) != 0)
			r->pfds[r->nsock].fd = -1; /* end of input: stop reading */
	}
	return 0;
}

/* The exit: every board safe and reported, its counters (up to
 * BOARDS_LIST_MACS_MAX boards; beyond, their sums), then the process's
 * counts. */
static void finish(struct runner *r, long late_us)
{
	struct board_set *s = &r->set;
	struct vmac_board_counters sum;
	int32_t k;
	memset(&sum, 0, sizeof(sum));
	for (k = 0; k < s->count; k++) {
		const struct vmac_board_counters *c = &s->boards[k].board.counters;
		vmac_board_safe(&s->boards[k].board);
		boards_report(s, k);
		if (s->count <= BOARDS_LIST_MACS_MAX) {
			boards_print_counters(s, k);
			boards_print_clock(s, k);
		}
		sum.frames_ok += c->frames_ok;
		sum.frames_malformed += c->frames_malformed;
		sum.frames_ignored += c->frames_ignored;
		sum.watchdog_trips += c->watchdog_trips;
		sum.auth_failed += c->auth_failed;
	}
	if (s->count > BOARDS_LIST_MACS_MAX)
		printf("vmac-board: all %" PRId32 " boards: frames ok %" PRIu32 ", malformed %" PRIu32
		       ", ignored %" PRIu32 ", watchdog trips %" PRIu32 ", auth_failed %" PRIu32 "\n",
		       s->count, sum.frames_ok, sum.frames_malformed, sum.frames_ignored, sum.watchdog_trips,
		       sum.auth_failed);
	if (s->late_ns > 0)
		printf("vmac-board: %" PRIu64 " late replies (board-side delay over %ld us)\n", s->late_replies,
		       late_us);
	if (s->unroutable > 0)
		printf("vmac-board: %" PRIu64 " frames for no board of this process, ignored\n", s->unroutable);
	if (s->unsent > 0)
		printf("vmac-board: %" PRIu64 " replies the kernel did not take\n", s->unsent);
	printf("vmac-board: stopped by signal %d, all outputs off\n", (int)stop_signal);
	if (s->io_log)
		fflush(s->io_log);
}

int main(int argc, char **argv)
{
	struct options o;
	struct runner r;
	char err[256];
	int rc = parse_options(argc, argv, &o);

	if (rc >= 0)
		return rc;
	if (o.cpu >= 0 && (rc = pin_to_cpu(o.cpu)) != 0)
		return rc;
	setvbuf(stdout, NULL, _IOLBF, 0);
	memset(&r, 0, sizeof(r));
	r.listen_fd = -1;
	rc = boards_init(&r.set, &o.cfg, now_ms(), err, sizeof(err));
	if (rc != 0) {
		fprintf(stderr, "vmac-board: %s\n", err);
		return rc == -2 ? 2 : 1;
	}
	r.set.quiet = o.quiet;
	boards_timed_init(&r.set);
	/* Wake for an instant when it comes, not up to 50 us after (the
	 * default slack of a normal thread; SCHED_FIFO has none). */
	prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
	if (o.io_log && !(r.set.io_log = fopen(o.io_log, "w"))) {
		fprintf(stderr, "vmac-board: --io-log %s: %s\n", o.io_log, strerror(errno));
		boards_fini(&r.set);
		return 1;
	}
	r.set.late_ns = (int64_t)o.late_us * 1000;
	r.set.transport = &r.transport;
	r.pkts = malloc(VMAC_TRANSPORT_BATCH * sizeof(*r.pkts));
	if (!r.pkts) {
		fprintf(stderr, "vmac-board: out of memory\n");
		rc = 1;
	} else if (open_sockets(&r, &o) != 0) {
		rc = 1;
	} else {
		catch_signals();
		if (o.realtime)
			boards_try_realtime();
		if (!o.quiet)
			print_start(&r.set, &o.cfg, o.bus, o.iface, &r.transport, o.cpu);
		rc = serve(&r);
		finish(&r, o.late_us);
	}
	if (r.listen_fd >= 0)
		close(r.listen_fd);
	if (r.transport_open)
		vmac_transport_close(&r.transport);
	free(r.pkts);
	if (r.set.io_log)
		fclose(r.set.io_log);
	boards_fini(&r.set);
	return rc;
}
