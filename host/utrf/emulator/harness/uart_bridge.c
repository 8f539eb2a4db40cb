/* UART0 <-> host bytes, with the wire's timing and the line faults.
 *
 * To the board: host bytes wait in a queue; a cycle timer puts one on the wire per frame
 * time at the baud the firmware configured (start + data + parity + stop bits). simavr's
 * receiver makes a byte readable one frame after it starts, so a byte sent at cycle t is
 * readable at t + frame, as on the chip. A byte is only handed over while simavr's 64-byte
 * FIFO has room (it waits otherwise, as behind flow control: nothing is lost or reordered),
 * and is lost, as on the chip, while the receiver is off (during boot or after a reset).
 *
 * To the host: a byte the firmware writes to UDR0 reaches the host when its stop bit ends,
 * never sooner than one frame after the previous one.
 *
 * simavr 1.6 counts a parity bit in every frame whether parity is on or not (11 bits for
 * 8N1), which makes its own receive and transmit pacing 10 % slow; the bridge sets its
 * per-byte time to the frame the registers describe.
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

/* A burst of noise: starts at a byte with probability f->burst and replaces it and the
 * bytes after it, burst_min..burst_max in all. True when b was replaced. */
static int burst_byte(utrf_sim_t *s, line_faults_t *f, uint8_t *b)
{
    if (!f->burst_left && chance(s, f->burst)) {
        uint32_t span = f->burst_max - f->burst_min + 1;
        f->burst_left = f->burst_min + (uint32_t)((utrf_xorshift64s(&s->rng) >> 32) % span);
    }
    if (!f->burst_left)
        return 0;
    f->burst_left--;
    *b = (uint8_t)(utrf_xorshift64s(&s->rng) >> 56);
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

static int uart_fifo_full(const avr_uart_t *u)
{
    return ((u->input.write + 1) & (uart_fifo_fifo_size - 1)) == u->input.read;
}

static avr_cycle_count_t rx_wire(avr_t *avr, avr_cycle_count_t when, void *param)
{
    utrf_sim_t *s = param;
    if (s->rx_head == s->rx_tail) {
        s->rx_wire_active = 0;
        return 0;
    }
    int rx_enabled;
    uint64_t frame = board_io_uart0_frame_cycles(avr, &rx_enabled);
    bridge_sync_baud(s);
    if (rx_enabled && uart_fifo_full(s->uart0)) {
        s->stats.rx_held++;
        return when + frame;
    }
    line_faults_t *f = &s->faults[UTRF_SIM_TO_BOARD];
    uint8_t b;
    if (!f->burst_left && chance(s, f->insert)) { /* a noise byte takes this frame; the host byte waits */
        b = (uint8_t)(utrf_xorshift64s(&s->rng) >> 56);
        s->stats.rx_inserted++;
    } else {
        b = s->rx[s->rx_tail & RX_MASK];
        if (!f->burst_left && chance(s, f->duplicate))
            s->stats.rx_duplicated++; /* left at the tail: it goes on the wire again */
        else
            s->rx_tail++;
        if (burst_byte(s, f, &b)) {
            s->stats.rx_burst_bytes++;
        } else {
            if (chance(s, f->drop)) {
                s->stats.rx_dropped++;
                return when + frame;
            }
            if (chance(s, f->corrupt)) {
                b = flip_bit(s, b);
                s->stats.rx_corrupted++;
            }
        }
    }
    if (!rx_enabled) {
        s->stats.rx_lost_disabled++;
    } else {
        avr_raise_irq(s->uart_irq + UART_IRQ_INPUT, b);
        s->stats.rx_uart_bytes++;
    }
    return when + frame;
}

void bridge_rx_kick(utrf_sim_t *s)
{
    if (s->rx_wire_active || s->rx_head == s->rx_tail)
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
        if (burst_byte(s, f, &b)) {
            out[n++] = b;
            s->stats.tx_burst_bytes++;
            continue;
        }
        if (chance(s, f->insert)) {
            out[n++] = (uint8_t)(utrf_xorshift64s(&s->rng) >> 56);
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
