#include "app.h"

#include "../generated/protocol_messages.h"
#include "../hal/hal.h"
#include "dispatch.h"
#include "kinematics.h"

namespace utrf {
namespace app {

namespace {
Board g_board;

// Bytes taken from the UART per loop() pass: bounds the pass, the rest waits in the buffer.
const uint8_t kRxBurst = 64;

// Room in the transmit buffer when it is empty: a board-initiated frame goes out only then,
// so a reply never queues behind more than the one frame on the line.
bool tx_idle(const Board& b) { return b.reply_len == 0 && hal::serial_tx_room() >= b.tx_capacity; }

void send_board_frame(Board& b, const uint8_t* frame, uint8_t n) {
    hal::serial_write(frame, n);
    b.board_seq = proto::next_board_seq(b.board_seq);
}

template <typename Msg>
void send_board_message(Board& b, const Msg& m) {
    uint8_t frame[framing::kMaxFrameBytes];
    framing::FrameWriter w(frame, b.board_seq, Msg::kId);
    proto::write(w, m);
    send_board_frame(b, frame, w.finish());
}

__attribute__((noinline)) void flush_reply_send(Board& b) {
    if (hal::serial_tx_room() >= b.reply_len) {
        hal::serial_write(b.reply, b.reply_len);
        if (b.cache_reply) {
            // Kept for a resend of its request, once it is on its way (no request is read
            // before: one reply waits at a time).
            ReplyCache& c = b.cache;
            for (uint8_t i = 0; i < b.reply_len; ++i) c.frame[i] = b.reply[i];
            c.len = b.reply_len;
            b.cache_reply = false;
        }
        b.reply_len = 0;
    }
}

// A reply waiting goes into the transmit buffer when it fits: the check inline (three times a
// pass, rarely true), the copy out of line.
__attribute__((always_inline)) inline void flush_reply(Board& b) {
    if (b.reply_len != 0) flush_reply_send(b);
}

// One valid frame from the host: the seq rules and the reply cache, then dispatch.
void take_request(Board& b) {
    const uint8_t seq = b.decoder.seq();
    const uint8_t id = b.decoder.msg_id();
    if (seq & proto::kBoardSeqFlag) {
        // A request's seq never has the board's flag: its reply would read as a board frame.
        ++b.link.rx_ignored;
        return;
    }
    ++b.link.rx_frames;
    b.hand.note_frame();
    const uint16_t crc = b.decoder.crc();
    ReplyCache& c = b.cache;
    if (c.len != 0 && seq == c.seq && id == c.msg_id && crc == c.crc) {
        ++b.link.rx_repeats;  // a resend: the reply again, the request not done twice
        for (uint8_t i = 0; i < c.len; ++i) b.reply[i] = c.frame[i];
        b.reply_len = c.len;
        return;
    }
    if (b.writer.busy() && b.save_seq == seq && id == proto::SaveConfig::kId) {
        ++b.link.rx_repeats;  // a resent save_config under way: its ack comes when done
        return;
    }
    if (id == proto::Heartbeat::kId) {
        // Heartbeats go out while a request waits for its resend: they keep its reply. Once
        // the host's counter is half a round past it, the cached seq could come round again
        // for a new request: forget it.
        if (c.len != 0 && ((uint8_t)(seq - c.seq) & 0x7F) >= 64) c.len = 0;
    } else {
        c.len = 0;  // a new request: the old reply is no longer anybody's
        b.request_seq = seq;
        b.request_id = id;
        b.request_crc = crc;
    }
    dispatch::handle(b, seq, id, b.decoder.body(), b.decoder.body_len());
    b.request_seq = -1;
}

// One received byte into the decoder, and what it completes.
void receive_byte(Board& b, uint8_t byte) {
    if (!b.decoder.in_frame()) b.rx_frame_tick = b.hand.ticks();
    switch (b.decoder.feed(byte)) {
        case framing::RxEvent::FRAME:
            take_request(b);
            break;
        case framing::RxEvent::CRC_ERROR:
            ++b.link.rx_crc_errors;
            // The hint echoes the damaged seq; one with the board's flag would read as a board
            // frame, and names no request: counted only.
            if (!(b.decoder.seq() & proto::kBoardSeqFlag)) {
                dispatch::nack(b, b.decoder.seq(), b.decoder.msg_id(),
                               (uint8_t)proto::ErrorCode::BAD_CRC, 0);
            }
            break;
        case framing::RxEvent::FRAMING_ERROR:
        case framing::RxEvent::OVERSIZE:
            // Nothing trustworthy to answer to (no seq): counted for get_stats.
            ++b.link.rx_framing_errors;
            break;
        case framing::RxEvent::NONE:
            break;
    }
}

// The received bytes, read in place from the UART's buffer (no copy, no call a byte), up to
// kRxBurst of them; a reply waiting for room stops the reading (the rest stays in the buffer).
// Out of line, called only when bytes wait: its locals and the decoder's registers are not
// saved and set up by the passes that find none (most of them).
__attribute__((noinline)) void receive_bytes(Board& b) {
    uint8_t budget = kRxBurst;
    while (budget != 0 && b.reply_len == 0) {
        const uint8_t* data;
        uint8_t n = hal::serial_rx_peek(&data);
        if (n == 0) break;
        if (n > budget) n = budget;
        uint8_t used = 0;
        while (used < n && b.reply_len == 0) {
            // A frame's bytes in one run, then the byte that ends the run (its 0x00) one at a
            // time.
            if (!b.decoder.in_frame()) b.rx_frame_tick = b.hand.ticks();
            used = (uint8_t)(used + b.decoder.feed_run(data + used, (uint8_t)(n - used)));
            if (used < n) receive_byte(b, data[used++]);
        }
        hal::serial_rx_take(used);
        budget = (uint8_t)(budget - used);
    }
}

// The UART's lost-byte counts, then the bytes (above). The counts are added only when some
// came (a 32-bit add each, every pass, otherwise).
void receive(Board& b) {
    const uint16_t lost = hal::serial_take_overruns();
    if (UTRF_UNLIKELY(lost != 0)) b.link.rx_overruns += lost;
    const hal::UartErrors e = hal::serial_take_uart_errors();
    if (UTRF_UNLIKELY((e.overruns | e.frame_errors) != 0)) {
        b.link.uart_overruns += e.overruns;
        b.link.uart_frame_errors += e.frame_errors;
    }
    if (b.reply_len == 0 && hal::serial_rx_waiting()) receive_bytes(b);
}

}  // namespace

void note_status(Board& b, const uint8_t* mode, const uint8_t* faults) {
    bool same = true;
    for (uint8_t f = 0; f < hand::kFingers; ++f) {
        same = same && mode[f] == b.status_mode[f] && faults[f] == b.status_faults[f];
    }
    if (same) return;
    for (uint8_t f = 0; f < hand::kFingers; ++f) {
        b.status_mode[f] = mode[f];
        b.status_faults[f] = faults[f];
    }
    ++b.status_change;
    b.status_pending = true;
}

namespace {
// The status as last noted, compared a byte at a time (each byte is read whole, so no lock is
// needed to tell): written out, each finger's bytes at a fixed address (the one Board), no
// frame, no loop; every loop() pass asks it.
__attribute__((always_inline)) inline bool status_unchanged(const Board& b) {
    static_assert(hand::kFingers == 5, "five fingers written out");
    const hand::Hand& h = b.hand;
    return h.finger(0).mode() == b.status_mode[0] && h.finger(0).faults() == b.status_faults[0] &&
           h.finger(1).mode() == b.status_mode[1] && h.finger(1).faults() == b.status_faults[1] &&
           h.finger(2).mode() == b.status_mode[2] && h.finger(2).faults() == b.status_faults[2] &&
           h.finger(3).mode() == b.status_mode[3] && h.finger(3).faults() == b.status_faults[3] &&
           h.finger(4).mode() == b.status_mode[4] && h.finger(4).faults() == b.status_faults[4];
}

// A change: taken as one snapshot, under the lock. Out of line: rare.
__attribute__((noinline)) void status_changed(Board& b) {
    uint8_t mode[hand::kFingers];
    uint8_t faults[hand::kFingers];
    {
        Lock lock;
        for (uint8_t f = 0; f < hand::kFingers; ++f) {
            mode[f] = b.hand.finger(f).mode();
            faults[f] = b.hand.finger(f).faults();
        }
    }
    note_status(b, mode, faults);
}
}  // namespace

void poll_status(Board& b) {
    // Usually nothing changed; only a change is taken as one snapshot, under the lock.
    if (!status_unchanged(b)) status_changed(b);
}

namespace {

// Whether any finger latched a fault not reported yet (written out: fixed addresses).
__attribute__((always_inline)) inline bool new_faults(const Board& b) {
    const hand::Hand& h = b.hand;
    return (h.finger(0).pending_new_faults() | h.finger(1).pending_new_faults() |
            h.finger(2).pending_new_faults() | h.finger(3).pending_new_faults() |
            h.finger(4).pending_new_faults()) != 0;
}

bool report_faults(Board& b) {
    for (uint8_t f = 0; f < hand::kFingers; ++f) {
        if (b.hand.finger(f).pending_new_faults() == 0) continue;
        proto::Fault m;
        {
            Lock lock;
            m.board_time = b.hand.ticks() * 1000UL;
            m.finger = f;
            m.new_faults = b.hand.finger(f).take_new_faults();
            for (uint8_t k = 0; k < hand::kFingers; ++k) m.faults[k] = b.hand.finger(k).faults();
        }
        send_board_message(b, m);
        return true;
    }
    return false;
}

// A request is coming in: bytes of it in the decoder (for at most kRequestHoldTicks: garbage
// with no 0x00 after it holds nothing longer), or bytes in the UART's buffer that loop() has
// not read yet (a tick or this pass's work held it up while they came).
bool request_coming(const Board& b) {
    return (b.decoder.in_frame() && b.hand.ticks() - b.rx_frame_tick < kRequestHoldTicks) ||
           hal::serial_rx_waiting();
}

// The board's own frames, in priority order: faults, the status, the state stream's samples.
// A frame starts only into an empty transmit buffer, one a pass, so a reply waits behind at
// most one. While a request is coming in, no sample starts (its reply goes first, onto a free
// line; they wait in the ring), and a sample encoded while one began to come is not sent. Once
// kStreamBacklog samples wait (loop() or the line fell behind: a long request, a busy line),
// they go out whatever comes in, back to back, as far as the buffer has room.
__attribute__((noinline)) void board_frames_send(Board& b) {
    const bool idle = tx_idle(b);
    uint8_t pending = b.hand.stream_pending();
    // Nothing can start (the buffer busy, the stream not behind): the status is polled when a
    // frame can go, before it.
    if (!idle && pending < kStreamBacklog) return;
    if (!status_unchanged(b)) status_changed(b);  // poll_status(), inline
    if (idle && report_faults(b)) return;
    if (idle && b.status_pending) {
        proto::Status m;
        dispatch::fill_status(b, m);
        send_board_message(b, m);
        b.status_pending = false;
        return;
    }
    while (pending != 0 && b.reply_len == 0 &&
           hal::serial_tx_room() >= framing::kMaxFrameBytes) {
        const bool hold = pending < kStreamBacklog;
        if (hold && request_coming(b)) return;  // read first, next pass
        const hand::StateSample& s = b.hand.stream_oldest();
        uint8_t seq = b.board_seq;
        for (uint8_t k = 0; k < s.skipped; ++k) seq = proto::next_board_seq(seq);
        // Encoded straight into the UART's ring, behind what it still holds (room checked),
        // and sent only if no request began to come in meanwhile (a tick may fall in the
        // encoding): then the bytes stay unsent, the sample waits, and the reply goes first.
        const uint8_t end =
            dispatch::write_state_frame(b, seq, s, hal::serial_tx_ring(), hal::serial_tx_head());
        if (hold && request_coming(b)) return;
        for (uint8_t k = 0; k < s.skipped; ++k) ++b.link.tx_dropped;  // their seqs skipped
        b.hand.stream_pop();
        hal::serial_tx_commit(end);
        b.board_seq = proto::next_board_seq(seq);
        if (--pending < kStreamBacklog) return;  // one a pass, unless behind
    }
}

// Most passes have nothing to send: no sample waiting, the status as noted and reported, no
// new fault. Then board_frames_send() would do nothing whatever the buffer holds; that is
// told here without its frame (its locals, a dozen register saves).
void board_frames(Board& b) {
    if (b.hand.stream_pending() == 0 && !b.status_pending && status_unchanged(b) &&
        !new_faults(b)) {
        return;
    }
    board_frames_send(b);
}

}  // namespace

void keep_stream() { board_frames(g_board); }

namespace {

void save_progress(Board& b) {
    if (!b.writer.busy() || b.reply_len != 0) return;
    if (!b.writer.step()) return;
    const uint8_t seq = (uint8_t)b.save_seq;
    b.save_seq = -1;
    if (b.writer.failed()) {
        // The EEPROM did not keep the image after every retry (worn cells?).
        dispatch::nack(b, seq, proto::SaveConfig::kId, (uint8_t)proto::ErrorCode::BUSY, 0xFF);
    } else {
        dispatch::ack(b, seq, proto::SaveConfig::kId);
    }
}

// Before any reply: the host learns of the reset first. Out of line: once after a reset.
__attribute__((noinline)) void send_boot(Board& b) {
    if (hal::serial_tx_room() < framing::kMaxFrameBytes) return;
    proto::Boot m;
    dispatch::fill_boot(b, m);
    send_board_message(b, m);
    b.boot_sent = true;
}

void watchdog(Board& b) {
    b.hand.note_loop();
    b.loop_due = 0;  // before the pass's work: a tick that asks for one during it is seen
    // The last tick's millisecond first, then now's (a tick between the two reads only makes
    // the first older, never later than now).
    const uint32_t tick_ms = hal::tick_millis();
    const uint32_t ms = hal::millis();
    b.pass_ms = ms;
    if (ms - tick_ms > kTickDeadMs) {
        // The tick stopped: nothing supervises the motors. Off, and let the watchdog reset.
        if (!b.hand.halted()) {
            Lock lock;
            b.hand.halt();
        }
        hal::motors_all_off();
        return;
    }
    if (!b.hand.halted()) hal::watchdog_feed();
}
}  // namespace

Board& board() { return g_board; }

uint32_t board_time_us() {
    uint32_t t;
    hal::Stamp s;
    bool wrapped;
    {
        Lock lock;
        t = g_board.hand.ticks();
        s = hal::stamp();
        wrapped = hal::tick_period_elapsed();
    }
    return (t + (wrapped ? 1 : 0)) * 1000UL + (uint32_t)s.coarse * 4u;
}

uint8_t* reply_slot() { return g_board.reply_len == 0 ? g_board.reply : 0; }

void reply_written(uint8_t seq, uint8_t len) {
    Board& b = g_board;
    b.reply_len = len;
    if (b.request_seq != (int16_t)seq || len == 0) return;
    // The reply to the request being dispatched: kept for a resend of that request (copied
    // when it goes into the transmit buffer, flush_reply()).
    ReplyCache& c = b.cache;
    b.cache_reply = true;
    c.seq = seq;
    c.msg_id = b.request_id;
    c.crc = b.request_crc;
}

void flush_reply() { flush_reply(g_board); }

bool queue_reply(uint8_t seq, uint8_t msg_id, const uint8_t* body, uint8_t len) {
    uint8_t* slot = reply_slot();
    if (slot == 0) return false;
    const uint8_t n = framing::encode_frame(seq, msg_id, body, len, slot);
    reply_written(seq, n);
    return n != 0;
}

void apply_finger_config(uint8_t f) {
    Board& b = g_board;
    pid::Coeffs c;
    const finger::Params p = finger::compile(b.cfg.finger[f], hand::kDt, c);
    dispatch::target_window(p.theta_min, p.theta_max, b.urad_lo[f], b.urad_hi[f]);
    Lock lock;
    // The move's memo goes with a path the new limits ended: its resend is a new move.
    if (b.hand.configure_finger(f, p, c)) b.move_memo = false;
}

void apply_motion(uint8_t f) {
    g_board.motion[f] = path::compile(g_board.cfg.finger[f].motion, hand::kDt);
}

void apply_all_config() {
    for (uint8_t f = 0; f < hand::kFingers; ++f) {
        apply_finger_config(f);
        apply_motion(f);
    }
    Lock lock;
    g_board.hand.set_safety(g_board.cfg.safety.heartbeat_timeout, g_board.cfg.safety.safe_action);
}

void setup() {
    Board& b = g_board;
    b.save_seq = -1;
    b.board_seq = proto::kBoardSeqFlag;
    b.boot_sent = false;
    b.tx_capacity = hal::serial_tx_room();  // empty: nothing was sent yet
    b.rx_frame_tick = 0;
    b.cache.len = 0;
    b.cache_reply = false;
    b.request_seq = -1;
    b.status_change = 0;
    b.status_pending = false;
    // A lone 0x00 ahead of boot ends whatever frame the reset cut off on the host's side, so
    // boot arrives whole (protocol/README.md, Receiving). The transmit buffer is empty here.
    static const uint8_t kDelimiter = 0;
    hal::serial_write(&kDelimiter, 1);
    b.reply_len = 0;
    b.link = LinkStats();
    b.reset_cause = hal::reset_cause();
    kin::init();
    b.config_status = (uint8_t)config::load(b.cfg);
    apply_all_config();
    for (uint8_t f = 0; f < hand::kFingers; ++f) {
        b.status_mode[f] = b.hand.finger(f).mode();
        b.status_faults[f] = b.hand.finger(f).faults();
    }
    b.loop_due = 0;
    b.loop_countdown = kLoopEveryTicks;
    b.paths_running = false;
    hal::watchdog_clear_hang_mark();
    hal::watchdog_start();
    hal::tick_start();
}

void loop() {
    Board& b = g_board;
    watchdog(b);
    if (UTRF_UNLIKELY(!b.boot_sent)) send_boot(b);
    flush_reply(b);
    receive(b);
    flush_reply(b);
    // After the requests: a request that came in meanwhile is not held up by the stall checks
    // (its reply is in the transmit buffer by now), and a check waits at most for one dispatch.
    b.hand.stall_rules();  // about every 5 ticks a finger (core/hand.h)
    board_frames(b);
    // A segment is due every 5 ticks, planned one ahead (core/path.h): while a move runs, a
    // pass every tick.
    b.paths_running = b.hand.plan_paths();
    save_progress(b);
    flush_reply(b);
}

bool idle() {
    // The cheap reads first (bytes, no call), the clocks' 32-bit compares last: each check
    // that finds work returns false, and all of them run before the transmit buffer's test.
    const Board& b = g_board;
    if (!b.boot_sent || b.reply_len != 0 || b.writer.busy()) return false;
    const uint8_t pending = b.hand.stream_pending();
    if (pending >= kStreamBacklog) return false;  // behind: they go as the buffer has room
    if (hal::serial_rx_waiting()) return false;
    if (b.loop_due || hal::millis() != b.pass_ms) return false;
    if (!tx_idle(b)) return true;    // a frame starts when the buffer empties: an interrupt
    return pending == 0 && !b.status_pending && !new_faults(b);
}

void take_bytes() {
    Board& b = g_board;
    if (b.reply_len != 0) return;
    const uint8_t* data;
    const uint8_t n = hal::serial_rx_peek(&data);
    if (n == 0) return;
    if (!b.decoder.in_frame()) b.rx_frame_tick = b.hand.ticks();
    hal::serial_rx_take(b.decoder.feed_run(data, n));
}

void tick() {
    g_board.hand.tick(hal::encoders_read());
    g_board.hand.stream_tick();
    hal::encoders_sample();
}

static_assert(kLoopEveryTicks <= finger::kStallEvery && kLoopEveryTicks < hand::kLoopHangTicks,
              "a pass at least as often as the stall rules and the loop-alive rule need");

bool tick_done(uint16_t cycles, bool overran) {
    Board& b = g_board;
    b.hand.record_timing(cycles, overran);
    // The cheap reads first: most ticks give loop() nothing (a sample every tenth at 100 Hz).
    // A pass at least every kLoopEveryTicks ticks, counted from the last one asked for (a
    // sample's pass serves the stall rules too).
    // A mode the tick changes comes with a new fault (a stop fault, the safe action's
    // HOST_TIMEOUT: a driving finger has none latched), or with the halt.
    if (--b.loop_countdown != 0 && b.hand.stream_pending() == 0 && !b.paths_running &&
        !new_faults(b) && !b.hand.halted()) {
        return false;
    }
    b.loop_countdown = kLoopEveryTicks;
    b.loop_due = 1;
    return true;
}

}  // namespace app
}  // namespace utrf
