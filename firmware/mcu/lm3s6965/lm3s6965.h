/* The registers of the TI Stellaris LM3S6965 (Cortex-M3) that this firmware
 * uses: system control, SysTick and the NVIC, timers 0 and 1, UART0, the
 * Ethernet MAC. Only the HAL files of firmware/mcu/lm3s6965/ include it. Names follow the data
 * sheet (DS-LM3S6965), addresses are those of the part and of QEMU's
 * lm3s6965evb machine alike. */
#ifndef VMAC_LM3S6965_H
#define VMAC_LM3S6965_H

#include <stdint.h>

#define REG32(addr) (*(volatile uint32_t *)(uintptr_t)(addr))

/* Memory. */
#define LM3S_FLASH_BASE 0x00000000u
#define LM3S_FLASH_SIZE (256u * 1024u)
#define LM3S_FLASH_PAGE 1024u /* the erase unit */
#define LM3S_SRAM_BASE 0x20000000u
#define LM3S_SRAM_SIZE (64u * 1024u)

/* System control. */
#define SYSCTL_RIS REG32(0x400FE050u)
#define SYSCTL_RIS_PLLLRIS (1u << 6) /* PLL locked */
#define SYSCTL_RCC REG32(0x400FE060u)
#define SYSCTL_RCGC1 REG32(0x400FE104u)
#define SYSCTL_RCGC1_UART0 (1u << 0)
#define SYSCTL_RCGC1_TIMER0 (1u << 16)
#define SYSCTL_RCGC1_TIMER1 (1u << 17)
#define SYSCTL_RCGC2 REG32(0x400FE108u)
#define SYSCTL_RCGC2_GPIOA (1u << 0)
#define SYSCTL_RCGC2_EMAC0 (1u << 28)
#define SYSCTL_RCGC2_EPHY0 (1u << 30)
/* RCC fields */
#define RCC_MOSCDIS (1u << 0)
#define RCC_OSCSRC_MASK (3u << 4)
#define RCC_XTAL_MASK (0xFu << 6)
#define RCC_XTAL_8MHZ (0xEu << 6) /* the evaluation board's crystal */
#define RCC_BYPASS (1u << 11)
#define RCC_PWRDN (1u << 13)
#define RCC_USESYSDIV (1u << 22)
#define RCC_SYSDIV_MASK (0xFu << 23)
#define RCC_SYSDIV(n) ((uint32_t)(n) << 23) /* the PLL's 400 MHz / 2 / (n + 1) */

/* Cortex-M3 system control space. */
#define SYST_CSR REG32(0xE000E010u)
#define SYST_RVR REG32(0xE000E014u)
#define SYST_CVR REG32(0xE000E018u)
#define SYST_CSR_ENABLE (1u << 0)
#define SYST_CSR_TICKINT (1u << 1)
#define SYST_CSR_CLKSOURCE (1u << 2)  /* the processor clock (QEMU has no reference clock) */
#define SYST_CSR_COUNTFLAG (1u << 16) /* counted to 0 since the last read of SYST_CSR (the read clears it) */
#define SYST_MAX 0x00FFFFFFu          /* SYST_RVR's and SYST_CVR's 24 bits */
#define NVIC_ISER(n) REG32(0xE000E100u + 4u * (n))
#define SCB_AIRCR REG32(0xE000ED0Cu)
#define SCB_AIRCR_RESET (0x05FA0000u | (1u << 2)) /* VECTKEY | SYSRESETREQ */

/* Interrupt numbers (vector = 16 + irq). */
#define IRQ_UART0 5
#define IRQ_TIMER0A 19
#define IRQ_TIMER1A 21
#define IRQ_ETHERNET 42
#define IRQ_COUNT 48 /* vectors 16..63; the part has 0..43 */

/* GPIO port A: UART0 is on PA0 (receive) and PA1 (send). */
#define GPIOA_AFSEL REG32(0x40004420u) /* 1: the pin's alternate function */
#define GPIOA_DEN REG32(0x4000451Cu)   /* 1: digital function on */
#define GPIO_PIN_UART0 0x03u

/* UART0 (an ARM PrimeCell PL011). */
#define UART0_BASE 0x4000C000u
#define UART0_DR REG32(UART0_BASE + 0x000u)
#define UART0_FR REG32(UART0_BASE + 0x018u)
#define UART0_IBRD REG32(UART0_BASE + 0x024u)
#define UART0_FBRD REG32(UART0_BASE + 0x028u)
#define UART0_LCRH REG32(UART0_BASE + 0x02Cu)
#define UART0_CTL REG32(UART0_BASE + 0x030u)
#define UART0_IM REG32(UART0_BASE + 0x038u)
#define UART0_ICR REG32(UART0_BASE + 0x044u)
#define UART_FR_RXFE (1u << 4) /* receive FIFO empty */
#define UART_FR_TXFF (1u << 5) /* transmit FIFO full */
#define UART_LCRH_FEN (1u << 4)
#define UART_LCRH_WLEN8 (3u << 5)
#define UART_CTL_UARTEN (1u << 0)
#define UART_CTL_TXE (1u << 8)
#define UART_CTL_RXE (1u << 9)
#define UART_INT_RX (1u << 4)
#define UART_INT_RT (1u << 6) /* receive time-out: a few bytes wait in the FIFO */

/* General-purpose timers (GPTM) 0 and 1, timer A of each: 32 bits
 * counting down at the system clock, the time-out an interrupt; timer 0 a
 * one-shot (the alarm), timer 1 periodic (the main loop's wake-up). */
#define TIMER0_BASE 0x40030000u
#define TIMER0_CFG REG32(TIMER0_BASE + 0x000u)
#define TIMER0_TAMR REG32(TIMER0_BASE + 0x004u)
#define TIMER0_CTL REG32(TIMER0_BASE + 0x00Cu)
#define TIMER0_IMR REG32(TIMER0_BASE + 0x018u)
#define TIMER0_ICR REG32(TIMER0_BASE + 0x024u)
#define TIMER0_TAILR REG32(TIMER0_BASE + 0x028u)
#define TIMER1_BASE 0x40031000u
#define TIMER1_CFG REG32(TIMER1_BASE + 0x000u)
#define TIMER1_TAMR REG32(TIMER1_BASE + 0x004u)
#define TIMER1_CTL REG32(TIMER1_BASE + 0x00Cu)
#define TIMER1_IMR REG32(TIMER1_BASE + 0x018u)
#define TIMER1_ICR REG32(TIMER1_BASE + 0x024u)
#define TIMER1_TAILR REG32(TIMER1_BASE + 0x028u)
#define TIMER_CFG_32BIT 0x0u
#define TIMER_TAMR_ONESHOT 0x1u
#define TIMER_TAMR_PERIODIC 0x2u
#define TIMER_CTL_TAEN (1u << 0)
#define TIMER_INT_TATO (1u << 0) /* timer A time-out */

/* Ethernet MAC. */
#define MAC_BASE 0x40048000u
#define MAC_RIS REG32(MAC_BASE + 0x000u) /* read: raw interrupt status; write: MACIACK */
#define MAC_IACK REG32(MAC_BASE + 0x000u)
#define MAC_IM REG32(MAC_BASE + 0x004u)
#define MAC_RCTL REG32(MAC_BASE + 0x008u)
#define MAC_TCTL REG32(MAC_BASE + 0x00Cu)
#define MAC_DATA REG32(MAC_BASE + 0x010u)
#define MAC_IA0 REG32(MAC_BASE + 0x014u)
#define MAC_IA1 REG32(MAC_BASE + 0x018u)
#define MAC_THR REG32(MAC_BASE + 0x01Cu)
#define MAC_MDV REG32(MAC_BASE + 0x024u) /* MII clock divider */
#define MAC_NP REG32(MAC_BASE + 0x034u)  /* frames waiting in the receive FIFO */
#define MAC_TR REG32(MAC_BASE + 0x038u)
#define MAC_INT_RX (1u << 0)
#define MAC_INT_TXER (1u << 1)
#define MAC_INT_TXEMP (1u << 2)
#define MAC_INT_FOV (1u << 3) /* receive FIFO overrun: a frame was lost */
#define MAC_INT_RXER (1u << 4)
#define MAC_INT_ALL 0x7Fu
#define MAC_RCTL_RXEN (1u << 0)
#define MAC_RCTL_AMUL (1u << 1)
#define MAC_RCTL_PRMS (1u << 2)
#define MAC_RCTL_BADCRC (1u << 3)
#define MAC_RCTL_RSTFIFO (1u << 4)
#define MAC_TCTL_TXEN (1u << 0)
#define MAC_TCTL_PADEN (1u << 1) /* pad short frames to 60 bytes */
#define MAC_TCTL_CRC (1u << 2)   /* append the FCS */
#define MAC_TCTL_DUPLEX (1u << 4)
#define MAC_TR_NEWTX (1u << 0) /* start sending the frame in the FIFO; reads 1 until it is sent */
#define MAC_THR_OFF 0x3Fu      /* no early transmit: a frame leaves on NEWTX only */
#define MAC_MDV_50MHZ 9u       /* MII clock 50 MHz / (2 x (9 + 1)) = 2.5 MHz, the PHY's most */

/* Interrupts on and off around the check-then-sleep of the main loop. */
static inline void lm3s_irq_disable(void)
{
	__asm__ volatile("cpsid i" ::: "memory");
}

/* Interrupts off, returning whether they were (PRIMASK) for lm3s_irq_restore. */
static inline uint32_t lm3s_irq_save(void)
{
	uint32_t primask;
	__asm__ volatile("mrs %0, primask\n\tcpsid i" : "=r"(primask)::"memory");
	return primask;
}

static inline void lm3s_irq_restore(uint32_t primask)
{
	__asm__ volatile("msr primask, %0" ::"r"(primask) : "memory");
}

static inline void lm3s_irq_enable(void)
{
	__asm__ volatile("cpsie i" ::: "memory");
}

/* Sleep until an interrupt is pending (also with interrupts masked). */
static inline void lm3s_wait_for_interrupt(void)
{
	__asm__ volatile("wfi" ::: "memory");
}

#endif
