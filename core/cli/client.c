/* vmac's HTTP client: see client.h. */
#include "client.h"

#include <curl/curl.h>
#include <errno.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static char bearer[256];

int vmac_client_token(const char *token, const char *file)
{
	if (token) {
		snprintf(bearer, sizeof(bearer), "%s", token);
	} else if (file) {
		FILE *f = fopen(file, "r");
		if (!f || !fgets(bearer, sizeof(bearer), f)) {
			fprintf(stderr, "vmac: cannot read a token from %s: %s\n", file,
			        f ? "empty file" : strerror(errno));
			if (f)
				fclose(f);
			return -1;
		}
		fclose(f);
		bearer[strcspn(bearer, "\r\n")] = 0;
	}
	return 0;
}

const char *vmac_client_auth_hint(void)
{
	return bearer[0] ? "(the token is not valid there, or lacks the scope: docs/API.md, \"Access\")"
	                 : "(give a token with --token, $VMAC_TOKEN or --token-file; vmac token create makes one)";
}

static size_t collect(char *ptr, size_t size, size_t nmemb, void *ud)
{
	struct vmac_buffer *b = ud;
	size_t n = size * nmemb;
	char *p;
	if (b->len + n > (16u << 20))
		return 0; /* refuse absurd answers */
	p = realloc(b->data, b->len + n + 1);
	if (!p)
		return 0;
	b->data = p;
	memcpy(b->data + b->len, ptr, n);
	b->len += n;
	b->data[b->len] = '\0';
	return n;
}

static int call(const char *method, const char *url, const char *body, size_t len, const char *type,
                struct vmac_buffer *out, long *code, char *err, size_t errlen);

void vmac_client_url(char *out, size_t len, const char *host, const char *path)
{
	size_t n = strlen(host);
	while (n > 0 && host[n - 1] == '/')
		n--;
	if (strncmp(host, "http://", 7) == 0 || strncmp(host, "https://", 8) == 0)
		snprintf(out, len, "%.*s%s", (int)n, host, path);
	else
		snprintf(out, len, "http://%.*s%s", (int)n, host, path);
}

/* TLS: the CA of $VMAC_CACERT, for a host with a self-signed certificate. */
static void trust(CURL *c)
{
	const char *ca = getenv("VMAC_CACERT");
	if (ca && ca[0])
		curl_easy_setopt(c, CURLOPT_CAINFO, ca);
}

int vmac_client_call(const char *method, const char *url, const char *body, struct vmac_buffer *out, long *code,
                     char *err, size_t errlen)
{
	return call(method, url, body, body ? strlen(body) : 0, "Content-Type: application/json", out, code, err,
	            errlen);
}

int vmac_client_upload(const char *url, const char *body, size_t len, struct vmac_buffer *out, long *code, char *err,
                       size_t errlen)
{
	return call("POST", url, body, len, "Content-Type: application/octet-stream", out, code, err, errlen);
}

static char extra_header[8192]; /* vmac_client_header */

void vmac_client_header(const char *header)
{
	snprintf(extra_header, sizeof(extra_header), "%s", header);
}

/* A libcurl handle for url with the bearer token's header in *headers and
 * the host's certificate trusted; NULL with err. */
static CURL *open_call(const char *url, struct curl_slist **headers, char *err, size_t errlen)
{
	CURL *c = curl_easy_init();
	char auth[300];
	*headers = NULL;
	if (!c) {
		snprintf(err, errlen, "cannot initialise libcurl");
		return NULL;
	}
	if (bearer[0]) {
		snprintf(auth, sizeof(auth), "Authorization: Bearer %s", bearer);
		*headers = curl_slist_append(*headers, auth);
	}
	if (extra_header[0])
		*headers = curl_slist_append(*headers, extra_header);
	curl_easy_setopt(c, CURLOPT_URL, url);
	trust(c);
	curl_easy_setopt(c, CURLOPT_CONNECTTIMEOUT_MS, 3000L);
	curl_easy_setopt(c, CURLOPT_NOSIGNAL, 1L);
	return c;
}

static int call(const char *method, const char *url, const char *body, size_t len, const char *type,
                struct vmac_buffer *out, long *code, char *err, size_t errlen)
{
	struct curl_slist *headers;
	CURL *c = open_call(url, &headers, err, errlen);
	CURLcode rc;
	*code = 0;
	if (!c)
		return -1;
	if (body) {
		headers = curl_slist_append(headers, type);
		curl_easy_setopt(c, CURLOPT_POSTFIELDSIZE, (long)len);
		curl_easy_setopt(c, CURLOPT_POSTFIELDS, body);
	}
	curl_easy_setopt(c, CURLOPT_HTTPHEADER, headers);
	curl_easy_setopt(c, CURLOPT_CUSTOMREQUEST, method);
	curl_easy_setopt(c, CURLOPT_WRITEFUNCTION, collect);
	curl_easy_setopt(c, CURLOPT_WRITEDATA, out);
	curl_easy_setopt(c, CURLOPT_TIMEOUT_MS, 60000L); /* a reload of many machines takes a while */
	rc = curl_easy_perform(c);
	curl_easy_getinfo(c, CURLINFO_RESPONSE_CODE, code);
	curl_easy_cleanup(c);
	curl_slist_free_all(headers);
	if (rc != CURLE_OK) {
		snprintf(err, errlen,
		         "cannot reach the host at %s: %s (is vmacd running? pick it with --http ADDR:PORT)", url,
		         curl_easy_strerror(rc));
		return -1;
	}
	return 0;
}

struct stream {
	int (*on_data)(void *ctx, const char *data, size_t len);
	void *ctx;
};

static size_t stream_chunk(char *ptr, size_t size, size_t nmemb, void *ud)
{
	struct stream *st = ud;
	size_t n = size * nmemb;
	return st->on_data(st->ctx, ptr, n) == 0 ? n : 0;
}

int vmac_client_stream(const char *url, int (*on_data)(void *ctx, const char *data, size_t len), void *ctx, long *code,
                       char *err, size_t errlen)
{
	struct curl_slist *headers;
	CURL *c = open_call(url, &headers, err, errlen);
	CURLcode rc;
	struct stream st = {on_data, ctx};
	*code = 0;
	if (!c)
		return -1;
	if (headers)
		curl_easy_setopt(c, CURLOPT_HTTPHEADER, headers);
	curl_easy_setopt(c, CURLOPT_WRITEFUNCTION, stream_chunk);
	curl_easy_setopt(c, CURLOPT_WRITEDATA, &st);
	/* The host sends a keep-alive every 15 s: a minute of silence means it is gone. */
	curl_easy_setopt(c, CURLOPT_LOW_SPEED_LIMIT, 1L);
	curl_easy_setopt(c, CURLOPT_LOW_SPEED_TIME, 60L);
	rc = curl_easy_perform(c);
	curl_easy_getinfo(c, CURLINFO_RESPONSE_CODE, code);
	curl_easy_cleanup(c);
	curl_slist_free_all(headers);
	if (rc != CURLE_OK && rc != CURLE_WRITE_ERROR) {
		snprintf(err, errlen, "%s: %s", url, curl_easy_strerror(rc));
		return *code ? 0 : -1;
	}
	return 0;
}

/* vmac_client_run and vmac_client_run_json: body (len bytes) as a driver
 * upload (upload set) or as JSON. */
/* A 403 about a bundle's signature (docs/API.md), not about the token. */
static int is_signature_refusal(json_t *answer)
{
	const char *code = json_string_value(json_object_get(answer, "code"));
	return code && strncmp(code, "ESIG", 4) == 0;
}

static int run(const struct vmac_cmd_args *a, const char *method, const char *path, const char *body, size_t len,
               int upload, void (*show)(json_t *answer))
{
	char url[512], err[600];
	struct vmac_buffer b = {NULL, 0};
	long code = 0;
	json_t *answer;
	json_error_t jerr;
	int rc;
	vmac_client_url(url, sizeof(url), a->opt[VMAC_CMD_HTTP], path);
	curl_global_init(CURL_GLOBAL_DEFAULT);
	rc = upload ? vmac_client_upload(url, body, len, &b, &code, err, sizeof(err))
	            : vmac_client_call(method, url, body, &b, &code, err, sizeof(err));
	curl_global_cleanup();
	if (rc != 0) {
		fprintf(stderr, "vmac: %s\n", err);
		return 1;
	}
	if (a->opt[VMAC_CMD_JSON]) {
		printf("%s\n", b.data ? b.data : "");
		free(b.data);
		return code == 200 ? 0 : 1;
	}
	answer = json_loads(b.data ? b.data : "", 0, &jerr);
	free(b.data);
	if (code == 401 || (code == 403 && !is_signature_refusal(answer))) {
		fprintf(stderr, "vmac: HTTP %ld: %s\n%s\n", code, json_string_value(json_object_get(answer, "error")),
		        vmac_client_auth_hint());
		json_decref(answer);
		return 1;
	}
	if (!answer) {
		fprintf(stderr, "vmac: HTTP %ld, and the answer is not JSON (%s)\n", code, jerr.text);
		return 1;
	}
	if (code != 200)
		fprintf(stderr, "vmac: HTTP %ld: %s\n", code, json_string_value(json_object_get(answer, "error")));
	show(answer);
	json_decref(answer);
	return code == 200 ? 0 : 1;
}

int vmac_client_run(const struct vmac_cmd_args *a, const char *method, const char *path, const char *body, size_t len,
                    void (*show)(json_t *answer))
{
	return run(a, method, path, body, len, body != NULL, show);
}

int vmac_client_run_json(const struct vmac_cmd_args *a, const char *method, const char *path, const char *json,
                         void (*show)(json_t *answer))
{
	return run(a, method, path, json, json ? strlen(json) : 0, 0, show);
}
