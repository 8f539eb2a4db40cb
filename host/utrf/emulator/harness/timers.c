/* Quiet PWM timers: simavr's timer events the firmware cannot observe, left out.
 *
 * simavr runs each timer on cycle-timer events: an overflow and each compare match, every
 * period. The four 20 kHz PWM timers make about 240,000 of them a simulated second, and while
 * the firmware sleeps each one ends simavr's skip over the idle cycles: they cost a fifth of
 * the emulator's CPU time (measured: 0.120 -> 0.093 s per simulated second, five fingers in
 * POSITION, 100 Hz telemetry, timers 3, 4 and 5 quiet). Their only effects are interrupt
 * flags and the OCnX pins' waveforms; the harness takes the duty from the registers
 * (board_io.c), not from the waveforms. So a timer whose interrupts are all disabled and whose
 * counter the firmware has never read has its events cancelled before each run; its
 * registers, and the duty they give, are untouched. Reading its TCNT marks it for good and
 * restarts it (a write of its clock select, as the firmware's own set-up would: the first
 * reading then counts from that moment). What differs from the chip: such a timer's TOVn and
 * OCFnx flags stay clear (the firmware polls none).
 */
#include <string.h>

#include "avr_timer.h"
#include "harness_internal.h"

/* The PWM timers but timer 1: the firmware reads TCNT1 for its fine clock, and a restart
 * would shift its phase (a first read of another timer's TCNT still restarts it). */
static const char QUIET_TIMERS[] = {'3', '4', '5'};

static avr_timer_t *timer_named(avr_t *avr, char name)
{
    for (avr_io_t *io = avr->io_port; io; io = io->next)
        if (!strcmp(io->kind, "timer") && ((avr_timer_t *)io)->name == name)
            return (avr_timer_t *)io;
    return NULL;
}

static int enabled(avr_t *avr, const avr_int_vector_t *v)
{
    return v->enable.reg && avr_regbit_get(avr, v->enable);
}

static int observable(avr_t *avr, const avr_timer_t *t)
{
    if (enabled(avr, &t->overflow) || enabled(avr, &t->icr))
        return 1;
    for (int c = 0; c < AVR_TIMER_COMP_COUNT; c++)
        if (enabled(avr, &t->comp[c].interrupt))
            return 1;
    return 0;
}

static void restart(avr_t *avr, const avr_timer_t *t)
{
    uint16_t reg = t->cs[0].reg;
    if (!reg || reg < 32 || reg >= 32 + MAX_IOs)
        return;
    avr_io_addr_t io = AVR_DATA_TO_IO(reg);
    if (avr->io[io].w.c)
        avr->io[io].w.c(avr, reg, avr->data[reg], avr->io[io].w.param);
}

static uint8_t tcnt_read(avr_t *avr, avr_io_addr_t addr, void *param)
{
    quiet_timer_t *q = param;
    if (!q->read) {
        q->read = 1;
        if (q->quieted)
            restart(avr, q->timer);
        q->quieted = 0;
    }
    return q->orig_read ? q->orig_read(avr, addr, q->orig_param) : avr->data[addr];
}

void timers_init(utrf_sim_t *s)
{
    avr_t *avr = s->avr;
    s->n_quiet = 0;
    for (size_t i = 0; i < sizeof QUIET_TIMERS; i++) {
        avr_timer_t *t = timer_named(avr, QUIET_TIMERS[i]);
        if (!t || !t->r_tcnt || t->r_tcnt < 32 || t->r_tcnt >= 32 + MAX_IOs)
            continue;
        quiet_timer_t *q = &s->quiet[s->n_quiet++];
        avr_io_addr_t io = AVR_DATA_TO_IO(t->r_tcnt);
        q->timer = t;
        q->read = 0;
        q->quieted = 0;
        q->orig_read = avr->io[io].r.c;
        q->orig_param = avr->io[io].r.param;
        avr->io[io].r.c = tcnt_read;
        avr->io[io].r.param = q;
    }
}

void timers_quiet(utrf_sim_t *s)
{
    if (!s->quiet_timers)
        return;
    avr_t *avr = s->avr;
    for (int i = 0; i < s->n_quiet; i++) {
        quiet_timer_t *q = &s->quiet[i];
        if (q->read || observable(avr, q->timer))
            continue;
        /* The timer's events are simavr's static callbacks: found by their parameter. */
        avr_cycle_timer_t found[8];
        int n = 0;
        for (avr_cycle_timer_slot_p slot = avr->cycle_timers.timer; slot && n < 8;
             slot = slot->next)
            if (slot->param == q->timer)
                found[n++] = slot->timer;
        for (int k = 0; k < n; k++)
            avr_cycle_timer_cancel(avr, found[k], q->timer);
        q->quieted = 1;
        s->stats.quieted_timer_events += (uint64_t)n;
    }
}

void utrf_sim_set_quiet_timers(utrf_sim_t *s, int on)
{
    s->quiet_timers = on != 0;
    if (!on) /* give every quieted timer its events back */
        for (int i = 0; i < s->n_quiet; i++) {
            if (s->quiet[i].quieted)
                restart(s->avr, s->quiet[i].timer);
            s->quiet[i].quieted = 0;
        }
}
