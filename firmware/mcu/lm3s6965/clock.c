/* The system clock (PLL, 50 MHz); the free-running time the board runs on,
 * to the processor's cycle: SysTick counting down over its whole 24 bits
 * (2^24 cycles, 335.5 ms a turn), extended to 64 bits by noticing each
 * turn from the counter itself, never by counting interrupts; the main
 * loop's wake-up every millisecond (GPTM timer 1A, periodic), and the alarm
 * of time-triggered I/O (timer 0A, one-shot: its interrupt wakes the main
 * loop at an instant). */
#include "lm3s6965.h"
#include "mcu.h"

#define SYSCLK_HZ 50000000u                    /* PLL 400 MHz / 2 / SYSDIV 4 */
#define NS_PER_CYCLE (1000000000u / SYSCLK_HZ) /* 20 ns */
#define TURN_CYCLES (SYST_MAX + 1u)            /* SysTick's period: RVR + 1 cycles */
#define CYCLES_PER_MS (SYSCLK_HZ / 1000u)
#define WAKE_HZ 1000u
#define LAST_VALUE_SPINS 100000u /* reads of SysTick's last value of a turn (1) before taking it */

/* The cycles since start-up at the start of the turn seen last, and how
 * far into it that look was: the main loop and the SysTick interrupt both
 * look (lm3s_irq_save between them). */
static uint64_t turn_start;
static uint32_t seen_into;

/* SysTick's value, never the last of a turn (1) for longer than it
 * lasts on the part, one cycle: QEMU shows 1 from a turn's end until it
 * runs that turn's timer callback, which its main loop may do late (seen:
 * 6,007 reads of 1 in a row on the loaded VM); time would stand still
 * meanwhile, and a frame stamped then would look early, which the clock's
 * minimum filter cannot tell from a fast path. Read again until it moves
 * on (bounded: never a hang). */
static uint32_t systick_value(void)
{
	uint32_t cvr = SYST_CVR;
	uint32_t spins;
	for (spins = 0; cvr == 1 && spins < LAST_VALUE_SPINS; spins++)
		cvr = SYST_CVR;
	return cvr;
}

/* Cycles into the current turn from SysTick's value: it counts RVR, ...,
 * 1, 0 and reloads, COUNTFLAG rising as it reaches 0, so a turn begins at
 * 0 (the flag's edge) and 1 is its last cycle. */
static uint32_t into_turn(uint32_t cvr)
{
	return cvr == 0 ? 0 : TURN_CYCLES - cvr;
}

/* Cycles since start-up. A new turn shows as the counter behind the last
 * look, or as COUNTFLAG (the counter went round and past the last look:
 * a gap of up to two turns, 671 ms, is still told right); the value is
 * read again when it turned between the reads, the flags of both reads
 * kept. Nothing depends on how many SysTick interrupts were taken: QEMU
 * runs the timer callbacks of several turns at once when its CPU was held
 * off and pends the interrupt once, but its counter value is exact. */
static uint64_t cycles_now(void)
{
	uint32_t primask = lm3s_irq_save();
	uint32_t flagged = 0, before, after;
	uint64_t cycles;
	do {
		before = into_turn(systick_value());
		flagged |= SYST_CSR & SYST_CSR_COUNTFLAG;
		after = into_turn(systick_value());
	} while (after < before);
	if (flagged || after < seen_into)
		turn_start += TURN_CYCLES;
	seen_into = after;
	cycles = turn_start + after;
	lm3s_irq_restore(primask);
	return cycles;
}

/* SysTick's interrupt, once a turn: a look at the counter however long the
 * main loop is away, so that no turn passes unseen. */
void vmac_mcu_systick_handler(void)
{
	(void)cycles_now();
}

/* The main loop's wake-up: the interrupt's end is the point. */
void vmac_mcu_timer1a_handler(void)
{
	TIMER1_ICR = TIMER_INT_TATO;
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
	SYST_RVR = SYST_MAX;
	SYST_CVR = 0; /* also clears COUNTFLAG */
	seen_into = 0;
	SYST_CSR = SYST_CSR_CLKSOURCE | SYST_CSR_TICKINT | SYST_CSR_ENABLE;
	SYSCTL_RCGC1 |= SYSCTL_RCGC1_TIMER0 | SYSCTL_RCGC1_TIMER1;
	(void)SYSCTL_RCGC1; /* a few cycles before the timers' registers answer */
	TIMER0_CTL = 0;
	TIMER0_CFG = TIMER_CFG_32BIT;
	TIMER0_TAMR = TIMER_TAMR_ONESHOT;
	TIMER0_IMR = TIMER_INT_TATO;
	NVIC_ISER(IRQ_TIMER0A / 32) = 1u << (IRQ_TIMER0A % 32);
	TIMER1_CTL = 0;
	TIMER1_CFG = TIMER_CFG_32BIT;
	TIMER1_TAMR = TIMER_TAMR_PERIODIC;
	TIMER1_TAILR = SYSCLK_HZ / WAKE_HZ - 1;
	TIMER1_IMR = TIMER_INT_TATO;
	NVIC_ISER(IRQ_TIMER1A / 32) = 1u << (IRQ_TIMER1A % 32);
	TIMER1_CTL = TIMER_CTL_TAEN;
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
	return cycles_now() / CYCLES_PER_MS;
}

uint64_t vmac_mcu_now_ns(void)
{
	return cycles_now() * NS_PER_CYCLE;
}
