/* libFuzzer harness for the line console's grammar (core/api/console.c):
 * the input is lines of submessages (DEVICE.NAME? DEVICE.NAME:VALUE
 * DEVICE.NAME>VALUE DEVICE.NAME!), answered by vmac_console_line against a
 * fake host: two running devices with variables and params of every type,
 * and an input hook that checks what reaches it and answers with every
 * status the real one gives. Each line is answered twice: into the
 * buffers the HTTP API uses, and into small ones (exactly their size, so
 * ASan sees a write past the end). An input is [size of the small
 * buffers][bit 0: the token has scope operate] then the lines. Seeds:
 * tests/fuzz/corpus-console/. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/api/console.h"
#include "fuzz.h"

static struct vmac_device_status devices[2];
static int may_operate;

static void add_var(struct vmac_variable *v, const char *name, enum vmac_value_type type, double number,
                    const char *str)
{
	memset(v, 0, sizeof(*v));
	snprintf(v->name, sizeof(v->name), "%s", name);
	v->value.type = type;
	v->value.number = number;
	snprintf(v->value.str, sizeof(v->value.str), "%s", str);
}

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
	struct vmac_device_status *w = &devices[0], *l = &devices[1];
	(void)argc;
	(void)argv;
	memset(devices, 0, sizeof(devices));
	snprintf(w->name, sizeof(w->name), "washer-1");
	w->state = "running";
	add_var(&w->vars[w->nvars++], "temp_c", VMAC_VALUE_NUMBER, 41.5, "");
	add_var(&w->vars[w->nvars++], "door", VMAC_VALUE_BOOL, 1, "");
	add_var(&w->vars[w->nvars++], "step", VMAC_VALUE_STRING, 0,
	        "a step name of exactly sixty-three bytes, the longest there is.");
	add_var(&w->vars[w->nvars++], "none", VMAC_VALUE_NONE, 0, "");
	add_var(&w->vars[w->nvars++], "huge", VMAC_VALUE_NUMBER, -1.7976931348623157e308, "");
	add_var(&w->params[w->nparams++], "fill_l", VMAC_VALUE_NUMBER, 12, "");
	add_var(&w->params[w->nparams++], "mode", VMAC_VALUE_STRING, 0, "eco");
	snprintf(l->name, sizeof(l->name), "L");
	l->state = "running";
	add_var(&l->vars[l->nvars++], "kitchen", VMAC_VALUE_BOOL, 0, "");
	add_var(&l->params[l->nparams++], "nan", VMAC_VALUE_NUMBER, 0.0 / 0.0, "");
	return 0;
}

static const struct vmac_device_status *fake_device(void *ctx, const char *name)
{
	int i;
	(void)ctx;
	for (i = 0; i < 2; i++)
		if (strcmp(devices[i].name, name) == 0)
			return &devices[i];
	return NULL;
}

static int name_ok(const char *s, size_t max)
{
	size_t n = strnlen(s, max + 1);
	return n > 0 && n <= max && strspn(s, "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-") == n;
}

/* The host's side of : > !: what reaches it must be well formed; the answer
 * (a status as POST /api/devices/NAME/input gives it) comes from the name,
 * so every branch of the console's mapping is reached. */
static unsigned fake_input(void *ctx, struct vmac_bus_input_request *req, char *msg, size_t msglen)
{
	static const unsigned statuses[] = {200, 404, 409, 409, 409, 409, 500, 503, 507, 502};
	unsigned pick = 0;
	const char *p;
	(void)ctx;
	if (!may_operate)
		abort(); /* input without scope operate */
	if (!name_ok(req->device, VMAC_NAME_MAX) || !name_ok(req->name, VMAC_NAME_MAX))
		abort();
	if (req->value.type == VMAC_VALUE_STRING &&
	    strnlen(req->value.str, sizeof(req->value.str)) > VMAC_VALUE_STR_MAX)
		abort();
	if (req->value.type == VMAC_VALUE_BOOL && req->value.number != 0 && req->value.number != 1)
		abort();
	if (req->value.type == VMAC_VALUE_NUMBER && req->value.number != req->value.number)
		abort(); /* NaN is no number an operator types */
	if (req->value.type > VMAC_VALUE_STRING)
		abort();
	for (p = req->name; *p; p++)
		pick = pick * 31 + (unsigned char)*p;
	pick %= sizeof(statuses) / sizeof(statuses[0]);
	req->rc = statuses[pick] == 409 ? (int)pick - 1 : 0; /* 1..4: BY_DRIVER, NAME, READ_ONLY, VALUE */
	if (pick == 5)
		req->rc = VMAC_REFUSED_NOT_PERSIST;
	snprintf(msg, msglen, "%s.%s: status %u", req->device, req->name, statuses[pick]);
	return statuses[pick];
}

/* One line into answer and errors, of exactly answerlen and errorslen
 * bytes (so ASan sees a write past either). */
static void answer_line(const struct vmac_console_ops *ops, const char *line, char *answer, size_t answerlen,
                        char *errors, size_t errorslen)
{
	int nerr = vmac_console_line(ops, line, answer, answerlen, errors, errorslen);
	if (nerr < 0 || strlen(answer) >= answerlen || strlen(errors) >= errorslen)
		abort();
	if (strpbrk(answer, "\n\r")) /* the answer is one line */
		abort();
	if (nerr > 0 && answerlen >= 4096 && errorslen >= 8192 && strlen(line) < 1000 && !strchr(answer, '#'))
		abort(); /* an error without its # answer (the buffers had room) */
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	struct vmac_console_ops ops;
	char *text, *line, *save = NULL, *answer, *errors, *small_answer, *small_errors;
	size_t small;
	if (size < 2 || size > 16384)
		return 0;
	/* [small buffers' size][scope operate?] then the lines */
	small = 1 + data[0] % 48;
	may_operate = data[1] & 1;
	data += 2;
	size -= 2;
	text = malloc(size + 1);
	if (!text)
		abort();
	memcpy(text, data, size);
	text[size] = 0;
	ops.device = fake_device;
	ops.input = fake_input;
	ops.ctx = NULL;
	ops.may_operate = may_operate;
	ops.wrote = NULL;
	answer = malloc(4096); /* as POST /api/console */
	errors = malloc(8192);
	small_answer = malloc(small);
	small_errors = malloc(small + 7);
	if (!answer || !errors || !small_answer || !small_errors)
		abort();
	for (line = strtok_r(text, "\n", &save); line; line = strtok_r(NULL, "\n", &save)) {
		answer_line(&ops, line, answer, 4096, errors, 8192);
		answer_line(&ops, line, small_answer, small, small_errors, small + 7);
	}
	free(text);
	free(answer);
	free(errors);
	free(small_answer);
	free(small_errors);
	return 0;
}
