/* Power-on of the LM3S6965: the vector table (at flash address 0), the reset
 * handler that lays out RAM (.data copied from flash, .bss zeroed) and calls
 * main, and the fault handler. The symbols come from lm3s6965.ld. */
#include <stdint.h>
#include <string.h>

#include "lm3s6965.h"
#include "mcu.h"

extern uint32_t __data_load[], __data_start[], __data_end[], __bss_start[], __bss_end[], __stack_bottom[],
    __stack_top[];

#define STACK_PAINT 0x5AC3A55Au /* what stack never written to still holds */
#define STACK_MARGIN 64         /* bytes below the reset handler's own frame left alone */

int main(void);
void vmac_mcu_reset_handler(void);
void vmac_mcu_fault_handler(void);
void vmac_mcu_unused_handler(void);

/* One entry of the table: the first is the initial stack pointer, every
 * other one a handler. A union keeps both without casting between object
 * and function pointers, which ISO C does not allow. */
union vector {
	uint32_t *stack_top;
	void (*handler)(void);
};

#define VECTORS (16 + IRQ_COUNT)

__attribute__((section(".vectors"), used)) const union vector vmac_mcu_vectors[VECTORS] = {
    [0] = {.stack_top = __stack_top},
    [1] = {.handler = vmac_mcu_reset_handler},
    [2] = {.handler = vmac_mcu_fault_handler},   /* NMI */
    [3] = {.handler = vmac_mcu_fault_handler},   /* HardFault */
    [4] = {.handler = vmac_mcu_fault_handler},   /* MemManage */
    [5] = {.handler = vmac_mcu_fault_handler},   /* BusFault */
    [6] = {.handler = vmac_mcu_fault_handler},   /* UsageFault */
    [11] = {.handler = vmac_mcu_unused_handler}, /* SVCall */
    [12] = {.handler = vmac_mcu_unused_handler}, /* DebugMon */
    [14] = {.handler = vmac_mcu_unused_handler}, /* PendSV */
    [15] = {.handler = vmac_mcu_systick_handler},
    [16 + IRQ_UART0] = {.handler = vmac_mcu_uart_handler},
    [16 + IRQ_TIMER0A] = {.handler = vmac_mcu_timer0a_handler},
    [16 + IRQ_TIMER1A] = {.handler = vmac_mcu_timer1a_handler},
    [16 + IRQ_ETHERNET] = {.handler = vmac_mcu_enet_handler},
};

/* The stack is painted first, so that vmac_mcu_stack_used can tell how deep
 * it has ever been (the figure docs/BOARD.md gives). */
void vmac_mcu_reset_handler(void)
{
	uint32_t here, *p;
	uintptr_t below_us = (uintptr_t)&here - STACK_MARGIN;
	for (p = __stack_bottom; (uintptr_t)p < below_us; p++)
		*p = STACK_PAINT;
	memcpy(__data_start, __data_load, (size_t)((char *)__data_end - (char *)__data_start));
	memset(__bss_start, 0, (size_t)((char *)__bss_end - (char *)__bss_start));
	main();
	vmac_mcu_reset();
}

uint32_t vmac_mcu_stack_used(void)
{
	const uint32_t *p = __stack_bottom;
	while (p < __stack_top && *p == STACK_PAINT)
		p++;
	return (uint32_t)((const char *)__stack_top - (const char *)p);
}

/* A fault is a firmware bug: say so, then reset, which leaves every output
 * off (as at power-on) until the host registers the board again. */
void vmac_mcu_fault_handler(void)
{
	vmac_mcu_uart_panic("vmac-board: fault, all outputs off, resetting\n");
	vmac_mcu_reset();
}

/* An interrupt nobody enabled: nothing to do. */
void vmac_mcu_unused_handler(void)
{
}

void vmac_mcu_reset(void)
{
	SCB_AIRCR = SCB_AIRCR_RESET;
	for (;;)
		lm3s_wait_for_interrupt();
}
