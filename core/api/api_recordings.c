/* The flight recordings (docs/API.md "GET /api/recordings", docs/RECORDING.md):
 * GET /api/recordings lists what the store keeps, newest first (?machine=
 * NAME: one machine's); GET /api/recordings/ID is the recording's file;
 * POST /api/devices/NAME/record captures a running machine's now. */
#include "http_internal.h"

#include <jansson.h>
#include <microhttpd.h>
#include <stdlib.h>
#include <string.h>

#include "../common/errors.h"

static void append(void *ctx, const struct vmac_recording_info *r)
{
	json_array_append_new(ctx, json_pack("{s:I, s:s, s:s, s:s, s:s, s:f, s:I}", "id", (json_int_t)r->id, "machine",
	                                     r->machine, "driver", r->driver, "version", r->version, "reason",
	                                     r->reason, "time", r->time, "size", (json_int_t)r->size));
}

enum MHD_Result http_recordings(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	const char *machine = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "machine");
	char err[512];
	json_t *list = json_array();
	(void)k;
	if (vmac_store_recording_list(h->store, machine, append, list, err, sizeof(err)) < 0) {
		json_decref(list);
		return http_reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, http_error_body(err));
	}
	return http_reply(c, MHD_HTTP_OK, json_pack("{s:o}", "recordings", list));
}

enum MHD_Result http_recording(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	const char *id = k->route.name;
	struct MHD_Response *r;
	enum MHD_Result ret;
	char err[512], *data;
	size_t len;
	int rc = vmac_store_recording_get(h->store, strtoll(id, NULL, 10), &data, &len, err, sizeof(err));
	if (rc < 0)
		return http_reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, http_error_body(err));
	if (rc == 0)
		return http_reply(c, MHD_HTTP_NOT_FOUND, http_error_body("no such recording (GET /api/recordings)"));
	r = MHD_create_response_from_buffer(len, data, MHD_RESPMEM_MUST_FREE);
	if (!r) {
		free(data);
		return MHD_NO;
	}
	MHD_add_response_header(r, "Content-Type", "application/x-ndjson");
	MHD_add_response_header(r, "Cache-Control", "no-store");
	ret = MHD_queue_response(c, MHD_HTTP_OK, r);
	MHD_destroy_response(r);
	return ret;
}

enum MHD_Result http_record(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	const char *device = k->route.name;
	char reply[300];
	int rc = vmac_bus_request_record(h->bus, device, 2000, reply, sizeof(reply));
	if (rc == -VMAC_ENOTRUNNING)
		return http_reply(c, MHD_HTTP_NOT_FOUND, http_error_body(reply));
	if (rc == -VMAC_EBUSY)
		return http_reply(c, MHD_HTTP_SERVICE_UNAVAILABLE, http_error_body(reply));
	if (rc != 0)
		return http_reply(c, MHD_HTTP_CONFLICT, http_error_body(reply));
	return http_reply(c, MHD_HTTP_OK, json_pack("{s:b, s:s}", "ok", 1, "text", reply));
}
