/* The LM3S6965 board's HAL, shared by its files: the clock (clock.c), the
 * UART0 log and operator input (uart.c), the Ethernet MAC (enet.c), the
 * identity block in flash (config.c), start-up and reset (startup.c). main.c
 * runs firmware/board.c and a plant on top of them. No heap, no OS. */
#ifndef VMAC_MCU_H
#define VMAC_MCU_H

#include <stddef.h>
#include <stdint.h>

#include "../../board.h"
#include "../../plant.h"
#include "../../report.h"
#include "config.h"

/* ---- clock.c ---- */

/* The PLL to 50 MHz, SysTick free-running (the time below), timer 1 to
 * wake the main loop every millisecond, timer 0 ready as the alarm. */
void vmac_mcu_clock_init(void);
/* Milliseconds since power-on (vmac_mcu_now_ns's, whole). */
uint64_t vmac_mcu_now_ms(void);
/* Nanoseconds since power-on, to the processor's cycle (20 ns): the
 * counter the board's clock (firmware/clock.h) is disciplined on. From
 * the main loop or an interrupt. */
uint64_t vmac_mcu_now_ns(void);
void vmac_mcu_systick_handler(void);
void vmac_mcu_timer1a_handler(void);
/* Interrupt in ns nanoseconds (timer 0A, one-shot, to the cycle), ending
 * the main loop's sleep: the timer compare of time-triggered I/O. A new
 * call replaces the last. */
void vmac_mcu_alarm_in(uint64_t ns);
void vmac_mcu_timer0a_handler(void);

/* ---- uart.c: UART0, 115200 8N1 ---- */

void vmac_mcu_uart_init(void);
/* Queue text for sending; the queue drains from vmac_mcu_uart_poll, so a log
 * line never holds up a reply. When the queue is full, waits for room. */
void vmac_mcu_uart_puts(const char *s);
void vmac_mcu_uart_putu(uint32_t value);               /* decimal */
void vmac_mcu_uart_puthex(uint32_t value, int digits); /* digits lowercase hex digits, no 0x */
void vmac_mcu_uart_putmac(const uint8_t mac[6]);       /* 02:12:34:56:00:01 */
/* Send what is queued while the hardware FIFO has room; never waits. */
void vmac_mcu_uart_poll(void);
/* The next whole received line (without its end), NUL-terminated, into line
 * (cap bytes); returns its length, or -1 when no whole line has come. A
 * line longer than cap - 1 is cut there. */
int vmac_mcu_uart_getline(char *line, size_t cap);
/* Whether bytes came since the last vmac_mcu_uart_getline (the main loop
 * then looks for a line before it sleeps). */
int vmac_mcu_uart_pending(void);
/* Write s straight to the hardware, waiting, from any context (a fault). */
void vmac_mcu_uart_panic(const char *s);
void vmac_mcu_uart_handler(void);

/* ---- enet.c: the Ethernet MAC, EtherType 0x88B5 only ---- */

#define VMAC_MCU_ETHERTYPE 0x88B5
#define VMAC_MCU_ETH_HLEN 14

struct vmac_mcu_enet_counters {
	uint32_t received, sent, not_ours, oversize, overruns;
};

/* Start the MAC with this station address: receive on, send with padding
 * to 60 bytes and the FCS added by the hardware. */
void vmac_mcu_enet_init(const uint8_t mac[6]);
/* Take the next frame out of the receive FIFO. Frames of another EtherType,
 * or to another station than ours or the broadcast address, are dropped
 * (counted in not_ours). Returns the vmac payload's length (the Ethernet
 * padding trimmed by the length its header declares), *payload pointing at
 * it in the driver's one frame buffer (valid until the next receive or
 * send), the sender in src and in *rx_ns when it came (vmac_mcu_now_ns
 * as the receive interrupt saw it, or as this call did when the interrupt
 * had not run yet); 0 for a frame dropped; -1 when the FIFO is empty. */
int vmac_mcu_enet_receive(const uint8_t **payload, uint8_t src[6], uint64_t *rx_ns);
/* Whether frames wait in the receive FIFO. */
int vmac_mcu_enet_pending(void);
/* Send payload (1..1500 bytes) to dst from our address, EtherType 0x88B5. */
void vmac_mcu_enet_send(const uint8_t dst[6], const uint8_t *payload, size_t len);
const struct vmac_mcu_enet_counters *vmac_mcu_enet_counters(void);
void vmac_mcu_enet_handler(void);

/* ---- startup.c ---- */

/* Reset the chip (every output off, as at power-on). */
void vmac_mcu_reset(void);
/* The most stack ever used since reset, in bytes (of STACK_SIZE in lm3s6965.ld). */
uint32_t vmac_mcu_stack_used(void);

#endif
