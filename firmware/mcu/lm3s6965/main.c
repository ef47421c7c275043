/* vmac-board on the LM3S6965: one generic board (firmware/board.c) with its
 * simulated plant (firmware/plant.c), on raw Ethernet through the chip's
 * MAC, its log and operator input on UART0. The loop is vmac-board's
 * (firmware/posix/) for one board: the watchdog, the plant and the log
 * every 5 ms, the watchdog again before every frame, one reply per request,
 * the instants of time-triggered I/O when timer 0A says, and the processor
 * asleep in between. */
#include <string.h>

#include "lm3s6965.h"
#include "mcu.h"

#define HOUSEKEEP_MS 5        /* watchdog, plant step and log lines this often */
#define PLANT_STEP_MAX_S 0.01 /* physics sub-step, as vmac-board */
#define FRAMES_PER_TURN 8     /* frames handled before the housekeeping looks again */
#define LINE_MAX 80           /* an operator line */

static struct vmac_mcu_settings settings;
static struct vmac_plant plant;
static struct vmac_board board;
static const struct vmac_board_io plant_io = {vmac_plant_io_read, vmac_plant_io_write};

static struct vmac_report reported;     /* what the log last said (firmware/report.c) */
static struct vmac_plant_safety safety; /* the plant's safety monitor, as the report reads it */
static uint64_t last_step_ms, last_housekeep_ms;
static uint8_t timed_src[6]; /* the sender of the last TIMED CYCLIC: where TIMED replies go */

static void put_name(void)
{
	vmac_mcu_uart_puts(board.id.board);
	vmac_mcu_uart_puts(": ");
}

/* The state, output and unsafe lines of vmac-board, for what changed since the last. */
static void report(void)
{
	char line[VMAC_REPORT_LINE];
	reported.quiet = settings.quiet;
	while (vmac_report_next(&reported, &board, &safety, line, sizeof(line))) {
		vmac_mcu_uart_puts(line);
		vmac_mcu_uart_puts("\n");
	}
}

static void poll_watchdog(uint64_t now_ms)
{
	if (vmac_board_poll(&board, now_ms)) {
		char line[VMAC_REPORT_LINE];
		vmac_report_watchdog(&board, line, sizeof(line));
		vmac_mcu_uart_puts(line);
		vmac_mcu_uart_puts("\n");
	}
}

/* The watchdog, the plant stepped to now, the log. */
static void housekeep(uint64_t now_ms)
{
	double left_s = now_ms > last_step_ms ? (double)(now_ms - last_step_ms) / 1000.0 : 0.0;
	poll_watchdog(now_ms);
	vmac_board_clock_poll(&board, vmac_mcu_now_ns()); /* holdover, lost: said by report() */
	while (left_s > 0) {
		double step_s = left_s > PLANT_STEP_MAX_S ? PLANT_STEP_MAX_S : left_s;
		vmac_plant_step(&plant, step_s);
		left_s -= step_s;
	}
	if (now_ms > last_step_ms)
		last_step_ms = now_ms;
	report();
}

/* One received vmac frame, stamped rx_ns by the receive interrupt (enet.c):
 * the watchdog first (a frame that waited while
 * the board could not run never revives a session already timed out),
 * then the board, then its reply, if any, back to the sender. */
static void handle_frame(const uint8_t *frame, size_t len, const uint8_t src[6], uint64_t now_ms, uint64_t rx_ns)
{
	static uint8_t reply[VMAC_BOARD_REPLY_MAX];
	int n;
	poll_watchdog(now_ms);
	if (len >= VMAC_HDR_LEN && (frame[3] & VMAC_FLAG_TIMED) && !(frame[3] & VMAC_FLAG_REPLY))
		memcpy(timed_src, src, sizeof(timed_src));
	n = vmac_board_receive_at(&board, frame, len, now_ms, rx_ns, reply, sizeof(reply));
	if (n > 0)
		vmac_mcu_enet_send(src, reply, (size_t)n);
}

/* Time-triggered I/O: what is due done (the watchdog first: a trip cancels
 * it) and its TIMED reply sent; the alarm armed for the next instant. */
static void run_instants(void)
{
	static uint8_t reply[VMAC_BOARD_REPLY_MAX];
	uint64_t at, now;
	while (vmac_board_next_deadline(&board, &at)) {
		int n;
		now = vmac_mcu_now_ns();
		if (at > now) {
			vmac_mcu_alarm_in(at - now);
			return;
		}
		poll_watchdog(vmac_mcu_now_ms());
		n = vmac_board_run_due(&board, now, reply, sizeof(reply));
		if (n > 0)
			vmac_mcu_enet_send(timed_src, reply, (size_t)n);
	}
}

/* A decimal number ("1", "-0.5", "3.5e1") into *value; -1 when text is not one. */
static int parse_number(const char *text, double *value)
{
	double v = 0.0, scale = 1.0;
	int negative = 0, digits = 0, exponent = 0, exp_negative = 0;
	if (*text == '-' || *text == '+')
		negative = *text++ == '-';
	for (; *text >= '0' && *text <= '9'; text++, digits++)
		v = v * 10.0 + (*text - '0');
	if (*text == '.') {
		for (text++; *text >= '0' && *text <= '9'; text++, digits++) {
			scale /= 10.0;
			v += (*text - '0') * scale;
		}
	}
	if (digits == 0)
		return -1;
	if (*text == 'e' || *text == 'E') {
		text++;
		if (*text == '-' || *text == '+')
			exp_negative = *text++ == '-';
		if (!(*text >= '0' && *text <= '9'))
			return -1;
		for (; *text >= '0' && *text <= '9' && exponent < 400; text++)
			exponent = exponent * 10 + (*text - '0');
	}
	if (*text != '\0')
		return -1;
	while (exponent-- > 0)
		v = exp_negative ? v / 10.0 : v * 10.0;
	*value = negative ? -v : v;
	return 0;
}

/* Split line in place into at most max words separated by blanks. */
static int split_words(char *line, char **words, int max)
{
	int n = 0;
	while (*line) {
		while (*line == ' ' || *line == '\t')
			*line++ = '\0';
		if (!*line)
			break;
		if (n == max)
			return max + 1;
		words[n++] = line;
		while (*line && *line != ' ' && *line != '\t')
			line++;
	}
	return n;
}

/* The board's counters as vmac-board prints them (firmware/report.c),
 * then the MAC's and the stack's; then, once SYNC frames came, the clock's
 * line. */
static void print_counters(void)
{
	const struct vmac_mcu_enet_counters *e = vmac_mcu_enet_counters();
	char line[VMAC_REPORT_LINE];
	vmac_report_counters(&board, line, sizeof(line));
	vmac_mcu_uart_puts(line);
	vmac_mcu_uart_puts("; Ethernet received ");
	vmac_mcu_uart_putu(e->received);
	vmac_mcu_uart_puts(", sent ");
	vmac_mcu_uart_putu(e->sent);
	vmac_mcu_uart_puts(", not ours ");
	vmac_mcu_uart_putu(e->not_ours);
	vmac_mcu_uart_puts(", oversize ");
	vmac_mcu_uart_putu(e->oversize);
	vmac_mcu_uart_puts(", overruns ");
	vmac_mcu_uart_putu(e->overruns);
	vmac_mcu_uart_puts("; stack used ");
	vmac_mcu_uart_putu(vmac_mcu_stack_used());
	vmac_mcu_uart_puts(" bytes\n");
	if (vmac_report_timed(&board, line, sizeof(line))) { /* once it served a TIMED record, as vmac-board */
		vmac_mcu_uart_puts(line);
		vmac_mcu_uart_puts("\n");
	}
	if (board.clock.state != VMAC_CLOCK_UNSYNCED || board.counters.sync_ignored) {
		vmac_report_clock(&board, 1, line, sizeof(line)); /* the clock's line, as vmac-board's */
		vmac_mcu_uart_puts(line);
		vmac_mcu_uart_puts("\n");
	}
}

/* An operator line, as vmac-board --commands takes it: 'NAME ACTION VALUE'
 * (e.g. 'lights-1 toggle1 1'); the value may be left out (0). 'status' (or
 * 'NAME status') prints the board's and the MAC's counters. */
static void command(char *line)
{
	char *words[3];
	double value = 0.0;
	int n = split_words(line, words, 3);
	if (n == 0)
		return;
	if ((n == 1 && strcmp(words[0], "status") == 0) ||
	    (n == 2 && strcmp(words[0], board.id.board) == 0 && strcmp(words[1], "status") == 0)) {
		print_counters();
		return;
	}
	if (n < 2 || n > 3 || (n == 3 && parse_number(words[2], &value) != 0)) {
		vmac_mcu_uart_puts("vmac-board: expected 'NAME ACTION VALUE' or 'status'\n");
		return;
	}
	if (strcmp(words[0], board.id.board) != 0) {
		vmac_mcu_uart_puts("vmac-board: no board named ");
		vmac_mcu_uart_puts(words[0]);
		vmac_mcu_uart_puts("\n");
		return;
	}
	put_name();
	if (vmac_plant_set(&plant, words[1], value) != 0)
		vmac_mcu_uart_puts("refused ");
	vmac_mcu_uart_puts(words[1]);
	vmac_mcu_uart_puts(" ");
	vmac_mcu_uart_puts(n == 3 ? words[2] : "0");
	vmac_mcu_uart_puts("\n");
	report(); /* an action may have begun an unsafe episode */
}

static void print_start(void)
{
	vmac_mcu_uart_puts("vmac-board: 1 ");
	vmac_mcu_uart_puts(vmac_plant_name(settings.kind));
	vmac_mcu_uart_puts(" board on bus eth:lm3s6965 (raw Ethernet, interface MAC ");
	vmac_mcu_uart_putmac(settings.mac);
	vmac_mcu_uart_puts("), protocol ");
	vmac_mcu_uart_putu(board.id.protocol);
	vmac_mcu_uart_puts(", MAC ");
	vmac_mcu_uart_puts(board.id.board);
	vmac_mcu_uart_puts(" ");
	vmac_mcu_uart_putmac(settings.mac);
	vmac_mcu_uart_puts("\nvmac-board: firmware ");
	vmac_mcu_uart_putu(VMAC_FIRMWARE_MAJOR);
	vmac_mcu_uart_puts(".");
	vmac_mcu_uart_putu(VMAC_FIRMWARE_MINOR);
	vmac_mcu_uart_puts(" on LM3S6965, driver ");
	vmac_mcu_uart_puts(board.id.driver);
	vmac_mcu_uart_puts(", major 0x");
	vmac_mcu_uart_puthex(board.id.major, 8);
	vmac_mcu_uart_puts(", minor ");
	vmac_mcu_uart_putu(board.id.minor);
	vmac_mcu_uart_puts(", identity block at 0x");
	vmac_mcu_uart_puthex(VMAC_MCU_CONFIG_ADDR, 8);
	vmac_mcu_uart_puts("\n");
	if (board.id.keyed)
		vmac_mcu_uart_puts("vmac-board: keyed: the board answers only a host that authenticates (key in "
		                   "the identity block)\n");
}

/* A block that cannot be used keeps the board off the bus, its outputs off
 * as at power-on; it says why once, then sleeps. */
static void halt(const char *why)
{
	vmac_mcu_uart_puts("vmac-board: identity block refused: ");
	vmac_mcu_uart_puts(why);
	vmac_mcu_uart_puts("; not joining the bus (scripts/qemu-board-config.py writes one)\n");
	for (;;) {
		vmac_mcu_uart_poll();
		lm3s_wait_for_interrupt();
	}
}

int main(void)
{
	const char *why = NULL;
	uint64_t now_ms;
	char line[LINE_MAX];

	vmac_mcu_clock_init();
	vmac_mcu_uart_init();
	lm3s_irq_enable();
	if (vmac_mcu_config_load(&settings, &why) != 0)
		halt(why);
	now_ms = vmac_mcu_now_ms();
	vmac_plant_init(&plant, settings.kind);
	vmac_board_init(&board, &settings.id, &plant_io, &plant, now_ms);
	safety = vmac_plant_safety_of(&plant);
	vmac_report_init(&reported, &board, &safety, settings.quiet);
	last_step_ms = last_housekeep_ms = now_ms;
	vmac_mcu_enet_init(settings.mac);
	print_start();

	for (;;) {
		const uint8_t *frame;
		uint8_t src[6];
		uint64_t rx_ns;
		int frames, len;

		run_instants();
		now_ms = vmac_mcu_now_ms();
		if (now_ms - last_housekeep_ms >= HOUSEKEEP_MS) {
			housekeep(now_ms);
			last_housekeep_ms = now_ms;
		}
		for (frames = 0; frames < FRAMES_PER_TURN && (len = vmac_mcu_enet_receive(&frame, src, &rx_ns)) >= 0;
		     frames++) {
			if (len > 0)
				handle_frame(frame, (size_t)len, src, vmac_mcu_now_ms(), rx_ns);
		}
		while (vmac_mcu_uart_getline(line, sizeof(line)) >= 0)
			command(line);
		run_instants(); /* a frame may have brought one: armed before the sleep */
		vmac_mcu_uart_poll();
		/* Sleep until the next interrupt (timer 1's millisecond wake-up
		 * at the latest), unless work came in since the looks above: masked,
		 * an interrupt still ends the sleep, and is taken after it. */
		lm3s_irq_disable();
		if (!vmac_mcu_enet_pending() && !vmac_mcu_uart_pending())
			lm3s_wait_for_interrupt();
		lm3s_irq_enable();
	}
}
