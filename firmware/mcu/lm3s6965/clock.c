/* The system clock (PLL, 50 MHz), the millisecond time the board logic
 * and the plant run on (SysTick), the free-running nanosecond counter
 * the board's disciplined clock runs on (SysTick's milliseconds and the
 * cycles into the current one), and the alarm of time-triggered I/O
 * (GPTM timer 0A, one-shot: its interrupt wakes the main loop at an
 * instant). */
#include "lm3s6965.h"
#include "mcu.h"

#define SYSCLK_HZ 50000000u /* PLL 400 MHz / 2 / SYSDIV 4 */
#define TICK_HZ 1000u
#define NS_PER_CYCLE (1000000000u / SYSCLK_HZ) /* 20 ns */

static volatile uint32_t ticks_ms; /* written by the interrupt only */
static uint32_t seen_ticks;        /* the main loop's last look at it */
static uint64_t now_ms;

void vmac_mcu_systick_handler(void)
{
	ticks_ms++;
}

/* The data sheet's sequence: bypass the PLL, set the crystal, power the
 * PLL up, wait for its lock, then divide it down to the system clock. */
static void pll_init(void)
{
	uint32_t rcc = SYSCTL_RCC;
	int spins;
	rcc |= RCC_BYPASS;
	rcc &= ~RCC_USESYSDIV;
	SYSCTL_RCC = rcc;
	rcc &= ~(RCC_XTAL_MASK | RCC_OSCSRC_MASK | RCC_MOSCDIS | RCC_PWRDN);
	rcc |= RCC_XTAL_8MHZ; /* main oscillator */
	SYSCTL_RCC = rcc;
	rcc = (rcc & ~RCC_SYSDIV_MASK) | RCC_SYSDIV(3) | RCC_USESYSDIV;
	SYSCTL_RCC = rcc;
	for (spins = 0; spins < 100000 && !(SYSCTL_RIS & SYSCTL_RIS_PLLLRIS); spins++)
		;
	SYSCTL_RCC = rcc & ~RCC_BYPASS;
}

void vmac_mcu_clock_init(void)
{
	pll_init();
	SYST_RVR = SYSCLK_HZ / TICK_HZ - 1;
	SYST_CVR = 0;
	SYST_CSR = SYST_CSR_CLKSOURCE | SYST_CSR_TICKINT | SYST_CSR_ENABLE;
	SYSCTL_RCGC1 |= SYSCTL_RCGC1_TIMER0;
	(void)SYSCTL_RCGC1; /* a few cycles before the timer's registers answer */
	TIMER0_CTL = 0;
	TIMER0_CFG = TIMER_CFG_32BIT;
	TIMER0_TAMR = TIMER_TAMR_ONESHOT;
	TIMER0_IMR = TIMER_INT_TATO;
	NVIC_ISER(IRQ_TIMER0A / 32) = 1u << (IRQ_TIMER0A % 32);
}

void vmac_mcu_timer0a_handler(void)
{
	TIMER0_ICR = TIMER_INT_TATO; /* the wake-up was the point: the main loop acts */
}

void vmac_mcu_alarm_in(uint64_t ns)
{
	uint64_t cycles = ns / NS_PER_CYCLE + 1;
	TIMER0_CTL = 0;
	TIMER0_TAILR = cycles > 0xFFFFFFFFu ? 0xFFFFFFFFu : (uint32_t)cycles; /* 85 s at most: then it looks again */
	TIMER0_ICR = TIMER_INT_TATO;
	TIMER0_CTL = TIMER_CTL_TAEN;
}

uint64_t vmac_mcu_now_ms(void)
{
	uint32_t t = ticks_ms;
	now_ms += (uint32_t)(t - seen_ticks);
	seen_ticks = t;
	return now_ms;
}

uint64_t vmac_mcu_now_ns(void)
{
	uint64_t ms = vmac_mcu_now_ms(); /* the 64-bit milliseconds as of seen_ticks */
	uint32_t before, after, cycles_left;
	/* SysTick counts down from RVR to 0, then the interrupt adds a
	 * millisecond: a tick between the two reads is read again. */
	do {
		before = ticks_ms;
		cycles_left = SYST_CVR;
		after = ticks_ms;
	} while (before != after);
	ms += (uint32_t)(before - seen_ticks);
	return ms * 1000000u + (uint64_t)(SYST_RVR - cycles_left) * NS_PER_CYCLE;
}
