/* The lockstep on a thread of its own, ahead of its caller (utrf_sim.h, "Running ahead"): a
 * driven client works on the frames of one stretch of simulated time while the board runs
 * the next. The run is utrf_sim_run_plant_until's, to the cycle: the periods in which a frame
 * ended are marked (where a client stopping at every frame would have looked) instead of
 * ending the run, and a heartbeat may be written at its time without stopping it.
 */
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "harness_internal.h"

struct utrf_ahead {
    pthread_t thread;
    int running;
    uint64_t target, period;
    int wake;
    int status;
};

int ahead_mark(utrf_sim_t *s)
{
    s->woke = 0;
    if (s->marks < UTRF_SIM_MARKS) {
        s->mark_cap[s->marks] = s->cap_head;
        s->mark_cycle[s->marks] = s->avr->cycle;
        s->marks++;
    }
    return s->marks < UTRF_SIM_MARKS;
}

void ahead_send_due(utrf_sim_t *s)
{
    if (!s->send_len || (double)s->avr->cycle / 16e6 < s->send_at)
        return;
    s->sent_n = utrf_sim_uart_write(s, s->send_buf, s->send_len);
    s->sent_cycle = s->avr->cycle;
    s->send_len = 0;
}

static void *ahead_main(void *arg)
{
    utrf_sim_t *s = arg;
    struct utrf_ahead *a = s->ahead;
    a->status = utrf_sim_run_plant_until(s, a->target, a->period, a->wake);
    return NULL;
}

int utrf_sim_ahead_start(utrf_sim_t *s, uint64_t target, uint64_t period, int wake)
{
    if (!s->ahead) {
        s->ahead = calloc(1, sizeof *s->ahead);
        if (!s->ahead)
            return -1;
    }
    struct utrf_ahead *a = s->ahead;
    if (a->running)
        return -1;
    a->target = target;
    a->period = period;
    a->wake = wake;
    s->marks = 0;
    s->mark_on = 1;
    if (pthread_create(&a->thread, NULL, ahead_main, s)) {
        s->mark_on = 0;
        return -1;
    }
    a->running = 1;
    return 0;
}

int utrf_sim_ahead_join(utrf_sim_t *s)
{
    struct utrf_ahead *a = s->ahead;
    if (!a || !a->running)
        return utrf_sim_status(s);
    pthread_join(a->thread, NULL);
    a->running = 0;
    s->mark_on = 0;
    return a->status;
}

int utrf_sim_ahead_running(const utrf_sim_t *s)
{
    return s->ahead && s->ahead->running;
}

size_t utrf_sim_ahead_marks(const utrf_sim_t *s, uint64_t *bytes, uint64_t *cycles, size_t n)
{
    size_t k = 0;
    for (; k < n && k < s->marks; k++) {
        bytes[k] = (uint32_t)(s->mark_cap[k] - s->cap_tail);
        cycles[k] = s->mark_cycle[k];
    }
    return k;
}

int utrf_sim_ahead_send(utrf_sim_t *s, const uint8_t *buf, size_t n, double at)
{
    if (n > UTRF_SIM_SEND_MAX || utrf_sim_ahead_running(s))
        return -1;
    memcpy(s->send_buf, buf, n);
    s->send_len = n;
    s->send_at = at;
    s->sent_cycle = 0;
    s->sent_n = 0;
    return 0;
}

uint64_t utrf_sim_ahead_sent(const utrf_sim_t *s, size_t *taken)
{
    if (taken)
        *taken = s->sent_n;
    return s->sent_cycle;
}

void ahead_close(utrf_sim_t *s)
{
    if (!s->ahead)
        return;
    utrf_sim_ahead_join(s);
    free(s->ahead);
    s->ahead = NULL;
}
