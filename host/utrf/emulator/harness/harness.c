/* The emulated board's core: load the ELF, run in lockstep, resets, EEPROM, simavr's log.
 *
 * The MCU is simavr's atmega2560 at 16 MHz with AVcc = AREF = 5 V, running the ELF as it
 * would run from flash after the bootloader (the bootloader itself is not simulated). Time is
 * the CPU cycle count: nothing here reads the wall clock, so a run is reproducible.
 */
#define _GNU_SOURCE
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "avr_adc.h"
#include "avr_eeprom.h"
#include "avr_extint.h"
#include "sim_core.h"
#include "harness_internal.h"

#define F_CPU_HZ 16000000u
#define SUPPLY_MV 5000u
#define EEPROM_PROGRAM_US 3400u /* ATmega2560 datasheet: 3.4 ms per byte */

/* ---- simavr's logger: errors and warnings go to the board they concern ---------------- */

#define MAX_BOARDS 64
static pthread_mutex_t g_boards_lock = PTHREAD_MUTEX_INITIALIZER;
static utrf_sim_t *g_boards[MAX_BOARDS];
static __thread char t_load_log[512]; /* messages logged with no board, e.g. while loading */

static void append(char *buf, size_t size, size_t *len, const char *text)
{
    size_t n = strlen(text);
    if (n >= size)
        return;
    if (*len + n >= size) { /* keep the most recent messages */
        size_t drop = *len + n - size + 1;
        memmove(buf, buf + drop, *len - drop);
        *len -= drop;
    }
    memcpy(buf + *len, text, n);
    *len += n;
    buf[*len] = 0;
}

static void logger(avr_t *avr, const int level, const char *format, va_list ap)
{
    if (level > LOG_WARNING)
        return;
    char line[256];
    vsnprintf(line, sizeof line, format, ap);
    if (!avr) {
        size_t len = strlen(t_load_log);
        append(t_load_log, sizeof t_load_log, &len, line);
        return;
    }
    pthread_mutex_lock(&g_boards_lock);
    for (int i = 0; i < MAX_BOARDS; i++) {
        if (g_boards[i] && g_boards[i]->avr == avr) {
            append(g_boards[i]->log, LOG_SIZE, &g_boards[i]->log_len, line);
            break;
        }
    }
    pthread_mutex_unlock(&g_boards_lock);
}

void harness_log(utrf_sim_t *s, const char *fmt, ...)
{
    char line[256];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(line, sizeof line, fmt, ap);
    va_end(ap);
    append(s->log, LOG_SIZE, &s->log_len, line);
}

static void install_logger(void)
{
    avr_global_logger_set(logger);
}

static void register_board(utrf_sim_t *s, int add)
{
    pthread_mutex_lock(&g_boards_lock);
    for (int i = 0; i < MAX_BOARDS; i++) {
        if (add && !g_boards[i]) {
            g_boards[i] = s;
            break;
        }
        if (!add && g_boards[i] == s) {
            g_boards[i] = NULL;
            break;
        }
    }
    pthread_mutex_unlock(&g_boards_lock);
}

/* ---- lockstep ---------------------------------------------------------------------------- */

static avr_cycle_count_t stop_timer(avr_t *avr, avr_cycle_count_t when, void *param)
{
    (void)avr;
    (void)when;
    ((utrf_sim_t *)param)->stop = 1;
    return 0;
}

/* Idle sleep: simavr's default sleeps the thread to follow the wall clock; pacing is ours.
 * simavr skips the slept cycles (to one past its next timer event); count them. When the run's
 * end is the event (stop_timer ran in this pass), simavr would still skip on to the event
 * after it: a run ended up to a whole tick late (a stop at a sleeping CPU's next wake-up), and
 * a watchdog reset due meanwhile cleared the end's timer (the run went on for ever). So the
 * skip stops at the end: the clock is set back by what simavr is about to add. */
static void no_sleep(avr_t *avr, avr_cycle_count_t how_long)
{
    utrf_sim_t *s = avr->custom.data;
    if (!s)
        return;
    if (s->in_run && s->stop) {
        avr->cycle -= how_long;
        how_long = 0;
    }
    s->stats.sleep_cycles += 1 + how_long;
}

static int status_of(const avr_t *avr)
{
    switch (avr->state) {
    case cpu_Crashed:
    case cpu_Stopped:
        return UTRF_SIM_CRASHED;
    case cpu_Done:
        return UTRF_SIM_DONE;
    default:
        return UTRF_SIM_RUNNING;
    }
}

/* simavr 1.6 goes back through avr_run, its cycle timers and its interrupt check after every
 * instruction, because avr_cycle_timer_reset sets run_cycle_limit to 1. avr_run_one can run
 * on by itself up to the next cycle timer, while the core runs and no interrupt is pending or
 * waiting (sim_core.c, run_one_again): the same instructions at the same cycles, since the
 * timers' list is the only thing that loop leaves out and it stops at the first due timer
 * (registering one recomputes how far it may go). Measured: 0.144 -> 0.090 s of CPU time per
 * simulated second (five fingers under position control, telemetry at 100 Hz). The harness's
 * own per-instruction work (a function profile, a pending jump) needs one instruction per
 * avr_run, as before. simavr's reset puts the limit back to 1: set again after each. */
#define RUN_CYCLE_LIMIT (16000000ull * 60u)

static void set_run_limit(utrf_sim_t *s)
{
    int per_instruction = s->prof_functions > 0 || s->pc_hist || s->jump_at >= 0;
    s->avr->run_cycle_limit = per_instruction ? 1 : RUN_CYCLE_LIMIT;
    if (per_instruction)
        s->avr->run_cycle_count = 1;
}

int utrf_sim_run_to(utrf_sim_t *s, uint64_t target)
{
    avr_t *avr = s->avr;
    set_run_limit(s);
    serve_poll(s, 0);
    bridge_sync_baud(s);
    if (target > avr->cycle && avr->cycle < s->hold_until) {
        /* held in reset: time passes, nothing runs */
        avr->cycle = target < s->hold_until ? target : s->hold_until;
    }
    timers_quiet(s);
    if (target > avr->cycle) {
        s->target = target;
        s->stop = 0;
        s->in_run = 1;
        avr_cycle_timer_register(avr, target - avr->cycle, stop_timer, s);
        if (s->prof_functions > 0 || s->pc_hist || s->jump_at >= 0) { /* the slow loop */
            while (!s->stop) {
                uint32_t pc0 = avr->pc;
                uint64_t c0 = avr->cycle;
                int own0 = s->pc_hist ? profile_in_own_work(s) : 0;
                int st = avr_run(avr);
                if (st == cpu_Crashed || st == cpu_Done || st == cpu_Stopped)
                    break;
                if (s->pc_hist)
                    profile_step_histogram(s, pc0, c0, own0);
                if (s->prof_functions > 0)
                    profile_step_functions(s);
                if (s->jump_at >= 0 && avr->pc == (uint32_t)s->jump_at) {
                    s->jump_at = -1;
                    utrf_sim_jump(s, s->jump_to, s->jump_interrupts);
                }
            }
        } else {
            while (!s->stop) {
                int st = avr_run(avr);
                if (st == cpu_Crashed || st == cpu_Done || st == cpu_Stopped)
                    break;
            }
        }
        s->in_run = 0;
        avr_cycle_timer_cancel(avr, stop_timer, s);
        if (avr->cycle < target) /* a stopped core: time goes on around it */
            avr->cycle = target;
    }
    board_io_read_pins(s);
    bridge_deliver(s);
    return status_of(avr);
}

uint64_t utrf_sim_cycle(const utrf_sim_t *s)
{
    return s->avr->cycle;
}

int utrf_sim_status(const utrf_sim_t *s)
{
    return status_of(s->avr);
}

uint32_t utrf_sim_pc(const utrf_sim_t *s)
{
    return s->avr->pc;
}

int utrf_sim_jump(utrf_sim_t *s, uint32_t addr, int interrupts)
{
    if ((addr & 1u) != 0 || addr > s->avr->flashend)
        return -1;
    s->avr->pc = addr;
    if (interrupts >= 0)
        avr_sreg_set(s->avr, S_I, interrupts ? 1 : 0); /* keeps simavr's pending state right */
    if (s->avr->state == cpu_Sleeping)
        s->avr->state = cpu_Running;
    return 0;
}

int utrf_sim_jump_at(utrf_sim_t *s, uint32_t at, uint32_t addr, int interrupts)
{
    if ((at & 1u) != 0 || at > s->avr->flashend || (addr & 1u) != 0 || addr > s->avr->flashend)
        return -1;
    s->jump_at = at;
    s->jump_to = addr;
    s->jump_interrupts = interrupts;
    return 0;
}

int32_t utrf_sim_flash_word(const utrf_sim_t *s, uint32_t addr)
{
    if (addr + 1 > s->avr->flashend)
        return -1;
    return s->avr->flash[addr] | (s->avr->flash[addr + 1] << 8);
}

double *utrf_sim_adc_volts(utrf_sim_t *s)
{
    return s->adc_volts;
}

const double *utrf_sim_pins(utrf_sim_t *s)
{
    return s->pins;
}

void utrf_sim_refresh_pins(utrf_sim_t *s)
{
    board_io_read_pins(s);
}

/* ---- resets ----------------------------------------------------------------------------- */

/* simavr 1.6 polls a low INTn pin on every cycle while its sense control is "low level" (the
 * reset default), whether the interrupt is enabled or not. D2 and D3 (INT4, INT5) are PWM
 * outputs on this board, low most of the time: with the polling the driven board ran at
 * 0.59x real time instead of 2.0x (five fingers moving, 500 Hz telemetry; measured by
 * switching this off).
 * Level interrupts then fire on the falling edge only; the firmware uses none. simavr's
 * extint reset turns the polling back on, so this runs after every reset. */
static void no_level_polling(avr_t *avr)
{
    for (uint8_t i = 0; i < EXTINT_COUNT; i++)
        avr_extint_set_strict_lvl_trig(avr, i, 0);
}

static avr_cycle_count_t eepe_clear(avr_t *avr, avr_cycle_count_t when, void *param)
{
    (void)when;
    (void)param;
    avr->data[board_io_eecr()] &= (uint8_t)~board_io_eepe_mask();
    return 0;
}

/* Our module is last in simavr's list, so this runs after every other module's reset (the
 * watchdog's has set WDRF by then). */
static void hook_reset(avr_io_t *io)
{
    utrf_sim_t *s = (utrf_sim_t *)((char *)io - offsetof(utrf_sim_t, hook));
    avr_t *avr = s->avr;
    if (s->pending_cause == UTRF_SIM_RESET_POWER_ON) {
        uint32_t start = board_io_sram_start();
        memset(avr->data + start, 0, avr->ramend + 1 - start);
    }
    board_io_apply_reset_flag(avr, s->pending_cause);
    s->pending_cause = -1;
    uint8_t flags = board_io_mcusr(avr);
    s->stats.resets++;
    if (board_io_is_watchdog_reset(flags))
        s->stats.watchdog_resets++;
    s->stats.last_reset_flags = flags;
    s->eempe_cycle = -1;
    no_level_polling(avr);
    /* simavr's reset cleared every cycle timer, ours included: set again, or, when the run's
     * end has come (a sleeping CPU skips to one cycle past the next event, here the end, and
     * the watchdog's reset, already due, runs before the end's timer), end the run now. */
    if (s->in_run && s->target > avr->cycle)
        avr_cycle_timer_register(avr, s->target - avr->cycle, stop_timer, s);
    else if (s->in_run)
        s->stop = 1;
    bridge_after_reset(s);
    profile_after_reset(s);
    s->jump_at = -1; /* a reset is a new run: a pending jump belonged to the old one */
    set_run_limit(s);
}

void utrf_sim_reset(utrf_sim_t *s, int cause, uint64_t hold_cycles)
{
    s->pending_cause = cause == UTRF_SIM_RESET_POWER_ON ? UTRF_SIM_RESET_POWER_ON
                                                        : UTRF_SIM_RESET_PIN;
    avr_reset(s->avr);
    s->hold_until = s->avr->cycle + hold_cycles;
    board_io_read_pins(s);
}

void utrf_sim_set_auto_reset_hold(utrf_sim_t *s, uint64_t hold_cycles)
{
    s->auto_reset_hold = hold_cycles;
}

/* simavr looks modules up in list order on every ioctl, and every WDR instruction is one:
 * with the watchdog first, a firmware that feeds it often does not pay for the walk. */
static void watchdog_first(utrf_sim_t *s)
{
    avr_io_t **p = &s->avr->io_port;
    while (*p && *p != &s->watchdog->io)
        p = &(*p)->next;
    if (!*p || p == &s->avr->io_port)
        return;
    *p = s->watchdog->io.next;
    s->watchdog->io.next = s->avr->io_port;
    s->avr->io_port = &s->watchdog->io;
}

static void append_hook(utrf_sim_t *s)
{
    static const char *kind = "utrf-harness";
    memset(&s->hook, 0, sizeof s->hook);
    s->hook.kind = kind;
    s->hook.reset = hook_reset;
    s->hook.avr = s->avr;
    avr_io_t **tail = &s->avr->io_port;
    while (*tail)
        tail = &(*tail)->next;
    *tail = &s->hook;
}

/* ---- EEPROM ------------------------------------------------------------------------------ */

/* simavr programs a byte at once and clears EEPE; the chip keeps EEPE set for 3.4 ms, and
 * firmware that waits on it (avr-libc does) must see that. Runs after simavr's own handler. */
static void eecr_write(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param)
{
    utrf_sim_t *s = param;
    uint8_t eempe = board_io_eempe_mask(), eepe = board_io_eepe_mask();
    if ((v & eempe) && !(v & eepe)) {
        s->eempe_cycle = (int64_t)avr->cycle;
        return;
    }
    if ((v & eepe) && s->eempe_cycle >= 0 && avr->cycle - (uint64_t)s->eempe_cycle <= 4) {
        s->eempe_cycle = -1;
        s->stats.eeprom_writes++;
        avr->data[addr] |= eepe;
        avr_cycle_timer_register_usec(avr, EEPROM_PROGRAM_US, eepe_clear, s);
    }
}

size_t utrf_sim_eeprom_size(const utrf_sim_t *s)
{
    return s->avr->e2end + 1;
}

int utrf_sim_eeprom_get(utrf_sim_t *s, uint8_t *buf, size_t n)
{
    if (n > utrf_sim_eeprom_size(s))
        return -1;
    avr_eeprom_desc_t d = {.ee = buf, .offset = 0, .size = (uint32_t)n};
    return avr_ioctl(s->avr, AVR_IOCTL_EEPROM_GET, &d) == -2 ? -1 : 0;
}

int utrf_sim_eeprom_set(utrf_sim_t *s, const uint8_t *buf, size_t n)
{
    if (!n || n > utrf_sim_eeprom_size(s))
        return -1;
    avr_eeprom_desc_t d = {.ee = (uint8_t *)buf, .offset = 0, .size = (uint32_t)n};
    return avr_ioctl(s->avr, AVR_IOCTL_EEPROM_SET, &d) == -2 ? -1 : 0;
}

/* ---- open and close --------------------------------------------------------------------- */

static avr_io_t *find_io(avr_t *avr, const char *kind, char name)
{
    for (avr_io_t *io = avr->io_port; io; io = io->next) {
        if (strcmp(io->kind, kind))
            continue;
        if (!name || ((avr_uart_t *)io)->name == name)
            return io;
    }
    return NULL;
}

static void free_firmware(elf_firmware_t *fw)
{
#if ELF_SYMBOLS
    for (uint32_t i = 0; i < fw->symbolcount; i++)
        free(fw->symbol[i]);
    free(fw->symbol);
#endif
    free(fw->flash);
    free(fw->eeprom);
    free(fw->fuse);
    free(fw->lockbits);
    memset(fw, 0, sizeof *fw);
}

int utrf_sim_abi(void)
{
    return UTRF_SIM_ABI;
}

utrf_sim_t *utrf_sim_open(const char *elf_path, uint64_t seed, char *err, size_t errlen)
{
    static pthread_once_t once = PTHREAD_ONCE_INIT;
    pthread_once(&once, install_logger);
    t_load_log[0] = 0;

    utrf_sim_t *s = calloc(1, sizeof *s);
    if (!s) {
        snprintf(err, errlen, "out of memory");
        return NULL;
    }
    s->capture = malloc(CAPTURE_SIZE);
    if (!s->capture) {
        free(s);
        snprintf(err, errlen, "out of memory");
        return NULL;
    }
    if (elf_read_firmware(elf_path, &s->fw) != 0) {
        snprintf(err, errlen, "simavr could not read %s: %s", elf_path,
                 t_load_log[0] ? t_load_log : "not a readable ELF file");
        free_firmware(&s->fw);
        free(s->capture);
        free(s);
        return NULL;
    }
    s->avr = avr_make_mcu_by_name("atmega2560");
    if (!s->avr) {
        snprintf(err, errlen, "this simavr has no atmega2560 core");
        free_firmware(&s->fw);
        free(s->capture);
        free(s);
        return NULL;
    }
    register_board(s, 1);
    avr_init(s->avr);
    /* simavr 1.6 flags an access past SRAM as a crash, then makes it anyway, past the end of
     * its data buffer (a firmware bug would corrupt our heap): give it all 64 KiB that a
     * 16-bit address can reach. avr_terminate frees it like its own. */
    uint8_t *data = calloc(1, 0x10000);
    if (!data) {
        snprintf(err, errlen, "out of memory");
        register_board(s, 0);
        free(s->avr);
        free_firmware(&s->fw);
        free(s->capture);
        free(s);
        return NULL;
    }
    memcpy(data, s->avr->data, s->avr->ramend + 1);
    free(s->avr->data);
    s->avr->data = data;
    s->fw.frequency = F_CPU_HZ;
    s->fw.vcc = s->fw.avcc = s->fw.aref = SUPPLY_MV;
    avr_load_firmware(s->avr, &s->fw);
    s->avr->frequency = F_CPU_HZ;
    s->avr->vcc = s->avr->avcc = s->avr->aref = SUPPLY_MV;
    s->avr->sleep = no_sleep;
    s->avr->custom.data = s;
    s->avr->log = LOG_WARNING;

    s->uart0 = (avr_uart_t *)find_io(s->avr, "uart", '0');
    s->watchdog = (avr_watchdog_t *)find_io(s->avr, "watchdog", 0);
    s->adc_irq = avr_io_getirq(s->avr, AVR_IOCTL_ADC_GETIRQ, 0);
    if (!s->uart0 || !s->adc_irq) {
        snprintf(err, errlen, "simavr's atmega2560 core lacks UART0 or the ADC");
        utrf_sim_close(s);
        return NULL;
    }
    s->pending_cause = -1;
    s->plant_threads = 1;
    s->plant_spin = 1;
    s->eempe_cycle = -1;
    s->wake_byte = -1;
    s->rng = seed;
    s->auto_reset = 0;
    no_level_polling(s->avr);
    if (s->watchdog)
        watchdog_first(s);
    append_hook(s);
    bridge_init(s);
    serve_init(s);
    profile_init(s);
    s->jump_at = -1;
    board_io_init(s);
    interrupts_init(s);
    timers_init(s);
    s->quiet_timers = 1;
    avr_register_io_write(s->avr, board_io_eecr(), eecr_write, s);
    s->stats.last_reset_flags = board_io_mcusr(s->avr); /* PORF, set by avr_init */
    board_io_read_pins(s);
    return s;
}

void utrf_sim_close(utrf_sim_t *s)
{
    if (!s)
        return;
    ahead_close(s);
    plant_thread_stop(s);
    serve_close(s);
    if (s->avr) {
        /* Our hook is not simavr's to free: unlink it first. */
        avr_io_t **p = &s->avr->io_port;
        while (*p && *p != &s->hook)
            p = &(*p)->next;
        if (*p)
            *p = s->hook.next;
        avr_terminate(s->avr);
        free(s->avr);
    }
    register_board(s, 0);
    profile_close(s);
    free_firmware(&s->fw);
    free(s->capture);
    free(s);
}

/* ---- inspection ------------------------------------------------------------------------- */

int utrf_sim_read_data(const utrf_sim_t *s, uint32_t addr, uint8_t *buf, size_t n)
{
    if (addr > s->avr->ramend || n > (size_t)s->avr->ramend + 1 - addr)
        return -1;
    memcpy(buf, s->avr->data + addr, n);
    return 0;
}

int64_t utrf_sim_symbol(const utrf_sim_t *s, const char *name)
{
#if ELF_SYMBOLS
    for (uint32_t i = 0; i < s->fw.symbolcount; i++)
        if (!strcmp(s->fw.symbol[i]->symbol, name))
            return s->fw.symbol[i]->addr;
#endif
    (void)s;
    (void)name;
    return -1;
}

void utrf_sim_stats(const utrf_sim_t *s, utrf_sim_stats_t *out)
{
    *out = s->stats;
}

size_t utrf_sim_log(const utrf_sim_t *s, char *buf, size_t n)
{
    if (!n)
        return s->log_len;
    size_t len = s->log_len < n - 1 ? s->log_len : n - 1;
    memcpy(buf, s->log + (s->log_len - len), len);
    buf[len] = 0;
    return len;
}
