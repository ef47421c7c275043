/* vmac-board's boards: making them (names, identities, MACs, plants), the
 * routing tables that dispatch.c reads, the periodic watchdog and plant
 * step, the lines printed for people and tests, and operator commands. */
#include "boards.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "keyfile.h"

#define PLANT_STEP_MAX_S 0.01    /* physics sub-step */
#define OSC_BACK_NS 4000000000LL /* the oscillator keeps 4.096 s behind its newest: stay within */
#define SESSIONS 65536           /* device_id & 0xFFFF: the host's slot of the device */

static uint32_t identity_hash(uint32_t major, uint32_t minor)
{
	uint32_t h = major * 0x9E3779B1u ^ minor * 0x85EBCA77u;
	return h ^ (h >> 15);
}

/* REGISTER arrives, on UDP, at the one socket every board shares: it is
 * routed by the identity it names. Boards never change identity, so the
 * table is filled once; boards of one identity (--major with --count) sit
 * side by side on the probe sequence. */
static void identity_add(struct board_set *s, int32_t i)
{
	const struct vmac_board_identity *id = &s->boards[i].board.id;
	uint32_t h = identity_hash(id->major, id->minor) & s->identity_mask;
	while (s->by_identity[h] != BOARD_NONE)
		h = (h + 1) & s->identity_mask;
	s->by_identity[h] = i;
}

int32_t boards_by_identity(const struct board_set *s, uint32_t major, uint32_t minor)
{
	int32_t found = BOARD_NONE, i;
	uint32_t h = identity_hash(major, minor) & s->identity_mask;
	for (; (i = s->by_identity[h]) != BOARD_NONE; h = (h + 1) & s->identity_mask) {
		const struct vmac_board *b = &s->boards[i].board;
		if (b->id.major != major || b->id.minor != minor)
			continue;
		if (found == BOARD_NONE)
			found = i;
		if (b->state == VMAC_BOARD_UNKNOWN)
			return i;
	}
	return found;
}

char *boards_mac_format(const uint8_t mac[6], char *buf, size_t len)
{
	snprintf(buf, len, "%02x:%02x:%02x:%02x:%02x:%02x", mac[0], mac[1], mac[2], mac[3], mac[4], mac[5]);
	return buf;
}

/* --key-file or DIR/NAME.key of --key-dir into id, which is then keyed;
 * neither: id stays unkeyed. 0, or -1 with the reason in err. */
static int board_key(const struct boards_config *cfg, struct vmac_board_identity *id, char *err, size_t errlen)
{
	char path[4096];
	if (cfg->key_file)
		snprintf(path, sizeof(path), "%s", cfg->key_file);
	else if (cfg->key_dir)
		snprintf(path, sizeof(path), "%s/%s.key", cfg->key_dir, id->board);
	else
		return 0;
	if (keyfile_read(path, id->key, err, errlen) != 0)
		return -1;
	id->keyed = 1;
	return 0;
}

/* Board i's plant: the C plant named, or its own Lua plant (seed + i). */
static int make_sim(const struct boards_config *cfg, int32_t i, struct vmac_sim *sim, char *err, size_t errlen)
{
	struct vmac_luaplant_limits lim = cfg->lua;
	if (!cfg->plant_file) {
		if (vmac_sim_init_c(sim, cfg->plant) == 0)
			return 0;
		snprintf(err, errlen, "unknown plant '%s'", cfg->plant);
		return -1;
	}
	lim.seed += (uint64_t)i;
	lim.time_scale = cfg->time_scale;
	return vmac_sim_init_lua(sim, cfg->plant_file, &lim, err, errlen);
}

/* Board i's oscillator: at true time 0 (the process's start) its counter
 * reads CLOCK_MONOTONIC + offset, then runs at 1 + ppm. 0, or -2 (an
 * offset that puts the counter below 0) or -1 (no memory) with err. */
static int clock_init(struct board_set *s, const struct boards_config *cfg, int32_t i, char *err, size_t errlen)
{
	struct oscillator_config oc;
	memset(&oc, 0, sizeof(oc));
	oc.offset_s = (double)s->clock_base_ns / 1e9 + cfg->clock.offset_s;
	if (oc.offset_s <= 0) {
		snprintf(err, errlen,
		         "--clock-offset %g: a counter that far behind CLOCK_MONOTONIC (%.0f s since boot) would start "
		         "below 0",
		         cfg->clock.offset_s, (double)s->clock_base_ns / 1e9);
		return -2;
	}
	oc.drift_ppm = cfg->clock.ppm;
	oc.step_at_s = -1;
	oc.jitter_us = cfg->clock.jitter_us;
	oc.seed = cfg->clock.seed + (uint64_t)i;
	s->boards[i].osc = malloc(sizeof(*s->boards[i].osc));
	if (!s->boards[i].osc) {
		snprintf(err, errlen, "out of memory for the clocks of %ld boards", cfg->count);
		return -1;
	}
	oscillator_init(s->boards[i].osc, &oc);
	return 0;
}

uint64_t boards_local_ns(struct board_set *s, int32_t i, int64_t mono_ns, int rx)
{
	struct oscillator *o = s->boards[i].osc;
	int64_t true_ns = mono_ns - s->clock_base_ns, oldest;
	if (!o)
		return mono_ns > 0 ? (uint64_t)mono_ns : 0;
	oldest = o->newest * (int64_t)OSCILLATOR_STEP_NS - OSC_BACK_NS;
	if (true_ns < oldest)
		true_ns = oldest;
	if (true_ns < 0)
		true_ns = 0;
	if (rx)
		true_ns += (int64_t)oscillator_rx_delay_ns(o);
	return oscillator_local_ns(o, (uint64_t)true_ns);
}

void boards_clock_poll(struct board_set *s, int64_t now_ns)
{
	int32_t i;
	for (i = 0; i < s->count; i++) {
		struct vmac_board *b = &s->boards[i].board;
		if (b->clock.state == VMAC_CLOCK_UNSYNCED)
			continue; /* nothing to age: no sync frame yet */
		vmac_board_clock_poll(b, boards_local_ns(s, i, now_ns, 0));
	}
}

void boards_print_clock(const struct board_set *s, int32_t i)
{
	char line[VMAC_REPORT_LINE];
	if (s->boards[i].board.clock.state == VMAC_CLOCK_UNSYNCED && s->boards[i].board.counters.sync_ignored == 0)
		return;
	vmac_report_clock(&s->boards[i].board, 1, line, sizeof(line));
	printf("%s\n", line);
}

int boards_init(struct board_set *s, const struct boards_config *cfg, uint64_t now_ms, char *err, size_t errlen)
{
	uint32_t hash = vmac_proto_default_major(cfg->name), slots = 2;
	int32_t i;
	int rc;

	memset(s, 0, sizeof(*s));
	s->count = (int32_t)cfg->count;
	s->clock_base_ns = vmac_now_ns();
	s->eth = cfg->eth;
	s->time_scale = cfg->time_scale > 0 ? cfg->time_scale : 1.0;
	/* Locally administered, unicast (first byte 0x02); then 3 bytes of the
	 * base name's hash, so processes with other names on one link differ;
	 * then the board's number, so a frame's MAC names its board. */
	s->mac_prefix[0] = 0x02;
	s->mac_prefix[1] = (uint8_t)(hash >> 16);
	s->mac_prefix[2] = (uint8_t)(hash >> 8);
	s->mac_prefix[3] = (uint8_t)hash;
	while (slots < 2u * (uint32_t)cfg->count)
		slots <<= 1;
	s->identity_mask = slots - 1;
	s->boards = calloc((size_t)cfg->count, sizeof(*s->boards));
	s->by_offset = malloc(VMAC_OFFSET_NONE * sizeof(*s->by_offset));
	s->by_session = malloc(SESSIONS * sizeof(*s->by_session));
	s->by_identity = malloc(slots * sizeof(*s->by_identity));
	s->replies = malloc(BOARDS_REPLY_MAX * sizeof(*s->replies));
	s->reply_board = malloc(BOARDS_REPLY_MAX * sizeof(*s->reply_board));
	s->waiting = malloc((size_t)cfg->count * sizeof(*s->waiting));
	if (!s->boards || !s->by_offset || !s->by_session || !s->by_identity || !s->replies || !s->reply_board ||
	    !s->waiting) {
		snprintf(err, errlen, "out of memory for %ld boards", cfg->count);
		boards_fini(s);
		return -1;
	}
	for (i = 0; i < VMAC_OFFSET_NONE; i++)
		s->by_offset[i] = BOARD_NONE;
	for (i = 0; i < SESSIONS; i++)
		s->by_session[i] = BOARD_NONE;
	for (i = 0; i < (int32_t)slots; i++)
		s->by_identity[i] = BOARD_NONE;

	for (i = 0; i < s->count; i++) {
		struct posix_board *pb = &s->boards[i];
		struct vmac_board_identity id;
		char full[80];
		memset(&id, 0, sizeof(id));
		if (cfg->count == 1)
			snprintf(full, sizeof(full), "%.40s", cfg->name);
		else
			snprintf(full, sizeof(full), "%.40s-%ld", cfg->name, (long)i + 1);
		if (strlen(full) > VMAC_NAME_MAX || strlen(cfg->driver) > VMAC_NAME_MAX) {
			snprintf(err, errlen, "board and driver names are at most %d characters ('%s')", VMAC_NAME_MAX,
			         full);
			boards_fini(s);
			return -2;
		}
		memcpy(id.board, full, strlen(full) + 1);
		memcpy(id.driver, cfg->driver, strlen(cfg->driver) + 1);
		id.major = cfg->major >= 0 ? (uint32_t)cfg->major : vmac_proto_default_major(id.board);
		id.minor = (uint32_t)cfg->minor;
		if (make_sim(cfg, i, &pb->sim, err, errlen) != 0) {
			boards_fini(s);
			return -2;
		}
		id.caps = vmac_sim_caps(&pb->sim);
		id.protocol = cfg->protocol;
		if (!vmac_board_identity_valid(&id)) {
			snprintf(err, errlen,
			         "invalid name '%s' or driver '%s': names are 1..%d characters of A-Z a-z 0-9 _ -",
			         id.board, id.driver, VMAC_NAME_MAX);
			boards_fini(s);
			return -2;
		}
		if (board_key(cfg, &id, err, errlen) != 0) {
			boards_fini(s);
			return -2;
		}
		vmac_board_init(&pb->board, &id, &vmac_sim_io, &pb->sim, now_ms);
		explicit_bzero(id.key, sizeof(id.key)); /* the board holds its copy */
		pb->safety = vmac_sim_safety(&pb->sim);
		vmac_report_init(&pb->report, &pb->board, &pb->safety, 0);
		pb->routed_offset = VMAC_OFFSET_NONE;
		if (cfg->clock.on && (rc = clock_init(s, cfg, i, err, errlen)) != 0) {
			boards_fini(s);
			return rc;
		}
		memcpy(pb->mac, s->mac_prefix, sizeof(s->mac_prefix));
		pb->mac[4] = (uint8_t)((i + 1) >> 8);
		pb->mac[5] = (uint8_t)(i + 1);
		identity_add(s, i);
	}
	s->last_step_ms = now_ms;
	return 0;
}

void boards_fini(struct board_set *s)
{
	int32_t i;
	for (i = 0; s->boards && i < s->count; i++) {
		vmac_sim_fini(&s->boards[i].sim);
		free(s->boards[i].osc);
	}
	free(s->boards);
	free(s->by_offset);
	free(s->by_session);
	free(s->by_identity);
	free(s->replies);
	free(s->reply_board);
	free(s->waiting);
	s->waiting = NULL;
	s->boards = NULL;
	s->by_offset = s->by_session = s->by_identity = s->reply_board = NULL;
	s->replies = NULL;
	s->count = 0;
}

void boards_track(struct board_set *s, int32_t i)
{
	struct posix_board *pb = &s->boards[i];
	const struct vmac_board *b = &pb->board;
	uint16_t offset = b->state == VMAC_BOARD_KNOWN ? b->offset : VMAC_OFFSET_NONE;
	int known = b->state == VMAC_BOARD_KNOWN;

	if (known != pb->counted_known) {
		s->known += known ? 1 : -1;
		pb->counted_known = known;
	}
	if (offset != pb->routed_offset) {
		/* Another board may have been given the old offset since (a new
		 * host, a new session): then the entry is its, not ours. */
		if (pb->routed_offset != VMAC_OFFSET_NONE && s->by_offset[pb->routed_offset] == i)
			s->by_offset[pb->routed_offset] = BOARD_NONE;
		if (offset != VMAC_OFFSET_NONE)
			s->by_offset[offset] = i;
		pb->routed_offset = offset;
	}
	/* The session entry is set when a registration gives the board a new
	 * device id, and left in place when the board forgets it: a request of
	 * the old session still reaches this board, which answers it ERROR 1
	 * (not registered) as a board with a socket of its own would. */
	if (b->device_id != pb->routed_device_id) {
		if (b->state == VMAC_BOARD_KNOWN && b->device_id != 0)
			s->by_session[b->device_id & 0xFFFF] = i;
		pb->routed_device_id = b->device_id;
	}
}

/* The trip line carries the board's own times (CLOCK_MONOTONIC ms, the
 * clock vmacd and a test's harness read too): when the last frame came and
 * when the outputs went off, so a test judges the watchdog by them, not by
 * when it happened to read the line. */
void boards_poll_one(struct board_set *s, int32_t i, uint64_t now_ms)
{
	struct vmac_board *b = &s->boards[i].board;
	uint64_t last_ms = b->last_valid_ms;
	char line[VMAC_REPORT_LINE];
	if (vmac_board_poll(b, now_ms)) {
		vmac_report_watchdog(b, line, sizeof(line));
		printf("%s; last frame at %" PRIu64 " ms, off at %" PRIu64 " ms\n", line, last_ms, now_ms);
	}
	boards_track(s, i);
}

void boards_report(struct board_set *s, int32_t i)
{
	struct posix_board *pb = &s->boards[i];
	char line[VMAC_REPORT_LINE];
	pb->report.quiet = s->quiet; /* --quiet is set after the boards are made */
	for (;;) {
		enum vmac_clock_state clock = pb->report.clock;
		if (!vmac_report_next(&pb->report, &pb->board, &pb->safety, line, sizeof(line)))
			break;
		/* A clock line carries the process's CLOCK_MONOTONIC, as a trip line
		 * does: a test judges how long locking took by it. */
		if (pb->report.clock != clock)
			printf("%s; at %" PRId64 " ms\n", line, vmac_now_ns() / 1000000);
		else
			printf("%s\n", line);
	}
}

void boards_print_counters(const struct board_set *s, int32_t i)
{
	char line[VMAC_REPORT_LINE];
	vmac_report_counters(&s->boards[i].board, line, sizeof(line));
	printf("%s\n", line);
	if (vmac_report_timed(&s->boards[i].board, line, sizeof(line)))
		printf("%s\n", line);
}

char *boards_one_line(const char *text, char *out, size_t len)
{
	const char *trace = strstr(text, "\nstack traceback:");
	size_t n = trace ? (size_t)(trace - text) : strlen(text), i;
	if (len == 0)
		return out;
	if (n >= len)
		n = len - 1;
	for (i = 0; i < n; i++)
		out[i] = (unsigned char)text[i] < 0x20 || text[i] == 0x7F ? ' ' : text[i];
	out[n] = '\0';
	return out;
}

void boards_housekeep(struct board_set *s, uint64_t now_ms)
{
	double dt_s = now_ms > s->last_step_ms ? (double)(now_ms - s->last_step_ms) / 1000.0 : 0.0;
	char why[VMAC_DRIVER_ERR_MAX];
	int32_t i;

	for (i = 0; i < s->count; i++) {
		struct posix_board *pb = &s->boards[i];
		boards_poll_one(s, i, now_ms);
		double left_s = dt_s * s->time_scale;
		int rc = 0;
		while (left_s > 0 && rc == 0) {
			double step_s = left_s > PLANT_STEP_MAX_S ? PLANT_STEP_MAX_S : left_s;
			rc = vmac_sim_step(&pb->sim, step_s);
			left_s -= step_s;
		}
		if (rc == -2)
			printf("%s: plant failed: %s; its inputs hold their last values\n", pb->board.id.board,
			       boards_one_line(vmac_sim_failure(&pb->sim), why, sizeof(why)));
		boards_report(s, i);
	}
	if (now_ms > s->last_step_ms)
		s->last_step_ms = now_ms;
}

void boards_command(struct board_set *s, const char *line)
{
	char name[64], action[64];
	double value = 0;
	int32_t i;
	int fields = sscanf(line, "%63s %63s %lf", name, action, &value);
	if (fields == 1 && strcmp(name, "status") == 0) {
		for (i = 0; i < s->count; i++) {
			boards_print_counters(s, i);
			boards_print_clock(s, i);
		}
		return;
	}
	if (fields < 2) {
		fprintf(stderr, "vmac-board: expected 'NAME ACTION VALUE', got: %s\n", line);
		return;
	}
	for (i = 0; i < s->count; i++) {
		struct posix_board *pb = &s->boards[i];
		if (strcmp(pb->board.id.board, name) == 0) {
			if (fields == 2 && strcmp(action, "status") == 0) {
				boards_print_counters(s, i);
				boards_print_clock(s, i);
				return;
			}
			char why[VMAC_DRIVER_ERR_MAX + 128], one[sizeof(why)];
			if (vmac_sim_set(&pb->sim, action, value, why, sizeof(why)) != 0)
				printf("%s: refused %s %g: %s\n", name, action, value,
				       boards_one_line(why, one, sizeof(one)));
			else
				printf("%s: %s %g\n", name, action, value);
			boards_report(s, i); /* an action may have begun an unsafe episode */
			return;
		}
	}
	fprintf(stderr, "vmac-board: no board named %s\n", name);
}
