/* The plant on a thread of its own (utrf_sim_set_plant_threads(s, 2)): each exchange period
 * the MCU runs on the caller's thread while the plant steps the same period here. The two
 * are independent within a period (lockstep.c: both start from the state at the period's
 * start), so the results are those of one thread, to the bit.
 *
 * The hand-over, twice a period (a few hundred thousand times in a long run), is two
 * sequence numbers: each side spins on the other's for a while (a period is tens of µs of
 * work; a futex wake-up costs about as much), then sleeps on a futex. Where cores are scarce
 * (utrf_sim_set_plant_spin(s, 0)) the plant's side sleeps at once while a client works beside
 * the board (a run ahead, not being joined), and the MCU's thread steps the plant itself
 * meanwhile (lockstep.c): spinning there would take the core the client needs, and waking the
 * plant each period costs more than its step; it spins while the client waits.
 * Linux only, as the rest of the harness (ptys).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <linux/futex.h>
#include <pthread.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "harness_internal.h"

/* How long a side spins before it sleeps, adapted to what the waits take: a wait that ended
 * while spinning lets the next spin longer (up to SPIN_MAX_NS, beyond a period's work on this
 * project's machines), one that had to sleep halves it (on a loaded machine the other side is
 * often off its core: spinning then burns what it needs), but not below SPIN_MIN_NS, about
 * the MCU's longer periods: below that every hand-over wakes a sleeper, which sends the MCU's
 * thread inline (lockstep.c), whose stretch times the spin out again, down to nothing (the
 * spiral measured in docs/benchmarks.md). A loaded machine is lockstep.c's to detect. */
#define SPIN_MIN_NS 150000L
#define SPIN_START_NS SPIN_MIN_NS
#define SPIN_MAX_NS 400000L

struct utrf_plant_thread {
    pthread_t thread;
    pid_t pid; /* the process that started it: a fork's child has no such thread */
    utrf_sim_t *s;
    double dt;
    int quit;
    _Atomic uint32_t go;   /* caller -> plant: periods handed over */
    _Atomic uint32_t done; /* plant -> caller: periods stepped */
    _Atomic int plant_asleep, caller_asleep;
    _Atomic int parked;          /* the caller has left the lockstep: the plant need not spin */
    _Atomic int plant_sleeps;    /* the plant's side sleeps at once while the client is busy */
    _Atomic int no_spin;         /* always set: wait_change's stop for a side that never spins */
    _Atomic long step_ns;        /* the last step's time on this thread */
    long plant_spin, caller_spin; /* each side's spin budget (ns) */
};

static void futex_wait(_Atomic uint32_t *addr, uint32_t expected)
{
    syscall(SYS_futex, (uint32_t *)addr, FUTEX_WAIT_PRIVATE, expected, NULL, NULL, 0);
}

static void futex_wake(_Atomic uint32_t *addr)
{
    syscall(SYS_futex, (uint32_t *)addr, FUTEX_WAKE_PRIVATE, 1, NULL, NULL, 0);
}

static inline void cpu_relax(void)
{
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#endif
}

/* Wait until *word differs from `from`: spin (while *parked is 0), then sleep (the other side
 * wakes a sleeper it sees flagged; the flag is set before the last look, so no wake-up is
 * lost). */
static uint32_t wait_change(_Atomic uint32_t *word, uint32_t from, _Atomic int *asleep,
                            long *budget, const _Atomic int *parked)
{
    uint32_t v;
    long deadline = 0;
    for (unsigned i = 1;; i++) {
        if ((v = atomic_load_explicit(word, memory_order_acquire)) != from) {
            *budget = *budget + *budget / 4 < SPIN_MAX_NS ? *budget + *budget / 4 : SPIN_MAX_NS;
            return v;
        }
        if (parked && atomic_load_explicit(parked, memory_order_relaxed))
            break;
        cpu_relax();
        if ((i & 63) == 0) {
            long t = harness_now_ns();
            if (!deadline)
                deadline = t + *budget;
            else if (t > deadline) {
                *budget = *budget / 2 > SPIN_MIN_NS ? *budget / 2 : SPIN_MIN_NS;
                break;
            }
        }
    }
    atomic_store(asleep, 1);
    while ((v = atomic_load(word)) == from)
        futex_wait(word, from);
    atomic_store(asleep, 0);
    return v;
}

static void post(_Atomic uint32_t *word, uint32_t value, _Atomic int *asleep)
{
    atomic_store(word, value);
    if (atomic_load(asleep))
        futex_wake(word);
}

static int sleeps_now(utrf_plant_thread_t *t)
{
    return atomic_load_explicit(&t->plant_sleeps, memory_order_relaxed) &&
           atomic_load_explicit(&t->s->client_busy, memory_order_relaxed);
}

int plant_thread_sleeps_now(utrf_sim_t *s)
{
    return s->plant_thread && sleeps_now(s->plant_thread);
}

static void *plant_main(void *arg)
{
    utrf_plant_thread_t *t = arg;
    uint32_t seen = 0;
    for (;;) {
        /* sleeping at once: a stop that reads as set, so the wait skips its spin */
        seen = wait_change(&t->go, seen, &t->plant_asleep, &t->plant_spin,
                           sleeps_now(t) ? &t->no_spin : &t->parked);
        if (t->quit)
            return NULL;
        utrf_sim_t *s = t->s;
        long t0 = harness_now_ns();
        if (s->plant_step)
            s->plant_step(s->plant_ctx, t->dt, s->hold);
        atomic_store_explicit(&t->step_ns, harness_now_ns() - t0, memory_order_relaxed);
        post(&t->done, seen, &t->caller_asleep);
    }
}

int plant_thread_start(utrf_sim_t *s)
{
    utrf_plant_thread_t *t = s->plant_thread;
    if (t && t->pid == getpid())
        return 0;
    if (t) { /* started by the process this one forked from: not here */
        free(t);
        s->plant_thread = NULL;
    }
    t = calloc(1, sizeof *t);
    if (!t)
        return -1;
    t->s = s;
    t->pid = getpid();
    t->plant_spin = t->caller_spin = SPIN_START_NS;
    t->parked = 1;
    t->plant_sleeps = !s->plant_spin;
    t->no_spin = 1;
    /* signals stay with the caller's threads (Python handles them there) */
    sigset_t all, old;
    sigfillset(&all);
    pthread_sigmask(SIG_SETMASK, &all, &old);
    int rc = pthread_create(&t->thread, NULL, plant_main, t);
    pthread_sigmask(SIG_SETMASK, &old, NULL);
    if (rc) {
        free(t);
        return -1;
    }
    pthread_setname_np(t->thread, "utrf-plant"); /* named for a profile's per-thread clocks */
    s->plant_thread = t;
    return 0;
}

void plant_thread_stop(utrf_sim_t *s)
{
    utrf_plant_thread_t *t = s->plant_thread;
    if (!t)
        return;
    s->plant_thread = NULL;
    if (t->pid == getpid()) {
        t->quit = 1;
        post(&t->go, atomic_load(&t->go) + 1, &t->plant_asleep);
        pthread_join(t->thread, NULL);
    }
    free(t);
}

void plant_thread_step(utrf_sim_t *s, double dt)
{
    utrf_plant_thread_t *t = s->plant_thread;
    t->dt = dt;
    atomic_store_explicit(&t->parked, 0, memory_order_relaxed);
    post(&t->go, atomic_load_explicit(&t->go, memory_order_relaxed) + 1, &t->plant_asleep);
}

void plant_thread_wait(utrf_sim_t *s)
{
    utrf_plant_thread_t *t = s->plant_thread;
    uint32_t go = atomic_load_explicit(&t->go, memory_order_relaxed);
    uint32_t done = atomic_load_explicit(&t->done, memory_order_acquire);
    while (done != go)
        done = wait_change(&t->done, done, &t->caller_asleep, &t->caller_spin, NULL);
}

long plant_thread_step_ns(utrf_sim_t *s)
{
    return atomic_load_explicit(&s->plant_thread->step_ns, memory_order_relaxed);
}

int utrf_sim_set_plant_spin(utrf_sim_t *s, int spin)
{
    s->plant_spin = spin ? 1 : 0;
    if (s->plant_thread)
        atomic_store(&s->plant_thread->plant_sleeps, !s->plant_spin);
    return 0;
}

void plant_thread_park(utrf_sim_t *s)
{
    atomic_store_explicit(&s->plant_thread->parked, 1, memory_order_relaxed);
}
