/* vmac-board: the generic peripheral board on POSIX. Runs one or more
 * boards (each with its own simulated plant and its own UDP endpoint) in one
 * process; the board logic itself is firmware/board.c, untouched by any OS. */
#include <arpa/inet.h>
#include <errno.h>
#include <getopt.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <unistd.h>

#include "../../core/transport/transport.h"
#include "../board.h"
#include "../plant.h"

#define PLANT_STEP_MAX_S 0.01 /* physics sub-step */

struct posix_board {
	struct vmac_board board;
	struct vmac_plant plant;
	struct vmac_transport transport;
	struct vmac_outputs reported; /* last outputs printed */
	enum vmac_board_state reported_state;
};

static const struct vmac_board_io plant_io = {vmac_plant_io_read, vmac_plant_io_write};
static volatile sig_atomic_t stop_signal;
static int quiet;

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
	           "  --name NAME       board name, [A-Za-z0-9_-], at most 31 (default: the plant's name)\n"
	           "  --driver NAME     driver the board announces (default: the plant's driver)\n"
	           "  --bus GROUP:PORT  discovery group and port (default 239.255.86.77:5870)\n"
	           "  --iface ADDR      local interface address (default 127.0.0.1)\n"
	           "  --count N         run N independent boards, named NAME-1..NAME-N (default 1)\n"
	           "  --major N         major id (default: hash of the name); --minor N (default 0)\n"
	           "  --commands        read operator actions from stdin: 'NAME ACTION VALUE'\n"
	           "                    (e.g. 'lights-1 toggle1 1', 'washer-1 door 0')\n"
	           "  --quiet           print only errors and safety events\n"
	           "  --help            this text\n\n"
	           "Prints one line per state change and output change on stdout. On SIGINT or\n"
	           "SIGTERM every board turns its outputs off before the process exits.\n");
}

static void report(struct posix_board *pb)
{
	struct vmac_board *b = &pb->board;
	if (b->state != pb->reported_state) {
		if (!quiet || b->state != VMAC_BOARD_KNOWN)
			printf("%s: state %s device 0x%08x watchdog %u ms\n", b->id.board,
			       vmac_board_state_name(b->state), (unsigned)b->device_id, (unsigned)b->watchdog_ms);
		pb->reported_state = b->state;
	}
	if (b->outputs.digital != pb->reported.digital || b->outputs.pwm != pb->reported.pwm) {
		if (!quiet)
			printf("%s: outputs digital=0x%02x pwm=%d\n", b->id.board, (unsigned)b->outputs.digital,
			       (int)b->outputs.pwm);
		pb->reported = b->outputs;
	}
}

/* Hand one datagram to a board and send its answer, if any, back to the
 * sender from the board's own socket. */
static void serve(struct posix_board *pb, const struct vmac_packet *in)
{
	struct vmac_packet out;
	int len = vmac_board_receive(&pb->board, in->data, in->len, now_ms(), out.data, sizeof(out.data));
	if (len > 0) {
		out.len = (size_t)len;
		out.addr = in->addr;
		vmac_transport_send(&pb->transport, &out, 1);
	}
}

static void operator_command(struct posix_board *boards, int count, char *line)
{
	char name[64], action[64];
	double value = 0;
	int i, fields = sscanf(line, "%63s %63s %lf", name, action, &value);
	if (fields < 2) {
		fprintf(stderr, "vmac-board: expected 'NAME ACTION VALUE', got: %s", line);
		return;
	}
	for (i = 0; i < count; i++) {
		if (strcmp(boards[i].board.id.board, name) == 0) {
			if (vmac_plant_set(&boards[i].plant, action, value) != 0)
				printf("%s: refused %s %g\n", name, action, value);
			else
				printf("%s: %s %g\n", name, action, value);
			return;
		}
	}
	fprintf(stderr, "vmac-board: no board named %s\n", name);
}

int main(int argc, char **argv)
{
	static const struct option opts[] = {
	    {"plant", required_argument, 0, 'p'},  {"name", required_argument, 0, 'n'},
	    {"driver", required_argument, 0, 'd'}, {"bus", required_argument, 0, 'b'},
	    {"iface", required_argument, 0, 'i'},  {"count", required_argument, 0, 'c'},
	    {"major", required_argument, 0, 'M'},  {"minor", required_argument, 0, 'm'},
	    {"commands", no_argument, 0, 'C'},     {"quiet", no_argument, 0, 'q'},
	    {"help", no_argument, 0, 'h'},         {0, 0, 0, 0}};
	enum vmac_plant_kind kind = VMAC_PLANT_GENERIC;
	const char *name = NULL, *driver = NULL, *bus = "239.255.86.77:5870", *iface = "127.0.0.1";
	long count = 1, major = -1, minor = 0;
	int commands = 0, opt, i, listen_fd = -1, nfds, rc = 0;
	struct vmac_bus_spec spec;
	struct posix_board *boards;
	struct pollfd *pfds;
	struct vmac_packet pkt[16];
	char err[160];
	uint64_t last_step_ms;
	char *end;

	while ((opt = getopt_long(argc, argv, "h", opts, NULL)) != -1) {
		switch (opt) {
		case 'p':
			if (vmac_plant_kind_from_name(optarg, &kind) != 0) {
				fprintf(stderr,
				        "vmac-board: unknown plant '%s' (washer, dishwasher, lights, generic)\n",
				        optarg);
				return 2;
			}
			break;
		case 'n': name = optarg; break;
		case 'd': driver = optarg; break;
		case 'b': bus = optarg; break;
		case 'i': iface = optarg; break;
		case 'c':
			count = strtol(optarg, &end, 10);
			if (*end || count < 1 || count > 4096) {
				fprintf(stderr, "vmac-board: --count takes 1..4096\n");
				return 2;
			}
			break;
		case 'M':
			major = strtol(optarg, &end, 0);
			if (*end || major < 0 || major > 0xFFFFFFFFL) {
				fprintf(stderr, "vmac-board: --major takes 0..4294967295\n");
				return 2;
			}
			break;
		case 'm':
			minor = strtol(optarg, &end, 0);
			if (*end || minor < 0 || minor > 0xFFFFFFFFL) {
				fprintf(stderr, "vmac-board: --minor takes 0..4294967295\n");
				return 2;
			}
			break;
		case 'C': commands = 1; break;
		case 'q': quiet = 1; break;
		case 'h': usage(stdout); return 0;
		default: usage(stderr); return 2;
		}
	}
	if (optind < argc) {
		fprintf(stderr, "vmac-board: unexpected argument '%s'\n", argv[optind]);
		return 2;
	}
	if (!name)
		name = vmac_plant_name(kind);
	if (!driver)
		driver = vmac_plant_default_driver(kind);
	if (vmac_bus_spec_parse(bus, &spec) != 0) {
		fprintf(stderr, "vmac-board: --bus wants MULTICAST_GROUP:PORT, e.g. 239.255.86.77:5870, got '%s'\n",
		        bus);
		return 2;
	}
	if (inet_pton(AF_INET, iface, &spec.iface) != 1) {
		fprintf(stderr, "vmac-board: --iface wants an IPv4 address, got '%s'\n", iface);
		return 2;
	}

	setvbuf(stdout, NULL, _IOLBF, 0);
	if (count > 200) { /* two fds a board at most; raise the soft limit */
		struct rlimit rl;
		if (getrlimit(RLIMIT_NOFILE, &rl) == 0 && rl.rlim_cur < (rlim_t)count + 64) {
			rl.rlim_cur = rl.rlim_max < (rlim_t)count + 64 ? rl.rlim_max : (rlim_t)count + 64;
			setrlimit(RLIMIT_NOFILE, &rl);
		}
	}
	boards = calloc((size_t)count, sizeof(*boards));
	pfds = calloc((size_t)count + 2, sizeof(*pfds));
	if (!boards || !pfds) {
		fprintf(stderr, "vmac-board: out of memory for %ld boards\n", count);
		return 1;
	}
	listen_fd = vmac_transport_listen(&spec, err, sizeof(err));
	if (listen_fd < 0) {
		fprintf(stderr, "vmac-board: %s\n", err);
		rc = 1;
		goto out;
	}
	for (i = 0; i < count; i++) {
		struct vmac_board_identity id;
		struct posix_board *pb = &boards[i];
		memset(&id, 0, sizeof(id));
		char full[80];
		if (count == 1)
			snprintf(full, sizeof(full), "%.40s", name);
		else
			snprintf(full, sizeof(full), "%.40s-%d", name, i + 1);
		if (strlen(full) > VMAC_NAME_MAX || strlen(driver) > VMAC_NAME_MAX) {
			fprintf(stderr, "vmac-board: board and driver names are at most %d characters ('%s')\n",
			        VMAC_NAME_MAX, full);
			rc = 2;
			goto out;
		}
		memcpy(id.board, full, strlen(full) + 1);
		memcpy(id.driver, driver, strlen(driver) + 1);
		id.major = major >= 0 ? (uint32_t)major : vmac_proto_default_major(id.board);
		id.minor = (uint32_t)minor;
		id.caps = vmac_plant_caps(kind);
		{ /* refuse at start what the protocol would refuse on every announce */
			struct vmac_msg probe;
			uint8_t frame[VMAC_FRAME_MAX];
			memset(&probe, 0, sizeof(probe));
			probe.flags = VMAC_FLAG_REPLY;
			probe.channel = VMAC_CH_SYSTEM;
			probe.op = VMAC_SYS_ANNOUNCE;
			memcpy(probe.u.announce.driver, id.driver, sizeof(id.driver));
			memcpy(probe.u.announce.board, id.board, sizeof(id.board));
			probe.u.announce.caps = id.caps;
			if (vmac_proto_encode(&probe, frame, sizeof(frame)) < 0) {
				fprintf(stderr,
				        "vmac-board: invalid name '%s' or driver '%s': names are 1..%d characters of "
				        "A-Z a-z 0-9 _ -\n",
				        id.board, id.driver, VMAC_NAME_MAX);
				rc = 2;
				goto out;
			}
		}
		vmac_plant_init(&pb->plant, kind);
		vmac_board_init(&pb->board, &id, &plant_io, &pb->plant, now_ms());
		pb->reported_state = pb->board.state;
		if (vmac_transport_open_board(&pb->transport, &spec, err, sizeof(err)) < 0) {
			fprintf(stderr, "vmac-board: %s: %s\n", id.board, err);
			rc = 1;
			goto out;
		}
		pfds[i].fd = pb->transport.fd;
		pfds[i].events = POLLIN;
	}
	pfds[count].fd = listen_fd;
	pfds[count].events = POLLIN;
	nfds = (int)count + 1;
	if (commands) {
		pfds[nfds].fd = STDIN_FILENO;
		pfds[nfds].events = POLLIN;
		nfds++;
	}
	signal(SIGINT, on_signal);
	signal(SIGTERM, on_signal);
	signal(SIGPIPE, SIG_IGN);
	if (!quiet)
		printf("vmac-board: %ld %s board%s on bus %s, interface %s\n", count, vmac_plant_name(kind),
		       count == 1 ? "" : "s", bus, iface);

	last_step_ms = now_ms();
	while (!stop_signal) {
		uint64_t t;
		/* Frames wake us at once; otherwise every 5 ms for the watchdog and the
		 * plant physics, which is resolution enough for both. */
		int ready = poll(pfds, (nfds_t)nfds, 5);
		if (ready < 0 && errno != EINTR) {
			perror("vmac-board: poll");
			break;
		}
		/* Watchdog first: frames that queued up while we were stopped must
		 * not revive a session that has already timed out. */
		t = now_ms();
		for (i = 0; i < count; i++) {
			if (vmac_board_poll(&boards[i].board, t))
				printf("%s: watchdog: no frame for %u ms, outputs off\n", boards[i].board.id.board,
				       (unsigned)boards[i].board.watchdog_ms);
		}
		if (ready > 0) {
			for (i = 0; i < count; i++) {
				struct posix_board *pb = &boards[i];
				int n, k;
				if (!(pfds[i].revents & POLLIN))
					continue;
				n = vmac_transport_recv(&pb->transport, pb->transport.fd, pkt, 16);
				for (k = 0; k < n; k++)
					serve(pb, &pkt[k]);
			}
			if (pfds[count].revents & POLLIN) {
				int n = vmac_transport_recv(&boards[0].transport, listen_fd, pkt, 16), k;
				for (k = 0; k < n; k++)
					for (i = 0; i < count; i++)
						serve(&boards[i], &pkt[k]);
			}
			if (commands && (pfds[count + 1].revents & (POLLIN | POLLHUP))) {
				char line[256];
				if (fgets(line, sizeof(line), stdin))
					operator_command(boards, (int)count, line);
				else
					pfds[count + 1].fd = -1; /* EOF: stop reading */
			}
		}
		t = now_ms();
		if (t > last_step_ms) {
			double dt = (double)(t - last_step_ms) / 1000.0;
			while (dt > 0) {
				double step = dt > PLANT_STEP_MAX_S ? PLANT_STEP_MAX_S : dt;
				for (i = 0; i < count; i++)
					vmac_plant_step(&boards[i].plant, step);
				dt -= step;
			}
			last_step_ms = t;
		}
		for (i = 0; i < count; i++)
			report(&boards[i]);
	}
	for (i = 0; i < count; i++) {
		vmac_board_safe(&boards[i].board);
		report(&boards[i]);
	}
	printf("vmac-board: stopped by signal %d, all outputs off\n", (int)stop_signal);
out:
	for (i = 0; i < count; i++)
		if (boards[i].transport.fd > 0)
			vmac_transport_close(&boards[i].transport);
	if (listen_fd >= 0)
		close(listen_fd);
	free(boards);
	free(pfds);
	return rc;
}
