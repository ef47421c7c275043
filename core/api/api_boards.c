/* Enrolling boards over the API (docs/API.md, "Boards"; docs/SECURITY.md):
 * GET /api/boards lists the enrolled boards (a fingerprint of each key,
 * never the key) and the boards waiting for approval; POST
 * /api/boards/NAME enrolls one, with the key given or one made here and
 * answered once; POST /api/boards/NAME/remove takes a key away. The store
 * holds the keys; the main thread hands them to the bus (mainloop.c). */
#include <microhttpd.h>
#include <sodium.h>
#include <stdio.h>
#include <string.h>

#include "../store/store.h"
#include "http_internal.h"

static json_t *enrolled_json(const struct vmac_board_key *k, const struct vmac_status *s)
{
	const char *state = NULL;
	int i, authenticated = 0;
	for (i = 0; i < s->ndevices; i++)
		if (strcmp(s->devices[i].name, k->board) == 0) {
			state = s->devices[i].state;
			authenticated = s->devices[i].authenticated;
		}
	return json_pack("{s:s, s:s, s:f, s:s, s:o, s:b}", "board", k->board, "fingerprint", k->fingerprint, "created",
	                 k->created, "note", k->note, "state", state ? json_string(state) : json_null(),
	                 "authenticated", authenticated);
}

struct listing {
	json_t *enrolled;
	const struct vmac_status *status;
};

static void list_one(void *ctx, const struct vmac_board_key *k)
{
	struct listing *l = ctx;
	json_array_append_new(l->enrolled, enrolled_json(k, l->status));
}

/* GET /api/boards */
enum MHD_Result http_boards(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	struct listing l;
	json_t *waiting = json_array(), *root;
	char err[512];
	int i, rc;
	(void)k;
	l.enrolled = json_array();
	pthread_mutex_lock(&h->status_lock);
	vmac_bus_status(h->bus, &h->status);
	l.status = &h->status;
	rc = vmac_board_key_list(h->store, list_one, &l, err, sizeof(err));
	for (i = 0; i < h->status.ndevices; i++) {
		const struct vmac_device_status *d = &h->status.devices[i];
		if (strcmp(d->state, "waiting") == 0)
			json_array_append_new(waiting,
			                      json_pack("{s:s, s:s, s:I, s:I, s:s, s:s}", "board", d->name, "driver",
			                                d->driver, "major", (json_int_t)d->major, "minor",
			                                (json_int_t)d->minor, "address", d->address, "note", d->note));
	}
	pthread_mutex_unlock(&h->status_lock);
	if (rc < 0) {
		json_decref(l.enrolled);
		json_decref(waiting);
		return http_reply(c, rc == -VMAC_ESTOREFULL ? 507 : MHD_HTTP_INTERNAL_SERVER_ERROR,
		                  http_error_body(err));
	}
	root = json_pack("{s:s, s:o, s:o}", "bus_trust", h->cfg.bus_trust, "enrolled", l.enrolled, "waiting", waiting);
	return http_reply(c, MHD_HTTP_OK, root);
}

/* 32 hex digits into key: 0, or -1. */
static int parse_key(const char *hex, uint8_t key[VMAC_BOARD_KEY_LEN])
{
	size_t n;
	if (strlen(hex) != 2 * VMAC_BOARD_KEY_LEN ||
	    sodium_hex2bin(key, VMAC_BOARD_KEY_LEN, hex, strlen(hex), NULL, &n, NULL) != 0 || n != VMAC_BOARD_KEY_LEN)
		return -1;
	return 0;
}

/* POST /api/boards/NAME {"key": HEX?, "replace": bool?, "note": text?} */
enum MHD_Result http_board_enroll(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	const char *board = k->route.name, *hex = NULL, *note = "";
	uint8_t key[VMAC_BOARD_KEY_LEN];
	char fp[VMAC_BOARD_FINGERPRINT_LEN + 1], keyhex[2 * VMAC_BOARD_KEY_LEN + 1], err[512], text[256];
	json_t *root = NULL, *body;
	json_error_t jerr;
	int replace = 0, made = 0, rc;
	if (!vmac_board_name_valid(board))
		return http_reply(c, MHD_HTTP_BAD_REQUEST,
		                  http_error_body("a board's name is 1..31 of A-Z a-z 0-9 _ - (what it announces)"));
	if (k->too_big)
		return http_reply(c, MHD_HTTP_CONTENT_TOO_LARGE, http_error_body("request body too large"));
	if (k->len > 0) {
		root = json_loadb(k->body, k->len, 0, &jerr);
		if (!root || !json_is_object(root) ||
		    json_unpack_ex(root, &jerr, 0, "{s?s, s?b, s?s}", "key", &hex, "replace", &replace, "note",
		                   &note) != 0) {
			json_decref(root);
			return http_reply(
			    c, MHD_HTTP_BAD_REQUEST,
			    http_error_body("expected {\"key\": \"32 hex digits\" (optional: one is made), "
			                    "\"replace\": true|false, \"note\": \"...\"}"));
		}
	}
	if (strlen(note) > VMAC_BOARD_NOTE_MAX) {
		json_decref(root);
		return http_reply(c, MHD_HTTP_BAD_REQUEST, http_error_body("note: at most 120 characters"));
	}
	if (hex && parse_key(hex, key) != 0) {
		json_decref(root);
		return http_reply(c, MHD_HTTP_BAD_REQUEST,
		                  http_error_body("key: 32 hex digits (16 bytes), as vmac board enroll --out writes"));
	}
	if (!hex) {
		randombytes_buf(key, sizeof(key));
		made = 1;
	}
	rc = vmac_board_key_set(h->store, board, key, replace, note, err, sizeof(err));
	json_decref(root);
	if (rc < 0) {
		sodium_memzero(key, sizeof(key));
		return http_reply(c, rc == -VMAC_ESTOREFULL ? 507 : MHD_HTTP_INTERNAL_SERVER_ERROR,
		                  http_error_body(err));
	}
	if (rc == 1) {
		sodium_memzero(key, sizeof(key));
		snprintf(err, sizeof(err),
		         "%s is enrolled already: replace its key with \"replace\": true (vmac board enroll --replace)",
		         board);
		return http_reply(c, MHD_HTTP_CONFLICT, http_error_body(err));
	}
	vmac_board_key_fingerprint(key, fp);
	http_audit_detail(k, "enroll %s key %s%s", board, fp, replace ? " (replace)" : "");
	snprintf(text, sizeof(text), "%s enrolled%s, key %s (through the API)", board,
	         replace ? " or its key replaced" : "", fp);
	vmac_event_log_add(h->log, "enrolled", board, text);
	vmac_bus_wake_main(h->bus); /* the main thread hands the bus the keys now */
	body = json_pack("{s:s, s:s}", "board", board, "fingerprint", fp);
	if (made) { /* said once, here: the store keeps it for the bus, no listing shows it */
		sodium_bin2hex(keyhex, sizeof(keyhex), key, sizeof(key));
		json_object_set_new(body, "key", json_string(keyhex));
		sodium_memzero(keyhex, sizeof(keyhex));
	}
	sodium_memzero(key, sizeof(key));
	return http_reply(c, MHD_HTTP_OK, body);
}

/* POST /api/boards/NAME/remove */
enum MHD_Result http_board_remove(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	const char *board = k->route.name;
	char err[512], text[200];
	int rc;
	http_audit_detail(k, "remove %s", board);
	rc = vmac_board_key_remove(h->store, board, err, sizeof(err));
	if (rc < 0)
		return http_reply(c, rc == -VMAC_ESTOREFULL ? 507 : MHD_HTTP_INTERNAL_SERVER_ERROR,
		                  http_error_body(err));
	if (rc == 1) {
		snprintf(err, sizeof(err), "%s is not enrolled", board);
		return http_reply(c, MHD_HTTP_NOT_FOUND, http_error_body(err));
	}
	snprintf(text, sizeof(text), "%s's key removed (through the API): it is dropped if it runs", board);
	vmac_event_log_add(h->log, "removed", board, text);
	vmac_bus_wake_main(h->bus);
	return http_reply(c, MHD_HTTP_OK, json_pack("{s:s, s:b}", "board", board, "removed", 1));
}
