/* vmac schedule: GET /api/schedule for people: per row of the table its
 * services, the instants they latch and release, and the deadline
 * violation vector of each; then the violations, the latest first
 * (docs/CLI.md, docs/SCHEDULER.md "The static time manager"). */
#include "schedule.h"

#include <jansson.h>
#include <stdio.h>

#include "client.h"

static long long integer(json_t *o, const char *key)
{
	return (long long)json_integer_value(json_object_get(o, key));
}

/* An instant of the table, or "-" for a service acting on arrival. */
static const char *instant(json_t *e, const char *key, char *buf, size_t len)
{
	json_t *v = json_object_get(e, key);
	if (!json_is_integer(v))
		return "-";
	snprintf(buf, len, "%lld", (long long)json_integer_value(v));
	return buf;
}

static void show_row(json_t *row)
{
	json_t *e;
	size_t i;
	json_array_foreach(json_object_get(row, "devices"), i, e)
	{
		json_t *v = json_object_get(e, "violations");
		char latch[24], release[24], slot[24] = "", offset[24] = "";
		if (i == 0) { /* the row's own columns, on its first service's line */
			snprintf(slot, sizeof(slot), "%lld", integer(row, "slot"));
			snprintf(offset, sizeof(offset), "%lld", integer(row, "offset_us"));
		}
		printf("%5s %10s  %-16s %-16s %5lld %5lld  %-8s %10s %10s  %6lld %6lld %6lld\n", slot, offset,
		       json_string_value(json_object_get(e, "name")),
		       json_is_string(json_object_get(e, "machine")) ? json_string_value(json_object_get(e, "machine"))
		                                                     : "-",
		       integer(e, "level"), integer(e, "slice"), json_string_value(json_object_get(e, "pattern")),
		       instant(e, "latch_us", latch, sizeof(latch)), instant(e, "release_us", release, sizeof(release)),
		       integer(v, "misses"), integer(v, "misses_host"), integer(v, "driver_late"));
	}
}

static void show_schedule(json_t *a)
{
	json_t *row, *v;
	size_t i;
	printf("%lld rows of %lld us (the longest period in use)\n", integer(a, "slots"), integer(a, "slot_us"));
	if (json_array_size(json_object_get(a, "timeline")) == 0) {
		printf("no device in the schedule\n");
		return;
	}
	printf("%5s %10s  %-16s %-16s %5s %5s  %-8s %10s %10s  %6s %6s %6s\n", "ROW", "OFFSET_US", "DEVICE", "MACHINE",
	       "LEVEL", "SLICE", "PATTERN", "LATCH_US", "RELEASE_US", "MISS", "HOST", "LATE");
	json_array_foreach(json_object_get(a, "timeline"), i, row) show_row(row);
	if (json_array_size(json_object_get(a, "violated")) == 0) {
		printf("\nno deadline violated\n");
		return;
	}
	printf("\ndeadline violations, the latest first:\n");
	json_array_foreach(json_object_get(a, "violated"), i, v) printf(
	    "  %-16s row %-5lld %-12s %.3f s ago\n", json_string_value(json_object_get(v, "name")), integer(v, "slot"),
	    json_string_value(json_object_get(v, "kind")), json_number_value(json_object_get(v, "ago_s")));
}

static int schedule_run(const struct vmac_cmd_args *a)
{
	return vmac_client_run(a, "GET", "/api/schedule", NULL, 0, show_schedule);
}

const struct vmac_cmd vmac_schedule_cmd = {
    .name = "schedule",
    .summary = "the schedule as a time-manager table, with each service's deadline violations",
    .about = "Show a running vmacd's schedule as seed 002's static time manager's table (GET /api/schedule,\n"
             "the JSON with --json): per row (slot) of the longest period in use, each board it serves,\n"
             "its machine, level, slice, timing pattern, the instants its inputs are latched and its\n"
             "outputs released (us after the table's start; - on arrival), and its deadline violations:\n"
             "MISS replies not in time, HOST requests the host failed to send, LATE driver ticks not done\n"
             "by the machine's next service. Then every violating board, the latest first.\n"
             "Needs a token of scope read or more.\n"
             "Exit 0 done, 1 the host refused or could not be reached, 2 wrong usage.\n",
    .common = VMAC_CMD_API,
    .run = schedule_run};
