/* The lockstep on a thread of its own, ahead of its caller (utrf_sim.h, "Running ahead"): a
 * driven client works on the frames of one stretch of simulated time while the board runs
 * the next. The run is utrf_sim_run_plant_until's, to the cycle: the periods in which a frame
 * ended are marked (where a client stopping at every frame would have looked) instead of
 * ending the run, and a heartbeat may be written at its time without stopping it.
 */
#define _GNU_SOURCE
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "harness_internal.h"

#define AHEAD_SPIN_START_NS 100000L
#define AHEAD_SPIN_MAX_NS 500000L
#define AHEAD_SPIN_MIN_NS 5000L

struct utrf_ahead {
    pthread_t thread;
    pid_t pid; /* the process that started the thread: a fork's child has no such thread */
    pthread_mutex_t mu;
    pthread_cond_t cv;
    _Atomic int work; /* under mu (read outside it while spinning): 1 a run to do, 2 done */
    int quit;         /* under mu: the thread to end */
    long spin_ns;     /* how long the thread spins for the next run before it sleeps */
    int running;    /* the caller's: a run started, not joined */
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

/* After a run, the caller's stop (the sample's truth, the next run's start) is short: the
 * thread spins for the next run a while before it sleeps, sparing the caller a wake-up on the
 * critical path (tens of µs on a virtual machine). The spin grows while the next run comes
 * within it and halves when it does not (a caller that works longer, a core that is busy). */
static void ahead_spin(struct utrf_ahead *a)
{
    long deadline = harness_now_ns() + a->spin_ns;
    for (unsigned i = 1; atomic_load_explicit(&a->work, memory_order_acquire) != 1; i++) {
        if ((i & 63) == 0 && harness_now_ns() > deadline) {
            a->spin_ns = a->spin_ns / 2 > AHEAD_SPIN_MIN_NS ? a->spin_ns / 2 : AHEAD_SPIN_MIN_NS;
            return;
        }
#if defined(__x86_64__) || defined(__i386__)
        __builtin_ia32_pause();
#endif
    }
    a->spin_ns = a->spin_ns + a->spin_ns / 4 < AHEAD_SPIN_MAX_NS ? a->spin_ns + a->spin_ns / 4
                                                                  : AHEAD_SPIN_MAX_NS;
}

/* At a stop: the MCU's cycle, the hits due applied, the plant's truth (utrf_sim_ahead_stops). */
static void ahead_stop(utrf_sim_t *s, uint32_t k)
{
    uint64_t cycle = s->avr->cycle;
    double t = (double)cycle / 16e6 - s->stop_t0; /* as the client's clock reads it */
    s->stop_cycle[k] = cycle;
    while (s->stop_hits_done < s->stop_hits_n && t >= s->stop_hit[s->stop_hits_done].at) {
        if (s->plant_hit)
            s->plant_hit(s->plant_ctx, &s->stop_hit[s->stop_hits_done]);
        s->stop_hit_at[s->stop_hits_done++] = (int32_t)k;
    }
    if (s->plant_truth)
        s->plant_truth(s->plant_ctx, s->stop_truth[k]);
    else
        memset(s->stop_truth[k], 0, sizeof s->stop_truth[k]);
    s->stops_done = k + 1;
}

/* The run, through its stops when it has any: each stretch is the run ahead to that stop,
 * and a stretch that ends short (a crash, the marks full) or changes the status ends it. */
static int ahead_run(utrf_sim_t *s, struct utrf_ahead *a)
{
    if (!s->stops_n)
        return utrf_sim_run_plant_until(s, a->target, a->period, a->wake);
    int status = utrf_sim_status(s);
    for (uint32_t k = 0; k < s->stops_n; k++) {
        /* between two stops the plant's thread may keep spinning: the next stretch follows */
        if (beats_arm(s, s->stop_target[k])) { /* the client decides the next heartbeat */
            if (s->plant_thread && s->plant_threads == 2)
                plant_thread_park(s);
            return status;
        }
        s->lock_keep_plant = k + 1 < s->stops_n;
        int now = utrf_sim_run_plant_until(s, s->stop_target[k], a->period, a->wake);
        s->lock_keep_plant = 0;
        beats_stretch_end(s);
        if (now != status || s->avr->cycle < s->stop_target[k]) {
            if (s->plant_thread && s->plant_threads == 2)
                plant_thread_park(s); /* the run ends here, short */
        }
        if (s->avr->cycle < s->stop_target[k])
            return now;
        ahead_stop(s, k);
        if (now != status)
            return now;
    }
    return status;
}

/* One thread for the board's life, woken for each run: a thread a run (thousands of runs a
 * hold) would cost its creation every time. */
static void *ahead_main(void *arg)
{
    utrf_sim_t *s = arg;
    struct utrf_ahead *a = s->ahead;
    pthread_mutex_lock(&a->mu);
    for (;;) {
        if (a->work == 2 && !a->quit) { /* a run just done: spin a while for the next */
            pthread_mutex_unlock(&a->mu);
            ahead_spin(a);
            pthread_mutex_lock(&a->mu);
        }
        while (a->work != 1 && !a->quit)
            pthread_cond_wait(&a->cv, &a->mu);
        if (a->quit)
            break;
        pthread_mutex_unlock(&a->mu);
        int status = ahead_run(s, a);
        pthread_mutex_lock(&a->mu);
        a->status = status;
        a->work = 2; /* done */
        pthread_cond_broadcast(&a->cv);
    }
    pthread_mutex_unlock(&a->mu);
    return NULL;
}

static int ahead_thread(utrf_sim_t *s)
{
    struct utrf_ahead *a = s->ahead;
    if (a && a->pid == getpid())
        return 0;
    if (!a) {
        a = calloc(1, sizeof *a);
        if (!a)
            return -1;
        s->ahead = a;
    }
    /* new, or inherited by a forked child without its thread: start afresh */
    memset(a, 0, sizeof *a);
    a->spin_ns = AHEAD_SPIN_START_NS;
    pthread_mutex_init(&a->mu, NULL);
    pthread_cond_init(&a->cv, NULL);
    if (pthread_create(&a->thread, NULL, ahead_main, s)) {
        free(a);
        s->ahead = NULL;
        return -1;
    }
    pthread_setname_np(a->thread, "utrf-board"); /* named for a profile's per-thread clocks */
    a->pid = getpid();
    return 0;
}

int utrf_sim_ahead_start(utrf_sim_t *s, uint64_t target, uint64_t period, int wake)
{
    if (utrf_sim_ahead_running(s) || ahead_thread(s))
        return -1;
    struct utrf_ahead *a = s->ahead;
    s->marks = 0;
    s->mark_on = 1;
    s->beats_ran = 0;
    s->stops_done = 0;
    s->stop_hits_done = 0;
    if (s->stops_n && s->stop_target[s->stops_n - 1] != target)
        s->stops_n = 0; /* stops for another run: none */
    if (!s->stops_n)
        s->beats_on = 0; /* heartbeats go with stops */
    if (!s->beats_on)
        s->beats_sent = 0;
    /* busy before the run can start: its first period already sees the client beside it */
    atomic_store_explicit(&s->client_busy, 1, memory_order_relaxed);
    pthread_mutex_lock(&a->mu);
    a->target = target;
    a->period = period;
    a->wake = wake;
    a->work = 1;
    pthread_cond_broadcast(&a->cv);
    pthread_mutex_unlock(&a->mu);
    a->running = 1;
    return 0;
}

int utrf_sim_ahead_join(utrf_sim_t *s)
{
    struct utrf_ahead *a = s->ahead;
    if (!utrf_sim_ahead_running(s))
        return utrf_sim_status(s);
    atomic_store_explicit(&s->client_busy, 0, memory_order_relaxed); /* the plant may spin */
    pthread_mutex_lock(&a->mu);
    while (a->work != 2)
        pthread_cond_wait(&a->cv, &a->mu);
    a->work = 0;
    pthread_mutex_unlock(&a->mu);
    a->running = 0;
    s->mark_on = 0;
    s->stops_n = 0; /* what they recorded stays for utrf_sim_ahead_stops_done */
    s->beats_ran = s->beats_on;
    s->beats_on = 0; /* and the heartbeats sent for utrf_sim_ahead_beats_done */
    return a->status;
}

int utrf_sim_ahead_stops(utrf_sim_t *s, const uint64_t *targets, size_t n, double t0,
                         const utrf_sim_hit_t *hits, size_t nhits)
{
    if (n > UTRF_SIM_STOPS || nhits > UTRF_SIM_HITS || utrf_sim_ahead_running(s))
        return -1;
    for (size_t k = 1; k < n; k++)
        if (targets[k] <= targets[k - 1])
            return -1;
    memcpy(s->stop_target, targets, n * sizeof *targets);
    memcpy(s->stop_hit, hits, nhits * sizeof *hits);
    for (size_t j = 0; j < nhits; j++)
        s->stop_hit_at[j] = -1;
    s->stops_n = (uint32_t)n;
    s->stop_hits_n = (uint32_t)nhits;
    s->stop_t0 = t0;
    return 0;
}

size_t utrf_sim_ahead_stops_done(const utrf_sim_t *s, uint64_t *cycles, double *truth,
                                 int32_t *hit_stop, size_t n)
{
    size_t k = 0;
    for (; k < n && k < s->stops_done; k++) {
        cycles[k] = s->stop_cycle[k];
        memcpy(truth + k * UTRF_SIM_TRUTH, s->stop_truth[k], sizeof s->stop_truth[k]);
    }
    for (size_t j = 0; j < s->stop_hits_n; j++)
        hit_stop[j] = s->stop_hit_at[j];
    return k;
}

int utrf_sim_ahead_running(const utrf_sim_t *s)
{
    return s->ahead && s->ahead->running && s->ahead->pid == getpid();
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
    struct utrf_ahead *a = s->ahead;
    if (!a)
        return;
    if (a->pid == getpid()) {
        utrf_sim_ahead_join(s);
        pthread_mutex_lock(&a->mu);
        a->quit = 1;
        pthread_cond_broadcast(&a->cv);
        pthread_mutex_unlock(&a->mu);
        pthread_join(a->thread, NULL);
        pthread_mutex_destroy(&a->mu);
        pthread_cond_destroy(&a->cv);
    }
    free(a);
    s->ahead = NULL;
}
