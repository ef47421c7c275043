/* UART0: the board's log (one line per event, as vmac-board prints) and its
 * operator input ('NAME ACTION VALUE' lines). Sending goes through a queue
 * the main loop drains, so logging never holds up a reply; receiving goes
 * through a queue the interrupt fills, so no byte waits on the main loop. */
#include "lm3s6965.h"
#include "mcu.h"

#define TX_QUEUE 512 /* powers of two: the indices wrap by masking */
#define RX_QUEUE 128

static char tx_queue[TX_QUEUE];
static uint32_t tx_head, tx_tail; /* main loop only */

static volatile char rx_queue[RX_QUEUE];
static volatile uint32_t rx_head; /* written by the interrupt */
static volatile uint32_t rx_tail; /* written by the main loop */
static volatile int rx_new;       /* bytes came since the main loop last looked */

void vmac_mcu_uart_init(void)
{
	SYSCTL_RCGC1 |= SYSCTL_RCGC1_UART0;
	SYSCTL_RCGC2 |= SYSCTL_RCGC2_GPIOA;
	(void)SYSCTL_RCGC2; /* a few clocks before the UART and port A answer */
	GPIOA_AFSEL |= GPIO_PIN_UART0;
	GPIOA_DEN |= GPIO_PIN_UART0;
	UART0_CTL = 0;
	UART0_IBRD = 27; /* 50 MHz / (16 x 115200) = 27 + 8/64 */
	UART0_FBRD = 8;
	UART0_LCRH = UART_LCRH_WLEN8 | UART_LCRH_FEN;
	UART0_IM = UART_INT_RX | UART_INT_RT;
	UART0_CTL = UART_CTL_UARTEN | UART_CTL_TXE | UART_CTL_RXE;
	NVIC_ISER(IRQ_UART0 / 32) = 1u << (IRQ_UART0 % 32);
}

void vmac_mcu_uart_poll(void)
{
	while (tx_tail != tx_head && !(UART0_FR & UART_FR_TXFF)) {
		UART0_DR = (uint8_t)tx_queue[tx_tail % TX_QUEUE];
		tx_tail++;
	}
}

static void put_char(char c)
{
	while (tx_head - tx_tail == TX_QUEUE)
		vmac_mcu_uart_poll(); /* full: wait for the wire */
	tx_queue[tx_head % TX_QUEUE] = c;
	tx_head++;
}

void vmac_mcu_uart_puts(const char *s)
{
	while (*s)
		put_char(*s++);
	vmac_mcu_uart_poll();
}

void vmac_mcu_uart_putu(uint32_t value)
{
	char digits[10];
	int n = 0;
	do {
		digits[n++] = (char)('0' + value % 10);
		value /= 10;
	} while (value);
	while (n)
		put_char(digits[--n]);
}

void vmac_mcu_uart_puthex(uint32_t value, int digits)
{
	while (digits-- > 0)
		put_char("0123456789abcdef"[(value >> (4 * digits)) & 0xF]);
}

void vmac_mcu_uart_putmac(const uint8_t mac[6])
{
	int i;
	for (i = 0; i < 6; i++) {
		if (i)
			put_char(':');
		vmac_mcu_uart_puthex(mac[i], 2);
	}
}

void vmac_mcu_uart_panic(const char *s)
{
	for (; *s; s++) {
		while (UART0_FR & UART_FR_TXFF)
			;
		UART0_DR = (uint8_t)*s;
	}
}

void vmac_mcu_uart_handler(void)
{
	while (!(UART0_FR & UART_FR_RXFE)) {
		char c = (char)(UART0_DR & 0xFF);
		if (rx_head - rx_tail < RX_QUEUE) { /* full: the byte is lost, and so the line */
			rx_queue[rx_head % RX_QUEUE] = c;
			rx_head++;
		}
		rx_new = 1;
	}
	UART0_ICR = UART_INT_RX | UART_INT_RT;
}

int vmac_mcu_uart_pending(void)
{
	return rx_new;
}

int vmac_mcu_uart_getline(char *line, size_t cap)
{
	uint32_t head, end, i;
	size_t n = 0;
	rx_new = 0; /* before the look: bytes that come during it set it again */
	head = rx_head;
	for (end = rx_tail; end != head; end++) {
		char c = rx_queue[end % RX_QUEUE];
		if (c == '\n' || c == '\r')
			break;
	}
	if (end == head && head - rx_tail < RX_QUEUE)
		return -1; /* no end of line yet, and room for one */
	for (i = rx_tail; i != end; i++) {
		if (n + 1 < cap)
			line[n++] = rx_queue[i % RX_QUEUE];
	}
	line[n] = '\0';
	rx_tail = end == head ? end : end + 1; /* a full queue without an end: taken as one line */
	return (int)n;
}
