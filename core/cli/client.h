/* vmac's HTTP client for a running host (libcurl): the bearer token, one
 * call, and one call with its answer shown for people. Used by every vmac
 * command on the host's API (docs/CLI.md). */
#ifndef VMAC_CLI_CLIENT_H
#define VMAC_CLI_CLIENT_H

#include <jansson.h>
#include <stddef.h>

#include "command.h"

struct vmac_buffer {
	char *data; /* NUL-terminated; free() it */
	size_t len;
};

/* The token for every call (docs/CLI.md, "Tokens"): token, else the first
 * line of file (each already their option or its environment variable:
 * command.c); neither, none. 0, or -1 after saying why (a file that cannot
 * be read). */
int vmac_client_token(const char *token, const char *file);

/* The URL of path (starting with /) on host: "ADDR:PORT" means
 * http://ADDR:PORT; "https://ADDR:PORT" (or "http://...") is taken as
 * given. A host's self-signed certificate is trusted through $VMAC_CACERT
 * (a PEM file). */
void vmac_client_url(char *out, size_t len, const char *host, const char *path);

/* method url [body as JSON]: 0 with the HTTP code and the answer in out, or
 * -1 when the host cannot be reached (err says why). */
int vmac_client_call(const char *method, const char *url, const char *body, struct vmac_buffer *out, long *code,
                     char *err, size_t errlen);

/* POST url with body (len bytes) as text/x-lua (a driver upload); as
 * vmac_client_call. */
int vmac_client_upload(const char *url, const char *body, size_t len, struct vmac_buffer *out, long *code, char *err,
                       size_t errlen);

/* GET url as a stream: on_data gets the bytes as they come, until the host
 * ends the answer (or on_data returns nonzero). 0 with the HTTP code, or -1
 * when the host cannot be reached (err says why). */
int vmac_client_stream(const char *url, int (*on_data)(void *ctx, const char *data, size_t len), void *ctx, long *code,
                       char *err, size_t errlen);

/* method path [body, len bytes: a driver upload] on the host of a's --http,
 * the answer shown by show (or printed as it is with --json): 0 on HTTP
 * 200, 1 otherwise (said why on stderr). */
int vmac_client_run(const struct vmac_cmd_args *a, const char *method, const char *path, const char *body, size_t len,
                    void (*show)(json_t *answer));

/* The same with a JSON body (NULL: none). */
int vmac_client_run_json(const struct vmac_cmd_args *a, const char *method, const char *path, const char *json,
                         void (*show)(json_t *answer));

/* One more header for the next calls ("Name: value"; copied), e.g. a
 * bundle's Vmac-Signature. */
void vmac_client_header(const char *header);

/* What to tell a person about a 401 or 403. */
const char *vmac_client_auth_hint(void);

#endif
