/* A run ahead's heartbeats, sent by the harness (utrf_sim.h, "Heartbeats within a run
 * ahead"): the client's rule (utrf.protocol.engine: the next heartbeat falls due a period
 * after the later of the last one sent and the last ack heard) kept here, so a batch of
 * samples runs through many heartbeats instead of ending before the next one. The output is
 * framed as the client frames it (COBS, CRC-16/CCITT-FALSE); a frame the rule cannot place
 * (not the stream, not an awaited ack: a boot, a nack, a damaged frame) freezes it, and the
 * run ends at the next stop, for the client to go on the general way.
 */
#include <string.h>

#include "harness_internal.h"

enum { KIND_OTHER = 0, KIND_STREAM = 1, KIND_ACK = 2 };

static uint16_t crc16_ccitt(const uint8_t *p, size_t n)
{
    uint16_t crc = 0xFFFF;
    for (size_t i = 0; i < n; i++) {
        crc ^= (uint16_t)(p[i] << 8);
        for (int b = 0; b < 8; b++)
            crc = crc & 0x8000 ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
    }
    return crc;
}

/* COBS-decoded length of in[0..n) into out, or -1 when it is not well formed */
static int cobs_decode(const uint8_t *in, size_t n, uint8_t *out)
{
    size_t i = 0, o = 0;
    while (i < n) {
        uint8_t code = in[i++];
        if (!code || i + code - 1 > n)
            return -1;
        for (uint8_t k = 1; k < code; k++)
            out[o++] = in[i++];
        if (code < 0xFF && i < n)
            out[o++] = 0;
    }
    return (int)o;
}

/* A frame ended (its 0x00 captured): an awaited ack is heard at this period's end, the
 * stream passes, anything else freezes the rule. */
static void beats_frame(utrf_sim_t *s)
{
    uint8_t raw[BEAT_ACC];
    int n = s->acc_sync && !s->acc_over ? cobs_decode(s->acc, s->acc_n, raw) : -1;
    if (n == 0)
        return; /* a lone 0x00 (the client's handshake sends one): nothing for the client */
    if (n < 4 || crc16_ccitt(raw, (size_t)n - 2) != (raw[n - 2] | raw[n - 1] << 8)) {
        s->beat_frozen = 1;
        return;
    }
    uint8_t seq = raw[0], kind = s->beat_kind[raw[1]];
    if (kind == KIND_STREAM && (seq & 0x80))
        return;
    if (kind == KIND_ACK && (s->beat_acks[seq >> 3] >> (seq & 7) & 1)) {
        s->beat_acks[seq >> 3] &= (uint8_t)~(1u << (seq & 7)); /* a second ack is stale */
        s->beat_heard = 1;
        return;
    }
    s->beat_frozen = 1;
}

void beats_byte(utrf_sim_t *s, uint8_t b)
{
    if (b) {
        if (s->acc_n < sizeof s->acc)
            s->acc[s->acc_n++] = b;
        else
            s->acc_over = 1;
        return;
    }
    if (s->beats_on)
        beats_frame(s);
    s->acc_n = 0;
    s->acc_over = 0;
    s->acc_sync = 1;
}

/* fl(t + period) is monotonic in t: max(due, fl(t + period)) is the client's fl(max(...) + period) */
static void beats_later(utrf_sim_t *s, uint64_t cycle)
{
    double due = (double)cycle / 16e6 + s->beat_period;
    if (due > s->beat_due)
        s->beat_due = due;
}

void beats_period_end(utrf_sim_t *s)
{
    if (s->beat_heard) {
        s->beat_heard = 0;
        beats_later(s, s->avr->cycle);
    }
}

int beats_arm(utrf_sim_t *s, uint64_t target)
{
    if (!s->beats_on)
        return 0;
    if (s->beat_frozen)
        return -1;
    if (!(s->beat_due <= (double)target / 16e6))
        return 0; /* not due within this stretch: the client would not make one for it */
    if (s->beats_sent >= s->beats_n)
        return -1;
    uint32_t i = s->beats_sent;
    memcpy(s->send_buf, s->beat_frame[i], s->beat_len[i]);
    s->send_len = s->beat_len[i];
    s->send_at = s->beat_due;
    s->sent_cycle = 0;
    s->sent_n = 0;
    s->beat_at[i] = s->beat_due;
    /* its ack counts from here: it goes out within the stretch, and no ack comes before */
    s->beat_acks[s->beat_seq[i] >> 3] |= (uint8_t)(1u << (s->beat_seq[i] & 7));
    return 0;
}

void beats_stretch_end(utrf_sim_t *s)
{
    if (!s->beats_on || !s->sent_cycle)
        return;
    uint32_t i = s->beats_sent++;
    s->beat_cycle[i] = s->sent_cycle;
    beats_later(s, s->sent_cycle);
    s->sent_cycle = 0;
}

int utrf_sim_ahead_beats(utrf_sim_t *s, const uint8_t *frames, const uint8_t *lens,
                         const uint8_t *seqs, size_t n, double due, double period,
                         const uint8_t *acks, const uint8_t *kinds)
{
    if (n > UTRF_SIM_BEATS || utrf_sim_ahead_running(s) || !(period > 0))
        return -1;
    for (size_t i = 0; i < n; i++) {
        if (!lens[i] || lens[i] > UTRF_SIM_BEAT_BYTES)
            return -1;
        memcpy(s->beat_frame[i], frames + i * UTRF_SIM_BEAT_BYTES, lens[i]);
        s->beat_len[i] = lens[i];
        s->beat_seq[i] = seqs[i];
    }
    memcpy(s->beat_acks, acks, sizeof s->beat_acks);
    memcpy(s->beat_kind, kinds, sizeof s->beat_kind);
    s->beats_n = (uint32_t)n;
    s->beats_sent = 0;
    s->beat_due = due;
    s->beat_period = period;
    s->beat_heard = 0;
    s->beat_frozen = 0;
    s->beats_on = 1;
    return 0;
}

size_t utrf_sim_ahead_beats_done(const utrf_sim_t *s, uint64_t *cycles, double *dues, size_t n)
{
    size_t k = 0;
    for (; k < n && k < s->beats_sent; k++) {
        cycles[k] = s->beat_cycle[k];
        dues[k] = s->beat_at[k];
    }
    return k;
}

int utrf_sim_ahead_beats_next(const utrf_sim_t *s, double *due, uint8_t *acks)
{
    if (!s->beats_ran || s->beat_frozen || utrf_sim_ahead_running(s))
        return -1;
    *due = s->beat_due;
    memcpy(acks, s->beat_acks, sizeof s->beat_acks);
    return 0;
}
