/* UART0 <-> host bytes, with the wire's timing, the line faults and the chip's receiver.
 *
 * To the board: host bytes wait in a queue; a cycle timer puts one on the wire per frame
 * time at the baud the firmware configured (start + data + parity + stop bits). When its stop
 * bit ends, the byte reaches the ATmega2560's receiver as modelled here (datasheet, "USART:
 * Receive Buffer"): a two-byte receive FIFO (UDR0) behind the shift register. A byte that
 * completes with the FIFO full waits in the shift register; when the next start bit comes and
 * the FIFO is still full, that byte is lost and the next byte into the FIFO carries the
 * data-overrun flag DOR0 (one or more bytes lost between the last one read and this one). A
 * byte whose stop bit the line damaged (a noise byte: a burst, an inserted byte) carries the
 * frame-error flag FE0. simavr's own receive FIFO holds 64 bytes: the bridge feeds it only the
 * bytes the chip's FIFO would hold, with the flags in each entry (FE in simavr's bit, DOR in
 * ours), and shows them in UCSR0A as the chip does, for the byte at the head. Bytes are lost
 * too while the receiver is off (during boot or after a reset). Each byte's wait, from the
 * end of its stop bit to the firmware's read of UDR0, is timed (utrf_sim_rx_timing).
 *
 * To the host: a byte the firmware writes to UDR0 reaches the host when its stop bit ends,
 * never sooner than one frame after the previous one.
 *
 * simavr 1.6 counts a parity bit in every frame whether parity is on or not (11 bits for
 * 8N1), which makes its own transmit pacing 10 % slow; the bridge sets its per-byte time to
 * the frame the registers describe.
 */
#include <string.h>

#include "harness_internal.h"

#define RX_MASK (RX_QUEUE_SIZE - 1)
#define TX_MASK (TX_QUEUE_SIZE - 1)
#define CAP_MASK (CAPTURE_SIZE - 1)

double bridge_random(utrf_sim_t *s)
{
    return utrf_xorshift64s_uniform(&s->rng);
}

static int chance(utrf_sim_t *s, double p)
{
    return p > 0.0 && bridge_random(s) < p;
}

static uint8_t flip_bit(utrf_sim_t *s, uint8_t b)
{
    return (uint8_t)(b ^ (1u << (utrf_xorshift64s(&s->rng) >> 61)));
}

/* A noise byte: random data, and a random stop bit from the same draw (low: a frame error). */
static uint8_t noise_byte(utrf_sim_t *s, int *frame_error)
{
    uint64_t x = utrf_xorshift64s(&s->rng);
    if (frame_error)
        *frame_error = !((x >> 55) & 1);
    return (uint8_t)(x >> 56);
}

/* A burst of noise: starts at a byte with probability f->burst and replaces it and the
 * bytes after it, burst_min..burst_max in all. True when b was replaced. */
static int burst_byte(utrf_sim_t *s, line_faults_t *f, uint8_t *b, int *frame_error)
{
    if (!f->burst_left && chance(s, f->burst)) {
        uint32_t span = f->burst_max - f->burst_min + 1;
        f->burst_left = f->burst_min + (uint32_t)((utrf_xorshift64s(&s->rng) >> 32) % span);
    }
    if (!f->burst_left)
        return 0;
    f->burst_left--;
    *b = noise_byte(s, frame_error);
    return 1;
}

void bridge_sync_baud(utrf_sim_t *s)
{
    uint64_t frame = board_io_uart0_frame_cycles(s->avr, NULL);
    s->frame_cycles = frame;
    s->stats.frame_cycles = frame;
    if (s->uart0 && s->uart0->cycles_per_byte != frame)
        s->uart0->cycles_per_byte = frame;
}

/* ---- the chip's receiver ---------------------------------------------------------------- */
#define CHIP_FIFO 2u             /* UDR0's receive buffer: two bytes */
#define RX_DOR_FLAG 0x4000u      /* a FIFO entry's DOR0 (simavr keeps FE0 in UART_INPUT_FE) */
#define ARR_MASK (UTRF_RX_ARRIVALS - 1)

/* simavr's FIFO, read in place (its accessors are not exported by libsimavr). */
static unsigned chip_fifo_count(const utrf_sim_t *s)
{
    const uart_fifo_t *f = &s->uart0->input;
    return (unsigned)(f->write - f->read) & (uart_fifo_fifo_size - 1);
}

static uint16_t chip_fifo_head(const utrf_sim_t *s)
{
    const uart_fifo_t *f = &s->uart0->input;
    return f->buffer[f->read & (uart_fifo_fifo_size - 1)];
}

/* The arrival times follow simavr's FIFO, which it empties itself when the receiver is
 * turned off or reset: drop the oldest until the two agree. */
static void sync_arrivals(utrf_sim_t *s)
{
    unsigned n = chip_fifo_count(s);
    while (s->rx_arr_head - s->rx_arr_tail > n)
        s->rx_arr_tail++;
}

/* RXC0 is a level on the chip: its interrupt comes again while the FIFO holds a byte. simavr
 * raises it once and re-raises it only a frame later (its pacing timer): request it now. */
static void rxc_request(utrf_sim_t *s)
{
    if (chip_fifo_count(s) && !s->uart0->rxc.pending)
        avr_raise_interrupt(s->avr, &s->uart0->rxc);
}

/* A complete byte into the FIFO, readable at once (simavr would wait another frame). */
static void fifo_put(utrf_sim_t *s, uint16_t v, uint64_t arrival)
{
    avr_t *avr = s->avr;
    avr_uart_t *u = s->uart0;
    sync_arrivals(s);
    if (s->rx_lost_pending) {
        v |= RX_DOR_FLAG;
        s->rx_lost_pending = 0;
    }
    avr_regbit_clear(avr, u->dor); /* simavr refuses input while DOR is set */
    avr_raise_irq(s->uart_irq + UART_IRQ_INPUT, v);
    s->rx_arrival[s->rx_arr_head++ & ARR_MASK] = arrival;
    if (!avr_regbit_get(avr, u->rxc.raised)) {
        u->rxc_raise_time = avr->cycle;
        u->rx_cnt = 0;
    }
    rxc_request(s);
}

/* The next start bit with the FIFO still full: the byte in the shift register is lost. */
static void overrun(utrf_sim_t *s)
{
    s->rx_shift_full = 0;
    s->rx_lost_pending = 1;
    s->stats.rx_overruns++;
    s->rx_timing.overruns++;
}

/* A byte's stop bit ends: into the FIFO, or the shift register while the FIFO is full. */
static void receiver_complete(utrf_sim_t *s, uint16_t v, int rx_enabled)
{
    if (!rx_enabled) {
        s->stats.rx_lost_disabled++;
        s->rx_shift_full = 0;
        s->rx_lost_pending = 0;
        return;
    }
    s->stats.rx_uart_bytes++;
    if (v & UART_INPUT_FE) {
        s->stats.rx_frame_errors++;
        s->rx_timing.frame_errors++;
    }
    if (s->rx_shift_full)
        overrun(s);
    if (chip_fifo_count(s) < CHIP_FIFO) {
        fifo_put(s, v, s->avr->cycle);
    } else {
        s->rx_shift_full = 1;
        s->rx_shift_byte = v;
        s->rx_shift_arrival = s->avr->cycle;
    }
}

/* UDR0 read: simavr takes the FIFO's head; its wait is timed, and a byte waiting in the shift
 * register moves into the room made. */
static uint8_t udr_read(avr_t *avr, avr_io_addr_t addr, void *param)
{
    utrf_sim_t *s = param;
    avr_uart_t *u = s->uart0;
    sync_arrivals(s);
    unsigned before = chip_fifo_count(s);
    u->rx_cnt = 0; /* simavr's guard against reads faster than its own pacing: ours is exact */
    uint8_t v = s->udr_read.c ? s->udr_read.c(avr, addr, s->udr_read.param) : avr->data[addr];
    if (chip_fifo_count(s) < before && s->rx_arr_tail != s->rx_arr_head) {
        uint64_t waited = avr->cycle - s->rx_arrival[s->rx_arr_tail++ & ARR_MASK];
        utrf_sim_rx_timing_t *t = &s->rx_timing;
        t->reads++;
        t->total += waited;
        if (waited > t->worst) {
            t->worst = waited;
            t->worst_at = avr->cycle;
        }
        if (waited > s->frame_cycles)
            t->late++;
    }
    if (s->rx_shift_full && chip_fifo_count(s) < CHIP_FIFO) {
        s->rx_shift_full = 0;
        fifo_put(s, s->rx_shift_byte, s->rx_shift_arrival);
    }
    rxc_request(s);
    return v;
}

/* UCSR0A read: DOR0 as the FIFO's head carries it (simavr sets FE0 the same way). */
static uint8_t ucsra_read(avr_t *avr, avr_io_addr_t addr, void *param)
{
    utrf_sim_t *s = param;
    avr_uart_t *u = s->uart0;
    int dor = chip_fifo_count(s) && (chip_fifo_head(s) & RX_DOR_FLAG);
    avr_regbit_setto(avr, u->dor, (uint8_t)(dor != 0));
    return s->ucsra_read.c ? s->ucsra_read.c(avr, addr, s->ucsra_read.param) : avr->data[addr];
}

static void hook_read(avr_t *avr, uint16_t reg, io_read_hook_t *orig, avr_io_read_t fn,
                      utrf_sim_t *s)
{
    avr_io_addr_t io = AVR_DATA_TO_IO(reg);
    *orig = (io_read_hook_t){avr->io[io].r.c, avr->io[io].r.param};
    avr->io[io].r.c = fn;
    avr->io[io].r.param = s;
}

void utrf_sim_rx_timing(utrf_sim_t *s, utrf_sim_rx_timing_t *out, int clear)
{
    if (out)
        *out = s->rx_timing;
    if (clear)
        memset(&s->rx_timing, 0, sizeof s->rx_timing);
}

/* ---- the wire ------------------------------------------------------------------------------ */
/* Every frame time while bytes come: the byte on the wire completes (its stop bit ends), then
 * the next one, if any, starts (its start bit: the moment an overrun is judged). */
static avr_cycle_count_t rx_wire(avr_t *avr, avr_cycle_count_t when, void *param)
{
    utrf_sim_t *s = param;
    int rx_enabled;
    uint64_t frame = board_io_uart0_frame_cycles(avr, &rx_enabled);
    bridge_sync_baud(s);
    if (s->rx_on_wire) {
        s->rx_on_wire = 0;
        receiver_complete(s, s->rx_wire_byte, rx_enabled);
    }
    if (s->rx_head == s->rx_tail) {
        s->rx_wire_active = 0;
        return 0;
    }
    line_faults_t *f = &s->faults[UTRF_SIM_TO_BOARD];
    uint8_t b;
    int fe = 0;
    if (!f->burst_left && chance(s, f->insert)) { /* a noise byte takes this frame; the host byte waits */
        b = noise_byte(s, &fe);
        s->stats.rx_inserted++;
    } else {
        b = s->rx[s->rx_tail & RX_MASK];
        if (!f->burst_left && chance(s, f->duplicate))
            s->stats.rx_duplicated++; /* left at the tail: it goes on the wire again */
        else
            s->rx_tail++;
        if (burst_byte(s, f, &b, &fe)) {
            s->stats.rx_burst_bytes++;
        } else {
            if (chance(s, f->drop)) {
                s->stats.rx_dropped++;
                return when + frame; /* the line idles for its frame */
            }
            if (chance(s, f->corrupt)) {
                b = flip_bit(s, b);
                s->stats.rx_corrupted++;
            }
        }
    }
    if (s->rx_shift_full && rx_enabled && chip_fifo_count(s) >= CHIP_FIFO)
        overrun(s);
    s->rx_on_wire = 1;
    s->rx_wire_byte = (uint16_t)(b | (fe ? UART_INPUT_FE : 0));
    return when + frame;
}

void bridge_rx_kick(utrf_sim_t *s)
{
    if (s->rx_wire_active || (s->rx_head == s->rx_tail && !s->rx_on_wire))
        return;
    s->rx_wire_active = 1;
    avr_cycle_timer_register(s->avr, 1, rx_wire, s);
}

size_t bridge_rx_space(const utrf_sim_t *s)
{
    return RX_QUEUE_SIZE - (s->rx_head - s->rx_tail);
}

size_t bridge_rx_push(utrf_sim_t *s, const uint8_t *buf, size_t n)
{
    size_t space = bridge_rx_space(s);
    if (n > space)
        n = space;
    for (size_t i = 0; i < n; i++)
        s->rx[(s->rx_head + i) & RX_MASK] = buf[i];
    s->rx_head += (uint32_t)n;
    bridge_rx_kick(s);
    return n;
}

static void on_uart_output(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    utrf_sim_t *s = param;
    /* Runs before simavr arms its transmit pump, so the pump gets the right frame time. */
    bridge_sync_baud(s);
    s->stats.tx_uart_bytes++;
    if (s->tx_head - s->tx_tail >= TX_QUEUE_SIZE) {
        s->stats.tx_unheard++;
        return;
    }
    uint64_t due = s->avr->cycle + s->frame_cycles;
    if (s->tx_head != s->tx_tail) {
        uint64_t after = s->tx[(s->tx_head - 1) & TX_MASK].due + s->frame_cycles;
        if (after > due)
            due = after;
    }
    s->tx[s->tx_head & TX_MASK] = (tx_byte_t){(uint8_t)value, due};
    s->tx_head++;
}

void bridge_to_host(utrf_sim_t *s, const uint8_t *buf, size_t n)
{
    if (s->capture_on) {
        for (size_t i = 0; i < n; i++) {
            if (s->cap_head - s->cap_tail >= CAPTURE_SIZE) {
                s->stats.tx_unheard += n - i;
                break;
            }
            s->capture[s->cap_head & CAP_MASK] = buf[i];
            s->cap_head++;
            beats_byte(s, buf[i]);
            if (buf[i] == s->wake_byte)
                s->woke = 1;
        }
    }
    serve_write(s, buf, n);
}

/* The captured frames' wire times: a frame starts with the start bit of the first byte after
 * a 0x00 and ends with the stop bit of its own 0x00 (the firmware's bytes, before the line's
 * faults). */
static void log_frame(utrf_sim_t *s, uint8_t b, uint64_t due)
{
    if (!s->tx_frame_start)
        s->tx_frame_start = due - s->frame_cycles;
    if (b)
        return;
    uint32_t i = s->frames_head % UTRF_SIM_FRAME_LOG;
    s->frame_start[i] = s->tx_frame_start;
    s->frame_end[i] = due;
    s->frames_head++;
    if (s->frames_head - s->frames_tail > UTRF_SIM_FRAME_LOG)
        s->frames_tail = s->frames_head - UTRF_SIM_FRAME_LOG; /* the oldest are lost */
    s->tx_frame_start = 0;
}

size_t utrf_sim_uart_frames(utrf_sim_t *s, uint64_t *starts, uint64_t *ends, size_t n)
{
    size_t k = 0;
    for (; k < n && s->frames_tail != s->frames_head; k++, s->frames_tail++) {
        starts[k] = s->frame_start[s->frames_tail % UTRF_SIM_FRAME_LOG];
        ends[k] = s->frame_end[s->frames_tail % UTRF_SIM_FRAME_LOG];
    }
    return k;
}

void bridge_deliver(utrf_sim_t *s)
{
    uint8_t out[512];
    size_t n = 0;
    line_faults_t *f = &s->faults[UTRF_SIM_TO_HOST];
    uint64_t now = s->avr->cycle;
    while (s->tx_tail != s->tx_head && s->tx[s->tx_tail & TX_MASK].due <= now) {
        uint8_t b = s->tx[s->tx_tail & TX_MASK].byte;
        if (s->capture_on)
            log_frame(s, b, s->tx[s->tx_tail & TX_MASK].due);
        s->tx_tail++;
        if (n + 3 > sizeof out) {
            bridge_to_host(s, out, n);
            n = 0;
        }
        if (burst_byte(s, f, &b, NULL)) {
            out[n++] = b;
            s->stats.tx_burst_bytes++;
            continue;
        }
        if (chance(s, f->insert)) {
            out[n++] = noise_byte(s, NULL);
            s->stats.tx_inserted++;
        }
        if (chance(s, f->drop)) {
            s->stats.tx_dropped++;
            continue;
        }
        if (chance(s, f->corrupt)) {
            b = flip_bit(s, b);
            s->stats.tx_corrupted++;
        }
        out[n++] = b;
        if (chance(s, f->duplicate)) {
            out[n++] = b;
            s->stats.tx_duplicated++;
        }
    }
    if (n)
        bridge_to_host(s, out, n);
}

void bridge_after_reset(utrf_sim_t *s)
{
    /* The reset cuts the byte on the wire and empties the transmit buffer: only bytes whose
     * stop bit has already gone reach the host. */
    uint64_t now = s->avr->cycle;
    while (s->tx_head != s->tx_tail && s->tx[(s->tx_head - 1) & TX_MASK].due > now) {
        s->tx_head--;
        s->stats.tx_cut++;
    }
    /* The byte coming in is cut, the receiver starts empty (simavr emptied its FIFO). */
    if (s->rx_on_wire)
        s->stats.rx_lost_disabled++;
    s->rx_on_wire = 0;
    s->rx_shift_full = 0;
    s->rx_lost_pending = 0;
    s->rx_arr_tail = s->rx_arr_head;
    /* It also cleared simavr's cycle timers: restart the wire if bytes are waiting. */
    s->rx_wire_active = 0;
    bridge_rx_kick(s);
}

void bridge_init(utrf_sim_t *s)
{
    uint64_t seed = s->rng + 0x9E3779B97F4A7C15ULL; /* splitmix64 of the seed: never zero */
    seed = (seed ^ (seed >> 30)) * 0xBF58476D1CE4E5B9ULL;
    seed = (seed ^ (seed >> 27)) * 0x94D049BB133111EBULL;
    seed ^= seed >> 31;
    s->rng = seed ? seed : 1;

    for (char name = '0'; name <= '3'; name++) {
        /* No console echo of the firmware's output, no usleep() while it polls UCSRnA. */
        uint32_t flags = 0;
        avr_ioctl(s->avr, AVR_IOCTL_UART_SET_FLAGS(name), &flags);
    }
    s->uart_irq = avr_io_getirq(s->avr, AVR_IOCTL_UART_GETIRQ('0'), 0);
    hook_read(s->avr, s->uart0->r_udr, &s->udr_read, udr_read, s);
    hook_read(s->avr, s->uart0->r_ucsra, &s->ucsra_read, ucsra_read, s);
    avr_irq_register_notify(s->uart_irq + UART_IRQ_OUTPUT, on_uart_output, s);
    bridge_sync_baud(s);
}

size_t utrf_sim_uart_write(utrf_sim_t *s, const uint8_t *buf, size_t n)
{
    n = bridge_rx_push(s, buf, n);
    s->stats.rx_host_bytes += n;
    return n;
}

size_t utrf_sim_uart_read(utrf_sim_t *s, uint8_t *buf, size_t n)
{
    size_t avail = s->cap_head - s->cap_tail;
    if (n > avail)
        n = avail;
    for (size_t i = 0; i < n; i++)
        buf[i] = s->capture[(s->cap_tail + i) & CAP_MASK];
    s->cap_tail += (uint32_t)n;
    return n;
}

size_t utrf_sim_uart_pending(const utrf_sim_t *s)
{
    return s->rx_head - s->rx_tail;
}

void utrf_sim_set_capture(utrf_sim_t *s, int on)
{
    s->capture_on = on != 0;
    if (!s->capture_on) {
        s->cap_head = s->cap_tail = 0;
        s->frames_head = s->frames_tail = 0;
        s->tx_frame_start = 0;
        s->acc_n = 0;
        s->acc_sync = 0; /* the client reads from the next capture's start */
    }
}

static int probability(double p)
{
    return p >= 0.0 && p <= 1.0;
}

int utrf_sim_set_line_faults(utrf_sim_t *s, int dir, const utrf_sim_line_faults_t *f)
{
    if (dir != UTRF_SIM_TO_BOARD && dir != UTRF_SIM_TO_HOST)
        return -1;
    if (!(probability(f->drop) && probability(f->corrupt) && probability(f->insert) &&
          f->insert < 1.0 && probability(f->duplicate) && f->duplicate < 1.0 &&
          probability(f->burst)))
        return -1;
    if (f->burst > 0.0 && !(f->burst_min >= 1 && f->burst_min <= f->burst_max))
        return -1;
    s->faults[dir] = (line_faults_t){f->drop,      f->corrupt,   f->insert, f->duplicate,
                                     f->burst,     f->burst_min, f->burst_max, 0};
    return 0;
}

size_t utrf_sim_inject(utrf_sim_t *s, int dir, const uint8_t *buf, size_t n)
{
    if (dir == UTRF_SIM_TO_BOARD) {
        n = bridge_rx_push(s, buf, n);
        s->stats.rx_inserted += n;
        return n;
    }
    if (dir == UTRF_SIM_TO_HOST) {
        bridge_to_host(s, buf, n);
        s->stats.tx_inserted += n;
        return n;
    }
    return 0;
}
