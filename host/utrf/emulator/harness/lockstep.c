/* Lockstep of the MCU with the plant attached to the board (mjplant.c attaches the MuJoCo
 * hand): the MCU runs each exchange period with the encoders as the plant had them at its
 * start, and the plant steps the same period with the pins as they were at its start.
 *
 * The plant keeps its own clock in MCU cycles and steps exact periods (plant_cycle + period,
 * or up to the run's target): the MCU ends a run at the first instruction boundary at or past
 * the period's end, and that overshoot is carried into its next period, which is shorter by
 * it. Within a period neither side reads what the other writes, so the plant may step on its
 * own thread (plant_thread.c) while the MCU runs: the same results either way.
 *
 * With two threads the MCU's thread keeps the hand-over honest: where posting the period and
 * waiting for the plant costs it more than stepping the plant itself would (no core free for
 * the plant's thread: other work on the machine), it steps the plant itself for a stretch of
 * periods, then tries the thread again; and it steps the plant itself while the plant's
 * thread sleeps for a client working beside the board (plant_thread_sleeps_now).
 */
#include <string.h>

#include "harness_internal.h"

#define CPU_HZ 16e6
/* periods stepped on the MCU's thread before the plant's is tried again: a stretch doubles,
 * up to INLINE_STRETCH_MAX (about 4 s simulated), while the thread fails again within the
 * first stretch's count of hand-overs (a machine that stays loaded: each try wakes a parked
 * thread that waits for a core), and is back to INLINE_STRETCH after a longer run of them */
#define INLINE_STRETCH 32
#define INLINE_STRETCH_MAX 4096

/* A running mean (x16) moved 1/32 of the way to x: one hand-over that waited out a
 * preemption (milliseconds) must not send a stretch inline, a machine that keeps the plant's
 * thread off its core does within a few dozen periods. */
static void mean16(long *m16, long x)
{
    *m16 += (x * 16 - *m16) / 32;
}

/* The plant's clock. When the MCU ran without it since the last exchange (utrf_sim_run_to),
 * the plant takes up again from where the MCU is (it skipped that time). */
static uint64_t plant_clock(utrf_sim_t *s)
{
    if (s->avr->cycle != s->lock_mcu_cycle) {
        s->plant_cycle = s->avr->cycle;
        s->lock_mcu_cycle = s->avr->cycle;
    }
    return s->plant_cycle;
}

uint64_t utrf_sim_plant_cycle(utrf_sim_t *s)
{
    return plant_clock(s);
}

int utrf_sim_set_plant_threads(utrf_sim_t *s, int threads)
{
    if (threads == 1) {
        plant_thread_stop(s);
        s->plant_threads = 1;
        return 0;
    }
    if (threads != 2)
        return -1;
    if (plant_thread_start(s))
        return -2;
    s->plant_threads = 2;
    return 0;
}

int utrf_sim_plant_threads(const utrf_sim_t *s)
{
    return s->plant_threads;
}

uint64_t utrf_sim_plant_wait_ns(const utrf_sim_t *s)
{
    return s->lock_wait_ns;
}

uint64_t utrf_sim_plant_inline_periods(const utrf_sim_t *s)
{
    return s->lock_inline_periods;
}

int utrf_sim_run_plant(utrf_sim_t *s, uint64_t target, uint64_t period)
{
    return utrf_sim_run_plant_until(s, target, period, -1);
}

int utrf_sim_run_plant_until(utrf_sim_t *s, uint64_t target, uint64_t period, int wake)
{
    int status = utrf_sim_status(s);
    if (!period)
        period = 1;
    s->wake_byte = wake >= 0 && wake <= 255 ? wake : -1;
    s->woke = 0;
    uint64_t at = plant_clock(s);
    /* a forked child has no plant thread: it starts its own */
    int threaded = s->plant_step && s->plant_threads == 2 && plant_thread_start(s) == 0;
    while (s->avr->cycle < target && !s->woke) {
        if (s->send_len)
            ahead_send_due(s);
        uint64_t end = at + period < target ? at + period : target;
        double dt = (double)(end - at) / CPU_HZ;
        memcpy(s->hold, s->pins, sizeof s->hold);
        if (s->plant_volts)
            s->plant_volts(s->plant_ctx, s->adc_volts);
        /* while the plant's thread would sleep at once (a client working beside the board
         * with no core for each: plant_thread.c), waking it costs more than its step */
        int handover = threaded && s->lock_inline_left == 0 && !plant_thread_sleeps_now(s);
        long t0 = 0, posted = 0;
        if (handover) {
            t0 = harness_now_ns();
            plant_thread_step(s, dt);
            posted = harness_now_ns() - t0;
        }
        int now = utrf_sim_run_to(s, end);
        if (handover) {
            t0 = harness_now_ns();
            plant_thread_wait(s);
            long waited = harness_now_ns() - t0;
            s->lock_wait_ns += (uint64_t)waited;
            mean16(&s->lock_handover_ns16, posted + waited);
            mean16(&s->lock_step_ns16, plant_thread_step_ns(s));
            s->lock_handed++;
            if (s->lock_handover_ns16 > s->lock_step_ns16) { /* cheaper here: a stretch */
                int again = s->lock_stretch && s->lock_handed < INLINE_STRETCH;
                s->lock_stretch = !again                             ? INLINE_STRETCH
                                  : s->lock_stretch < INLINE_STRETCH_MAX ? 2 * s->lock_stretch
                                                                       : INLINE_STRETCH_MAX;
                s->lock_handed = 0;
                s->lock_inline_left = s->lock_stretch;
                s->lock_handover_ns16 = s->lock_step_ns16 / 2; /* the next try starts fair */
                plant_thread_park(s); /* the plant's thread sleeps through it, not spins */
            }
        } else if (s->plant_step) {
            s->plant_step(s->plant_ctx, dt, s->hold);
            if (threaded) {
                if (s->lock_inline_left > 0)
                    s->lock_inline_left--;
                s->lock_inline_periods++;
            }
        }
        at = s->plant_cycle = end;
        s->lock_mcu_cycle = s->avr->cycle;
        beats_period_end(s);
        if (now != status) {
            status = now;
            break;
        }
        if (s->woke && s->mark_on && !ahead_mark(s))
            break; /* the marks are full: the caller reads them and runs on */
    }
    if (s->send_len && status == utrf_sim_status(s))
        ahead_send_due(s); /* at the run's last period's end too */
    if (threaded && !s->lock_keep_plant)
        plant_thread_park(s);
    s->wake_byte = -1;
    return status;
}
