/* The UTRF emulated board: the real firmware ELF on simavr (ATmega2560 at 16 MHz).
 *
 * A shared library (build/emulator/libutrf_sim.so) driven from Python through ctypes
 * (utrf/emulator/_native.py mirrors every declaration here; bump UTRF_SIM_ABI when one
 * changes). The caller owns the clock: utrf_sim_run_to() runs the MCU up to a cycle and
 * returns, so the plant model can exchange pins and ADC values with it in lockstep.
 *
 * Threading: one utrf_sim_t must not be used from two threads at once; the Python wrapper
 * holds a lock around every call. With utrf_sim_set_plant_threads(s, 2) the lockstep steps
 * the plant on a thread of its own, inside the call.
 */
#ifndef UTRF_SIM_H
#define UTRF_SIM_H

#include <stddef.h>
#include <stdint.h>

#define UTRF_SIM_ABI 20

#define UTRF_SIM_ADC_CHANNELS 8 /* ADC0..7: simavr 1.6 takes external values on these */
/* Pin block: per finger (5), per channel (0 = motor A, 1 = motor B), 4 doubles:
 * PWM duty at the TB6612's PWM input (0..1), IN1 level, IN2 level, STBY level (0 or 1). */
#define UTRF_SIM_PIN_FIELDS 4
#define UTRF_SIM_PIN_VALUES (5 * 2 * UTRF_SIM_PIN_FIELDS)

enum utrf_sim_status {
    UTRF_SIM_RUNNING = 0, /* the MCU runs (or sleeps, waiting for an interrupt) */
    UTRF_SIM_CRASHED = 1, /* simavr stopped the core (bad opcode or address); reset to recover */
    UTRF_SIM_DONE = 2,    /* the program slept with interrupts off: it has ended */
};

enum utrf_sim_reset_cause {
    UTRF_SIM_RESET_POWER_ON = 0, /* PORF; SRAM cleared */
    UTRF_SIM_RESET_PIN = 1,      /* EXTRF: the reset pin (the USB-serial auto-reset) */
};

enum utrf_sim_dir {
    UTRF_SIM_TO_BOARD = 0, /* host -> UART0 RX */
    UTRF_SIM_TO_HOST = 1,  /* UART0 TX -> host */
};

/* Counters since utrf_sim_open. All uint64_t so ctypes mirrors them as one array. */
typedef struct {
    uint64_t rx_host_bytes;     /* bytes accepted from the host (pty, TCP, in-process) */
    uint64_t rx_uart_bytes;     /* bytes delivered into the UART's receiver */
    uint64_t rx_lost_disabled;  /* bytes that arrived while the receiver was off (boot, reset) */
    uint64_t rx_dropped;        /* line faults: bytes dropped on the way to the board */
    uint64_t rx_corrupted;      /* line faults: bytes with a flipped bit */
    uint64_t rx_inserted;       /* line faults: noise bytes added */
    uint64_t rx_overruns;       /* bytes the chip's receiver lost: its 2-byte FIFO full (DOR0) */
    uint64_t tx_uart_bytes;     /* bytes the firmware sent */
    uint64_t tx_dropped;        /* line faults: bytes dropped on the way to the host */
    uint64_t tx_corrupted;      /* line faults */
    uint64_t tx_inserted;       /* line faults */
    uint64_t tx_unheard;        /* bytes sent while no client listened (or it did not read) */
    uint64_t tx_cut;            /* bytes whose transmission a reset cut short */
    uint64_t resets;            /* resets of any cause after power-on */
    uint64_t watchdog_resets;
    uint64_t last_reset_flags;  /* MCUSR as the firmware finds it after the last reset */
    uint64_t clients;           /* client connections (pty opens and TCP accepts) */
    uint64_t eeprom_writes;     /* EEPROM byte program operations */
    uint64_t frame_cycles;      /* UART0 frame time in CPU cycles at its configured baud */
    uint64_t adc_conversions;   /* conversions started */
    uint64_t late_interrupts;   /* interrupts raised when enabled with their flag already set */
    uint64_t rx_duplicated;     /* line faults: bytes sent twice */
    uint64_t rx_burst_bytes;    /* line faults: bytes garbled by bursts */
    uint64_t tx_duplicated;
    uint64_t tx_burst_bytes;
    uint64_t stalls;            /* stalled entries of the stalled vector (utrf_sim_stall_vector) */
    uint64_t sleep_cycles;      /* cycles the CPU slept (SLEEP; simavr skips them) */
    uint64_t quieted_timer_events; /* PWM timer events left out (timers.c) */
    uint64_t rx_frame_errors;   /* bytes received with a damaged stop bit (FE0): line noise */
} utrf_sim_stats_t;

/* The receive path's timing since the last clear: each byte from the end of its stop bit to
 * the firmware's read of UDR0 (uart_bridge.c). */
typedef struct {
    uint64_t reads;        /* bytes read from UDR0 */
    uint64_t total;        /* their waits, summed (cycles) */
    uint64_t worst;        /* the longest wait (cycles) */
    uint64_t worst_at;     /* the cycle of that read */
    uint64_t late;         /* reads more than one frame after their byte's arrival */
    uint64_t overruns;     /* bytes lost (DOR0) */
    uint64_t frame_errors; /* bytes received with FE0 */
} utrf_sim_rx_timing_t;

/* Cycle profile of one interrupt vector or one function. */
typedef struct {
    uint64_t count;       /* completed calls */
    uint64_t total;       /* cycles, exclusive of nested interrupts */
    uint64_t worst;       /* longest call, exclusive */
    uint64_t best;        /* shortest call, exclusive */
    uint64_t total_incl;  /* cycles including nested interrupts */
    uint64_t worst_incl;
    uint64_t last_entry;  /* cycle of the last entry */
    uint64_t period_sum;  /* sum of entry-to-entry intervals */
    uint64_t intervals;   /* how many intervals period_sum holds */
    uint64_t latency_sum; /* vector: cycles from its flag being raised to its entry */
    uint64_t latency_worst;
    uint64_t nested;          /* interrupts that nested in the calls (directly) */
    uint64_t nested_worst;    /* the most cycles of nested interrupts in one call */
    uint64_t period_worst;    /* the longest entry-to-entry interval */
    uint64_t period_worst_at; /* the entry that began it (cycle) */
} utrf_sim_profile_t;

typedef struct utrf_sim utrf_sim_t;

int utrf_sim_abi(void);

/* Load an AVR ELF as an atmega2560 at 16 MHz with AVcc = AREF = 5 V. seed drives the line
 * fault generator. NULL on failure, with a message in err. */
utrf_sim_t *utrf_sim_open(const char *elf_path, uint64_t seed, char *err, size_t errlen);
void utrf_sim_close(utrf_sim_t *s);

/* Run the MCU until avr->cycle >= target (a few cycles past, at an instruction boundary).
 * Before running: serve the host side (accept, read input, detect clients) and apply the ADC
 * inputs; after: refresh the pin block and deliver the output bytes that are due. */
int utrf_sim_run_to(utrf_sim_t *s, uint64_t target);
uint64_t utrf_sim_cycle(const utrf_sim_t *s);
int utrf_sim_status(const utrf_sim_t *s);
uint32_t utrf_sim_pc(const utrf_sim_t *s);
/* Move the CPU to a flash byte address at the instruction boundary where it stands, as a
 * runaway firmware would; interrupts: 1 sets SREG's I flag, 0 clears it, -1 leaves it.
 * Hanging the firmware in a self-loop this way is how the watchdog is proven. -1 when addr
 * is odd or past the flash. */
int utrf_sim_jump(utrf_sim_t *s, uint32_t addr, int interrupts);
/* The same jump, made when the PC next reaches the byte address at (an instruction
 * boundary in the code that runs there, e.g. a function's entry); a reset cancels it. */
int utrf_sim_jump_at(utrf_sim_t *s, uint32_t at, uint32_t addr, int interrupts);
/* The program word at a flash byte address; -1 past the flash. */
int32_t utrf_sim_flash_word(const utrf_sim_t *s, uint32_t addr);

/* The voltages on ADC0..7 (UTRF_SIM_ADC_CHANNELS doubles, in volts). Each conversion samples
 * its channel when it starts, and gives the datasheet's ideal converter's code,
 * floor(1024 V / Vref + 1/2) within 0..1023 (board_io.c). */
double *utrf_sim_adc_volts(utrf_sim_t *s);
/* The pin block (UTRF_SIM_PIN_VALUES doubles), refreshed after each run. */
const double *utrf_sim_pins(utrf_sim_t *s);
void utrf_sim_refresh_pins(utrf_sim_t *s);

/* The driver pins as registers, per board_pins.h: per motor the PWM timer's compare output
 * mode of its channel (COMnX), OCRnX, ICRn, the waveform mode (WGM), the clock select, the
 * IN1, IN2 and PWM pins' levels, and whether all three are outputs; per finger STBY's level
 * and whether it is an output. For checks of the firmware against the pin map. */
typedef struct {
    uint32_t com, ocr, icr, wgm, cs, in1, in2, pwm_pin, outputs;
} utrf_sim_motor_regs_t;
typedef struct {
    utrf_sim_motor_regs_t motor[2];
    uint32_t stby, stby_out;
} utrf_sim_finger_regs_t;
void utrf_sim_pin_registers(const utrf_sim_t *s, utrf_sim_finger_regs_t *out5);

/* Data-space access (registers and SRAM), for tests and diagnostics. */
int utrf_sim_read_data(const utrf_sim_t *s, uint32_t addr, uint8_t *buf, size_t n);
/* Address of an ELF symbol (data symbols carry avr-gcc's 0x800000 offset); -1 if absent. */
int64_t utrf_sim_symbol(const utrf_sim_t *s, const char *name);

/* UART0, in-process side. Bytes written start on the wire at the present cycle, one frame
 * time apart; returns how many were accepted (the queue holds 64 KiB). Capture keeps the
 * output for utrf_sim_uart_read (off by default: output goes to the pty/TCP clients). */
size_t utrf_sim_uart_write(utrf_sim_t *s, const uint8_t *buf, size_t n);
size_t utrf_sim_uart_read(utrf_sim_t *s, uint8_t *buf, size_t n);
size_t utrf_sim_uart_pending(const utrf_sim_t *s); /* host bytes not yet on the UART */
void utrf_sim_set_capture(utrf_sim_t *s, int on);
/* With capture on, the wire times of each captured 0x00 (a protocol frame's end), in the
 * order captured: when the first byte after the previous 0x00 started on the line (its start
 * bit) and when this 0x00's stop bit ended. The log keeps the last UTRF_SIM_FRAME_LOG. */
#define UTRF_SIM_FRAME_LOG 4096
size_t utrf_sim_uart_frames(utrf_sim_t *s, uint64_t *starts, uint64_t *ends, size_t n);

/* Serving: a pty (path returned) and a TCP listener on host:port (port 0: any free one;
 * returns the port, or -errno). One TCP client at a time; a second one is closed at once.
 * With auto_reset, a client opening the pty or connecting resets the board (EXTRF), as
 * the MEGA's USB-serial chip does through DTR. */
int utrf_sim_serve_pty(utrf_sim_t *s, char *path, size_t len);
int utrf_sim_serve_tcp(utrf_sim_t *s, const char *host, int port);
void utrf_sim_set_auto_reset(utrf_sim_t *s, int on);
int utrf_sim_clients(const utrf_sim_t *s); /* bit 0: pty open, bit 1: TCP connected */
/* Hang up on the TCP client, as a pulled cable would (it reads end-of-file). */
void utrf_sim_drop_client(utrf_sim_t *s);

/* Line faults per direction, as probabilities per byte: drop it, flip one random bit of it,
 * insert one random byte before it, send it twice, or start a burst of noise there that
 * replaces it and the bytes after it, burst_min..burst_max bytes in all (uniform). */
typedef struct {
    double drop, corrupt, insert, duplicate, burst;
    uint32_t burst_min, burst_max;
} utrf_sim_line_faults_t;
int utrf_sim_set_line_faults(utrf_sim_t *s, int dir, const utrf_sim_line_faults_t *f);
/* Put raw bytes on the line now (noise bursts); to the board they queue behind host bytes. */
size_t utrf_sim_inject(utrf_sim_t *s, int dir, const uint8_t *buf, size_t n);

/* Reset the board; with hold_cycles > 0 it stays in reset that long (its pins float, nothing
 * runs) before the firmware starts. */
void utrf_sim_reset(utrf_sim_t *s, int cause, uint64_t hold_cycles);
/* How long a client's connection holds the board in reset (with auto-reset), in cycles. */
void utrf_sim_set_auto_reset_hold(utrf_sim_t *s, uint64_t hold_cycles);

/* The 4 KiB EEPROM. */
size_t utrf_sim_eeprom_size(const utrf_sim_t *s);
int utrf_sim_eeprom_get(utrf_sim_t *s, uint8_t *buf, size_t n);
int utrf_sim_eeprom_set(utrf_sim_t *s, const uint8_t *buf, size_t n);

void utrf_sim_stats(const utrf_sim_t *s, utrf_sim_stats_t *out);
/* The receive path's timing into out (NULL: none); clear != 0 starts it again. */
void utrf_sim_rx_timing(utrf_sim_t *s, utrf_sim_rx_timing_t *out, int clear);

/* Cycle profiling: of an interrupt vector (its entry to its RETI), or of a function from its
 * first instruction to its return (address in bytes, e.g. from utrf_sim_symbol). One vector
 * and UTRF_SIM_FUNCTION_PROFILES functions (slots) at a time; 0 (vector) or -1 (function)
 * turns one off. utrf_sim_profile_function is slot 0. Setting one restarts its figures. */
#define UTRF_SIM_FUNCTION_PROFILES 3
int utrf_sim_profile_vector(utrf_sim_t *s, int vector);
int utrf_sim_profile_function(utrf_sim_t *s, int64_t addr);
int utrf_sim_profile_function_slot(utrf_sim_t *s, int slot, int64_t addr);
/* which: 0 the vector, 1 + k function slot k. */
void utrf_sim_profile_get(const utrf_sim_t *s, int which, utrf_sim_profile_t *out);
/* The vector's calls count only when function slot `slot` was entered within them (a timer
 * interrupt that ran the tick, not one that deferred it); -1: every call. */
int utrf_sim_profile_vector_requires(utrf_sim_t *s, int slot);
/* Where the cycles go: per program address (byte address / 2), the cycles of the
 * instructions executed there, counted from now on, of every instruction (slot -1) or only of
 * function slot `slot`'s own work (its calls, less the interrupts nested in them). A sleeping
 * CPU's skipped cycles count at the instruction after its SLEEP. slot < -1 stops and frees it.
 * utrf_sim_pc_histogram_get copies up to n counts (address 0 first) and returns how many
 * there are (0: off). */
int utrf_sim_pc_histogram(utrf_sim_t *s, int slot);
size_t utrf_sim_pc_histogram_get(const utrf_sim_t *s, uint64_t *out, size_t n);
/* Every profile's figures back to zero; calls under way, and the last entry that the next
 * interval is measured from, are kept (a measurement window opened mid-run). */
void utrf_sim_profile_clear(utrf_sim_t *s);

/* Quiet PWM timers (timers.c, on by default): the events of a 16-bit timer whose interrupts
 * are all off and whose TCNT the firmware never read are cancelled before each run (its
 * flags stay clear; its registers, and the duty, are untouched). */
void utrf_sim_set_quiet_timers(utrf_sim_t *s, int on);

/* Faults of the board (faults.c), for the safety tests. A stalled vector: at each of the
 * next `count` entries of the interrupt (-1: every entry; 0 or vector 0: none) the clock
 * jumps `cycles` ahead, as if its handler ran that much longer (the timers run on). */
int utrf_sim_stall_vector(utrf_sim_t *s, int vector, uint64_t cycles, int64_t count);
int64_t utrf_sim_stalls_left(const utrf_sim_t *s);
/* Write an I/O register as the CPU would (simavr's module for it reacts: a timer's clock
 * select stops the timer); -1 outside the data space. */
int utrf_sim_write_io(utrf_sim_t *s, uint32_t addr, uint8_t value);
/* Write a byte of the data space behind every module's back (no module reacts). */
int utrf_sim_poke(utrf_sim_t *s, uint32_t addr, uint8_t value);

/* ---- Lockstep with the plant (lockstep.c) ------------------------------------------------- */
/* Run in lockstep with the plant up to `target`, one exchange every `period` cycles of the
 * plant's clock: the MCU runs each period with the encoders as the plant had them at its
 * start, and the plant steps the same period with the pins as they were at its start. The
 * plant steps exact periods (the last one up to `target`); the MCU's few cycles past a
 * period's end are carried into its next. Returns the status; stops early after a period in
 * which it changed. */
int utrf_sim_run_plant(utrf_sim_t *s, uint64_t target, uint64_t period);
/* The same, and it also stops after the period in which the captured output (capture on) got
 * the byte `wake` (0..255; 0 ends every protocol frame; -1: never): a driven client looks at
 * the output when a frame has come, not every period. */
int utrf_sim_run_plant_until(utrf_sim_t *s, uint64_t target, uint64_t period, int wake);
/* The plant's clock (cycle): the next exchange period starts there (at most a few cycles
 * behind the MCU's; when the MCU ran alone since, utrf_sim_run_to, from where it is). */
uint64_t utrf_sim_plant_cycle(utrf_sim_t *s);
/* 1: the plant steps on the caller's thread after the MCU's period; 2: on a thread of its
 * own while the MCU runs the period (the same results). 0, or -1 for another count, -2 when
 * the thread cannot start. */
int utrf_sim_set_plant_threads(utrf_sim_t *s, int threads);
int utrf_sim_plant_threads(const utrf_sim_t *s);
/* With two: 1 (the default) lets the plant's thread spin a while for the MCU's next period
 * before it sleeps; 0 makes it sleep at once (cores too few for it to spin beside the MCU
 * and a client: utrf.emulator.twin_threads chooses). The results are the same either way. */
int utrf_sim_set_plant_spin(utrf_sim_t *s, int spin);
/* With two: the periods the MCU's thread stepped the plant itself, the hand-over costing it
 * more than the step (lockstep.c) */
uint64_t utrf_sim_plant_inline_periods(const utrf_sim_t *s);
/* With two: how long (ns, the monotonic clock) the MCU's thread waited for the plant's at the
 * hand-overs, its period run (the stall the second thread costs it) */
uint64_t utrf_sim_plant_wait_ns(const utrf_sim_t *s);

/* ---- Running ahead of the caller (run_ahead.c) ---------------------------------------------
 * utrf_sim_run_plant_until(s, target, period, wake) on a thread of its own: the call returns
 * at once and the caller may work (on anything but `s`) until utrf_sim_ahead_join(s), which
 * waits and returns the run's status. Each period in which the captured output got `wake` is
 * marked instead of ending the run (up to UTRF_SIM_MARKS: then it ends there, short of
 * `target`); utrf_sim_ahead_marks gives them after the join: the capture's bytes up to each
 * (counted from what utrf_sim_uart_read has not read yet) and the MCU's cycle at that period's
 * end, where a client stopping at every frame would have looked. With utrf_sim_ahead_send,
 * `n` bytes are written to UART0 at the first period's end (or the run's start) whose MCU
 * time in s ((double)cycle / 16e6) reaches `at`: a heartbeat at its time; its cycle is kept
 * for utrf_sim_ahead_sent. Returns 0, or -1 when a run is under way or the thread cannot
 * start (the run then does not happen). */
#define UTRF_SIM_MARKS 256
#define UTRF_SIM_SEND_MAX 64
int utrf_sim_ahead_start(utrf_sim_t *s, uint64_t target, uint64_t period, int wake);
int utrf_sim_ahead_join(utrf_sim_t *s);
int utrf_sim_ahead_running(const utrf_sim_t *s);
size_t utrf_sim_ahead_marks(const utrf_sim_t *s, uint64_t *bytes, uint64_t *cycles, size_t n);
int utrf_sim_ahead_send(utrf_sim_t *s, const uint8_t *buf, size_t n, double at);
/* the cycle the waiting bytes went at (0: not yet), and how many the UART's queue took */
uint64_t utrf_sim_ahead_sent(const utrf_sim_t *s, size_t *taken);

/* Stops within the next run ahead (a client's samples taken in batches): the run passes
 * through each of `n` targets (rising plant cycles, the last the run's own target), each as
 * a run ahead to it would end there, and at each it applies the hits due and records the
 * MCU's cycle and the plant's truth, then runs on: the same run, to the cycle, as one run
 * ahead per stop with the caller reading the truth and hitting the plant between them. A hit
 * is due at the first stop whose MCU time from t0, (double)cycle / 16e6 - t0, reaches its
 * `at` (the hits in rising `at`). The stops hold until the next utrf_sim_ahead_start; -1
 * when too many or a run is under way. */
#define UTRF_SIM_STOPS 64
#define UTRF_SIM_HITS 16
#define UTRF_SIM_TRUTH 32 /* doubles a stop records: the plant's (utrf_mjplant_truth_sites) */
typedef struct {
    double at;
    int32_t body, site; /* the plant's (MuJoCo's ids; site -1: the body's centre of mass) */
    double impulse[3];  /* N s, world frame */
    double duration;    /* s */
} utrf_sim_hit_t;
int utrf_sim_ahead_stops(utrf_sim_t *s, const uint64_t *targets, size_t n, double t0,
                         const utrf_sim_hit_t *hits, size_t nhits);
/* After the join: how many stops the run reached (a crash or the marks full end it short),
 * their MCU cycles and truths (n x UTRF_SIM_TRUTH), and per hit the stop it was applied at
 * (-1: not yet). */
size_t utrf_sim_ahead_stops_done(const utrf_sim_t *s, uint64_t *cycles, double *truth,
                                 int32_t *hit_stop, size_t n);

/* Heartbeats within the next run ahead with stops (beats.c): the client's rule kept by the
 * harness. The next falls due at `due` (s), and a `period` after each one sent or each
 * awaited ack heard (at its period's end), whichever is later; before each stretch to a stop
 * whose target ((double)target / 16e6) it reaches, the next of the `n` frames
 * (UTRF_SIM_BEAT_BYTES apart, `lens` long, their `seqs`) waits for it, as
 * utrf_sim_ahead_send. An ack is a frame of kind 2 (`kinds`, per message id: 1 the stream,
 * with the board's seq flag, 2 an ack) whose seq is in `acks` (a bit a seq) or was sent
 * since; any frame neither the stream nor such an ack (a boot, a damaged frame) ends the run
 * at the next stop, as does a heartbeat due with none left. -1: too many, or a run on. */
#define UTRF_SIM_BEATS 16
#define UTRF_SIM_BEAT_BYTES 16
int utrf_sim_ahead_beats(utrf_sim_t *s, const uint8_t *frames, const uint8_t *lens,
                         const uint8_t *seqs, size_t n, double due, double period,
                         const uint8_t *acks, const uint8_t *kinds);
/* After the join: the heartbeats sent, their cycles and the due times they went for. */
size_t utrf_sim_ahead_beats_done(const utrf_sim_t *s, uint64_t *cycles, double *dues, size_t n);
/* After the join: where the rule stands (the next heartbeat's due time, the seqs whose acks
 * still count, a bit each), for the next batch to start before the client takes this one's
 * frames; -1 when it cannot be carried on (heartbeats off, or the rule frozen). */
int utrf_sim_ahead_beats_next(const utrf_sim_t *s, double *due, uint8_t *acks);

/* ---- The MuJoCo plant (mjplant.c) ----------------------------------------------------------
 * The MuJoCo hand (utrf.models.mjcf, drive "force") stepped here; its mjModel and mjData
 * belong to the caller (the mujoco package) and stay live there. Indices are MuJoCo's. */
#define UTRF_PLANT_FINGERS 5
#define UTRF_MJPLANT_LOADS 16

typedef struct {
    int32_t actuator[5][2]; /* actuator id of motor A, B (-1: none, e.g. a rotary finger's B) */
    int32_t dof[5][2];      /* its joint's qvel index */
    double gear[5][2];      /* pulling speed (m/s) per unit of that qvel */
    int32_t j2_qpos[5];     /* Joint 2's qpos index */
    double supply_v, force_constant, resistance, electrical_time_constant, stall_force;
    double enc_supply, enc_offset, enc_band[2], enc_noise_v, enc_unplugged_v;
    int32_t enc_invert, enc_bits;
} utrf_mjplant_params_t;

typedef struct {
    double time;
    double current[5][2], drive_mode[5][2], drive_duty[5][2];
    double plugged[5], unplugged_v[5], encoder_shift[5];
    /* steady loads: a world-frame force (N) on a body at a site (-1: at its centre of mass);
     * body -1: the slot is free */
    double load_body[UTRF_MJPLANT_LOADS], load_site[UTRF_MJPLANT_LOADS];
    double load_force[UTRF_MJPLANT_LOADS][3];
    /* a ramp: the force goes linearly from load_from at time load_t0 to load_force at load_t1
     * (load_t1 <= load_t0: load_force at once) */
    double load_from[UTRF_MJPLANT_LOADS][3];
    double load_t0[UTRF_MJPLANT_LOADS], load_t1[UTRF_MJPLANT_LOADS];
    /* build faults (utrf.emulator.build_faults), where the physical fault is: finger f's
     * motors are wired to the driver of finger build_motor_from[f]; each motor's lead
     * polarity (+1, -1: swapped leads), supply (0: unpowered) and force constant and
     * resistance scales (weaker, slower); ADC channel f reads the encoder of finger
     * build_encoder_from[f], its magnet inverted (1), turned by build_encoder_offset rad, off
     * centre by build_encoder_eccentric rad (a once-per-turn error of that amplitude) */
    double build_motor_from[5], build_lead[5][2], build_powered[5][2];
    double build_k_scale[5][2], build_r_scale[5][2];
    double build_encoder_from[5], build_encoder_invert[5], build_encoder_offset[5];
    double build_encoder_eccentric[5];
} utrf_mjplant_state_t;

typedef struct utrf_mjplant utrf_mjplant_t;

/* libmujoco: the path of the library the mujoco package loaded; model, data: the addresses of
 * its MjModel and MjData (kept alive by the caller). NULL with a message in err. */
utrf_mjplant_t *utrf_mjplant_new(const char *libmujoco, void *model, void *data,
                                 const utrf_mjplant_params_t *params, uint64_t seed, char *err,
                                 size_t errlen);
void utrf_mjplant_free(utrf_mjplant_t *mp);
utrf_mjplant_state_t *utrf_mjplant_state(utrf_mjplant_t *mp);
void utrf_mjplant_step(utrf_mjplant_t *mp, double dt, const double *pins);
void utrf_mjplant_encoder_volts(utrf_mjplant_t *mp, double *out5);
/* A hammer hit: a world-frame force pulse carrying (jx, jy, jz) N s on a body at a site (-1:
 * its centre of mass) over duration s from now. -2: too many under way. */
int utrf_mjplant_hit(utrf_mjplant_t *mp, int body, int site, double jx, double jy, double jz,
                     double duration);
int utrf_mjplant_pulses(const utrf_mjplant_t *mp);
/* What a stop of a run ahead records of the plant (UTRF_SIM_TRUTH doubles): the world
 * positions of up to 5 sites (these, -1: none; 15 doubles, zeros for none), then the motors'
 * currents (10, A). */
int utrf_mjplant_truth_sites(utrf_mjplant_t *mp, const int32_t *sites, int n);
/* The board's plant (NULL: none; the ADC inputs and pins are then the caller's). The board
 * does not own it: free it after the board. */
void utrf_sim_attach_mjplant(utrf_sim_t *s, utrf_mjplant_t *mp);

/* The last messages simavr logged for this board (errors and warnings), NUL-terminated. */
size_t utrf_sim_log(const utrf_sim_t *s, char *buf, size_t n);

#endif /* UTRF_SIM_H */
