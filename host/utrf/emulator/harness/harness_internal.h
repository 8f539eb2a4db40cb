/* Internals shared by the harness's C files. Not part of the ctypes interface. */
#ifndef UTRF_HARNESS_INTERNAL_H
#define UTRF_HARNESS_INTERNAL_H

#include <stdatomic.h>
#include <stdint.h>
#include <time.h>

#include "avr_uart.h"
#include "avr_watchdog.h"
#include "sim_avr.h"
#include "sim_elf.h"
#include "utrf_sim.h"

#define RX_QUEUE_SIZE 65536u   /* host bytes waiting for the wire (power of two) */
#define TX_QUEUE_SIZE 8192u    /* bytes on the wire toward the host (power of two) */
#define CAPTURE_SIZE 1048576u  /* in-process output buffer (power of two) */
#define BEAT_ACC 80u           /* beats.c: a frame's bytes kept (the protocol's longest is 69) */

/* The monotonic clock in ns: the threads' spins and the hand-over's timing. */
static inline long harness_now_ns(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec * 1000000000L + t.tv_nsec;
}
#define LOG_SIZE 4096u
#define UTRF_RX_ARRIVALS 4u    /* arrival times of the receive FIFO's bytes (power of two, > 2) */

/* An AVR interrupt vector's simavr IRQ (faults.c's stalls, profile.c's timing): NULL for a
 * vector outside 1..255 or one the core does not have. */
static inline avr_irq_t *utrf_vector_irq(avr_t *avr, int vector)
{
    if (vector <= 0 || vector > 255)
        return NULL;
    return avr_get_interrupt_irq(avr, (uint8_t)vector);
}

/* ---- the plant's drive, encoder and noise (drive.c) ----------------------------------------------------- */
typedef struct {
    uint64_t state;
    double spare;
    int have_spare;
} utrf_rng_t;

/* xorshift64*: small, fast and reproducible for a seed; the one generator of the plant's noise
 * (utrf_rng_t) and the line faults (utrf_sim_t.rng). The state must not be zero. */
static inline uint64_t utrf_xorshift64s(uint64_t *state)
{
    uint64_t x = *state;
    x ^= x >> 12;
    x ^= x << 25;
    x ^= x >> 27;
    *state = x;
    return x * 0x2545F4914F6CDD1DULL;
}

/* A uniform double in [0, 1) from the generator's top 53 bits. */
static inline double utrf_xorshift64s_uniform(uint64_t *state)
{
    return (double)(utrf_xorshift64s(state) >> 11) * (1.0 / 9007199254740992.0);
}

void utrf_rng_init(utrf_rng_t *r, uint64_t seed); /* any seed, 0 included */
double utrf_rng_normal(utrf_rng_t *r);            /* standard Gaussian */

enum { UTRF_DRIVE_COAST = 0, UTRF_DRIVE_BRAKE = 1, UTRF_DRIVE_FORWARD = 2, UTRF_DRIVE_REVERSE = 3 };
/* The TB6612FNG's truth table for one channel's pin block (duty, IN1, IN2, STBY): the mode,
 * and the signed duty the motor sees (0 when braking or coasting). */
int utrf_tb6612(const double *block, double *signed_duty);

typedef struct {
    double supply, offset, band[2], noise_v;
    int invert, bits;
} utrf_as5600_t;
/* The AS5600's analog output (V) for a Joint-2 angle: quantised to 2^bits a turn inside the
 * band, plus seeded Gaussian noise. */
double utrf_as5600_volts(const utrf_as5600_t *e, double theta2, utrf_rng_t *r);

typedef struct {
    uint8_t byte;
    uint64_t due; /* cycle at which its stop bit ends */
} tx_byte_t;

typedef struct {
    double drop, corrupt, insert, duplicate, burst;
    uint32_t burst_min, burst_max; /* a burst's length in bytes */
    uint32_t burst_left;           /* bytes of the burst under way still to garble */
} line_faults_t;

struct avr_timer_t;
typedef struct {
    avr_io_write_t c;
    void *param;
} io_write_hook_t;

typedef struct {
    avr_io_read_t c;
    void *param;
} io_read_hook_t;

typedef struct {
    struct avr_timer_t *timer;
    int quieted; /* its events were cancelled */
    avr_io_read_t orig_read;
    void *orig_param;
    io_write_hook_t orig_ocr[3]; /* simavr's handlers of OCRnA..C's writes */
} quiet_timer_t;

typedef struct {
    utrf_sim_profile_t p;
    int active;    /* inside a call */
    int paused;    /* a nested interrupt runs */
    int depth;     /* the interrupt nesting depth the call runs at (0: the main program) */
    uint64_t entry, seg, excl;
    uint16_t sp0;  /* function profile: SP at entry */
    int waiting;   /* vector profile: its flag is raised, its handler not yet entered */
    uint64_t raised_at;
} profile_state_t;

struct utrf_sim {
    avr_t *avr;
    elf_firmware_t fw;
    avr_uart_t *uart0;
    avr_watchdog_t *watchdog;
    avr_irq_t *uart_irq; /* UART0's IRQ block */
    avr_irq_t *adc_irq;  /* the ADC's IRQ block */
    avr_io_t hook;       /* our module at the end of simavr's list: sees every reset */

    /* lockstep */
    int in_run;
    volatile int stop;
    uint64_t target;
    double adc_volts[UTRF_SIM_ADC_CHANNELS];
    double pins[UTRF_SIM_PIN_VALUES];

    /* UART bridge */
    uint8_t rx[RX_QUEUE_SIZE];
    uint32_t rx_head, rx_tail;
    int rx_wire_active;
    tx_byte_t tx[TX_QUEUE_SIZE];
    uint32_t tx_head, tx_tail;
    uint8_t *capture;
    uint32_t cap_head, cap_tail;
    int capture_on;
    uint64_t frame_start[UTRF_SIM_FRAME_LOG], frame_end[UTRF_SIM_FRAME_LOG]; /* captured frames */
    uint32_t frames_head, frames_tail;
    uint64_t tx_frame_start; /* the captured frame under way: its first byte's start (0: none) */
    int wake_byte; /* utrf_sim_run_plant_until: the byte it waits for (-1: none) */
    int woke;      /* it was captured */
    line_faults_t faults[2];
    uint64_t rng;
    uint64_t frame_cycles;
    /* the chip's receiver: the byte on the wire, the shift register, the FIFO's arrivals */
    int rx_on_wire;
    uint16_t rx_wire_byte;      /* with UART_INPUT_FE when its stop bit was damaged */
    int rx_shift_full;          /* a complete byte waits there: the FIFO was full */
    uint16_t rx_shift_byte;
    uint64_t rx_shift_arrival;
    int rx_lost_pending;        /* a byte was lost: the next into the FIFO carries DOR0 */
    uint64_t rx_arrival[UTRF_RX_ARRIVALS];
    uint32_t rx_arr_head, rx_arr_tail;
    utrf_sim_rx_timing_t rx_timing;
    io_read_hook_t udr_read, ucsra_read; /* simavr's handlers of UDR0's and UCSR0A's reads */

    /* serving */
    int pty_fd;
    char pty_path[128];
    int pty_open;
    int pty_dtr; /* the modelled DTR line of the pty (see serve.c) */
    int pty_refused; /* the pty was opened while a TCP host was attached: turned away */
    int listen_fd;
    int client_fd;
    int auto_reset;
    uint64_t auto_reset_hold;
    uint64_t hold_until; /* the MCU stays in reset until this cycle */

    /* resets and EEPROM */
    int pending_cause; /* -1: none (watchdog or simavr-internal) */
    int64_t eempe_cycle;

    profile_state_t prof_vec, prof_fn[UTRF_SIM_FUNCTION_PROFILES];
    int prof_vector;    /* vector profiled, 0: none */
    int prof_requires;  /* the function slot the vector's calls must run (-1: none) */
    int64_t prof_addr[UTRF_SIM_FUNCTION_PROFILES]; /* functions profiled (byte address), -1: none */
    int prof_functions; /* how many slots profile a function */
    int depth;          /* interrupts running, nested (0: the main program) */
    uint64_t *pc_hist;  /* utrf_sim_pc_histogram: cycles per program word (NULL: off) */
    size_t pc_hist_words;
    int pc_hist_slot;   /* whose cycles: a function slot, or -1 every instruction's */

    /* a jump waiting for the PC to reach jump_at (byte address; -1: none) */
    int64_t jump_at;
    uint32_t jump_to;
    int jump_interrupts;

    /* the plant stepped in lockstep (mjplant.c, lockstep.c); not owned */
    uint64_t plant_cycle;    /* the plant's clock: it has stepped up to this cycle */
    uint64_t lock_mcu_cycle; /* the MCU's cycle when the lockstep last left it */
    double hold[UTRF_SIM_PIN_VALUES]; /* the pins the plant steps the period with */
    int plant_threads;       /* 2: the plant steps on its own thread (plant_thread.c) */
    struct utrf_plant_thread *plant_thread;
    int plant_spin; /* 1: the plant's thread spins before it sleeps (utrf_sim_set_plant_spin) */
    _Atomic int client_busy; /* run_ahead.c: a run ahead is under way, its caller not joining */
    /* lockstep.c, two threads: what a period's hand-over costs the MCU's thread (posting and
     * waiting) against what stepping the plant itself would (ns, running means x16), and how
     * many periods are left to step it here before the thread is tried again; the stretch's
     * length (doubled when the thread failed again soon after one) and the hand-overs since */
    long lock_handover_ns16, lock_step_ns16;
    int lock_inline_left, lock_stretch, lock_handed;
    uint64_t lock_inline_periods; /* periods two threads stepped on one, for a test to read */
    uint64_t lock_wait_ns; /* the MCU's thread waiting for the plant's at the hand-overs */
    int lock_keep_plant; /* a run ahead's stops: the run goes on at once, the plant not parked */
    void *plant_ctx;
    void (*plant_step)(void *ctx, double dt, const double *pins);
    void (*plant_volts)(void *ctx, double *out5);
    void (*plant_truth)(void *ctx, double *out); /* UTRF_SIM_TRUTH doubles */
    int (*plant_hit)(void *ctx, const utrf_sim_hit_t *hit);

    /* run_ahead.c: the lockstep on a thread of its own while the caller works; each period in
     * which the wake byte was captured is marked (the capture's head, the MCU's cycle) rather
     * than ending the run, and one host write may wait for its time */
    int mark_on;
    uint32_t marks;
    uint32_t mark_cap[UTRF_SIM_MARKS];
    uint64_t mark_cycle[UTRF_SIM_MARKS];
    uint8_t send_buf[UTRF_SIM_SEND_MAX];
    size_t send_len;  /* bytes waiting for send_at (0: none) */
    double send_at;   /* written at the first period's end whose MCU time (s) reaches it */
    uint64_t sent_cycle; /* where they went (0: not yet) */
    size_t sent_n;       /* how many the UART queue took */
    struct utrf_ahead *ahead;
    /* run_ahead.c: the stops within the next run ahead (utrf_sim_ahead_stops) */
    uint32_t stops_n, stops_done;
    uint64_t stop_target[UTRF_SIM_STOPS], stop_cycle[UTRF_SIM_STOPS];
    double stop_truth[UTRF_SIM_STOPS][UTRF_SIM_TRUTH];
    double stop_t0;
    utrf_sim_hit_t stop_hit[UTRF_SIM_HITS];
    int32_t stop_hit_at[UTRF_SIM_HITS];
    uint32_t stop_hits_n, stop_hits_done;
    /* beats.c: the output framed as the client frames it, and the next run ahead's heartbeats
     * sent at the client's times (utrf_sim_ahead_beats) */
    uint8_t acc[BEAT_ACC];
    size_t acc_n;
    int acc_sync, acc_over; /* a 0x00 seen since the capture began; the frame too long */
    int beats_on, beat_heard, beat_frozen;
    int beats_ran; /* the last run ahead joined had them (utrf_sim_ahead_beats_next) */
    uint32_t beats_n, beats_sent;
    uint8_t beat_frame[UTRF_SIM_BEATS][UTRF_SIM_BEAT_BYTES];
    uint8_t beat_len[UTRF_SIM_BEATS], beat_seq[UTRF_SIM_BEATS];
    uint8_t beat_acks[16];  /* the seqs whose ack the client awaits, a bit each */
    uint8_t beat_kind[256]; /* per message id: 0 other, 1 the stream, 2 an ack */
    double beat_due, beat_period, beat_at[UTRF_SIM_BEATS];
    uint64_t beat_cycle[UTRF_SIM_BEATS];

    /* faults.c: a stalled interrupt vector (0: none) */
    int stall_vector;
    uint64_t stall_cycles;
    int64_t stall_count; /* stalls left; -1: every entry */

    /* timers.c */
    quiet_timer_t quiet[4];
    int n_quiet;
    int quiet_timers;

    utrf_sim_stats_t stats;
    char log[LOG_SIZE];
    size_t log_len;
};

/* mjplant.c: attach the plant's stepping and encoder volts to the board, or detach it
 * (ctx NULL). */
static inline void utrf_sim_attach_ops(utrf_sim_t *s, void *ctx,
                                       void (*step)(void *ctx, double dt, const double *pins),
                                       void (*volts)(void *ctx, double *out5),
                                       void (*truth)(void *ctx, double *out),
                                       int (*hit)(void *ctx, const utrf_sim_hit_t *h))
{
    s->plant_ctx = ctx;
    s->plant_step = ctx ? step : NULL;
    s->plant_volts = ctx ? volts : NULL;
    s->plant_truth = ctx ? truth : NULL;
    s->plant_hit = ctx ? hit : NULL;
}

/* plant_thread.c: the plant's thread, started (again in a forked child) or stopped; one
 * period handed over (the plant steps dt with s->hold), and waited for */
typedef struct utrf_plant_thread utrf_plant_thread_t;
int plant_thread_start(utrf_sim_t *s);
void plant_thread_stop(utrf_sim_t *s);
void plant_thread_step(utrf_sim_t *s, double dt);
void plant_thread_wait(utrf_sim_t *s);
void plant_thread_park(utrf_sim_t *s); /* the caller leaves the lockstep: the plant sleeps */
int plant_thread_sleeps_now(utrf_sim_t *s); /* the plant's thread sleeps at once: a client beside */
long plant_thread_step_ns(utrf_sim_t *s); /* the plant thread's last step, ns (0: none yet) */

/* run_ahead.c: the lockstep's marks and its waiting write; mark returns 0 when full */
int ahead_mark(utrf_sim_t *s);
void ahead_send_due(utrf_sim_t *s);
void ahead_close(utrf_sim_t *s);

/* beats.c: each captured byte; each period's end; before a stretch of a run ahead to
 * `target` (-1: the run ends here, the rule frozen or out of heartbeats) and after it */
void beats_byte(utrf_sim_t *s, uint8_t b);
void beats_period_end(utrf_sim_t *s);
int beats_arm(utrf_sim_t *s, uint64_t target);
void beats_stretch_end(utrf_sim_t *s);

/* uart_bridge.c */
void bridge_init(utrf_sim_t *s);
void bridge_after_reset(utrf_sim_t *s);
void bridge_sync_baud(utrf_sim_t *s);
void bridge_rx_kick(utrf_sim_t *s);
void bridge_deliver(utrf_sim_t *s);
size_t bridge_rx_push(utrf_sim_t *s, const uint8_t *buf, size_t n);
size_t bridge_rx_space(const utrf_sim_t *s);
void bridge_to_host(utrf_sim_t *s, const uint8_t *buf, size_t n); /* after line faults */
double bridge_random(utrf_sim_t *s);

/* serve.c */
void serve_init(utrf_sim_t *s);
void serve_poll(utrf_sim_t *s, int timeout_ms);
void serve_close(utrf_sim_t *s);
void serve_write(utrf_sim_t *s, const uint8_t *buf, size_t n);

/* board_io.c */
void board_io_read_pins(utrf_sim_t *s);
void board_io_init(utrf_sim_t *s);
uint64_t board_io_uart0_frame_cycles(const avr_t *avr, int *rx_enabled);
void board_io_apply_reset_flag(avr_t *avr, int cause);
uint8_t board_io_mcusr(const avr_t *avr);
int board_io_is_watchdog_reset(uint8_t mcusr);
uint16_t board_io_eecr(void);
uint8_t board_io_eempe_mask(void);
uint8_t board_io_eepe_mask(void);
uint32_t board_io_sram_start(void);

/* interrupts.c */
void interrupts_init(utrf_sim_t *s);

/* timers.c */
void timers_init(utrf_sim_t *s);
void timers_quiet(utrf_sim_t *s);

/* profile.c */
void profile_init(utrf_sim_t *s);
void profile_after_reset(utrf_sim_t *s);
void profile_step_functions(utrf_sim_t *s);
void profile_step_histogram(utrf_sim_t *s, uint32_t pc0, uint64_t c0, int own0);
int profile_in_own_work(const utrf_sim_t *s);
void profile_close(utrf_sim_t *s);

/* harness.c */
void harness_log(utrf_sim_t *s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

#endif /* UTRF_HARNESS_INTERNAL_H */
