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

bool send_board_frame(Board& b, uint8_t msg_id, const uint8_t* body, uint8_t len) {
    uint8_t frame[framing::kMaxFrameBytes];
    const uint8_t n = framing::encode_frame(b.board_seq, msg_id, body, len, frame);
    if (hal::serial_tx_room() < n) return false;
    hal::serial_write(frame, n);
    b.board_seq = proto::next_board_seq(b.board_seq);
    return true;
}

void receive(Board& b) {
    const uint16_t lost = hal::serial_take_overruns();
    b.link.rx_overruns += lost;
    for (uint8_t i = 0; i < kRxBurst && b.reply_len == 0; ++i) {
        uint8_t byte;
        if (hal::serial_read(&byte, 1) == 0) break;
        switch (b.decoder.feed(byte)) {
            case framing::RxEvent::FRAME:
                ++b.link.rx_frames;
                b.hand.note_frame();
                dispatch::handle(b, b.decoder.seq(), b.decoder.msg_id(), b.decoder.body(),
                                 b.decoder.body_len());
                break;
            case framing::RxEvent::CRC_ERROR:
                ++b.link.rx_crc_errors;
                dispatch::nack(b, b.decoder.seq(), b.decoder.msg_id(),
                               (uint8_t)proto::ErrorCode::BAD_CRC, 0xFF);
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
}

void report_faults(Board& b) {
    for (uint8_t f = 0; f < hand::kFingers; ++f) {
        if (b.hand.finger(f).pending_new_faults() == 0) continue;
        if (hal::serial_tx_room() < framing::kMaxFrameBytes) return;  // next pass
        proto::Fault m;
        {
            Lock lock;
            m.board_time = b.hand.ticks() * 1000UL;
            m.finger = f;
            m.new_faults = b.hand.finger(f).take_new_faults();
            for (uint8_t k = 0; k < hand::kFingers; ++k) m.faults[k] = b.hand.finger(k).faults();
        }
        uint8_t body[proto::kMaxPayload];
        send_board_frame(b, m.kId, body, proto::encode(m, body));
    }
}

void stream(Board& b) {
    const uint32_t now = b.hand.ticks();
    const uint32_t elapsed = now - b.telemetry_tick;
    b.telemetry_tick = now;
    if (b.telemetry_hz == 0) return;
    // Phase accumulator: rate per tick, one frame per 1000 (kTickHz).
    uint32_t acc = b.telemetry_acc + elapsed * b.telemetry_hz;
    if (acc < hand::kTickHz) {
        b.telemetry_acc = (uint16_t)acc;
        return;
    }
    acc -= hand::kTickHz;
    // Frames that fell due while loop() was elsewhere are lost: count them, keep the seq gap.
    while (acc >= hand::kTickHz) {
        acc -= hand::kTickHz;
        ++b.link.tx_dropped;
        b.board_seq = proto::next_board_seq(b.board_seq);
    }
    b.telemetry_acc = (uint16_t)acc;
    if (hal::serial_tx_room() < framing::kMaxFrameBytes) {
        ++b.link.tx_dropped;
        b.board_seq = proto::next_board_seq(b.board_seq);  // the host sees the gap
        return;
    }
    uint8_t body[proto::kMaxPayload];
    const uint8_t n = dispatch::encode_state(b, body);
    send_board_frame(b, proto::State::kId, body, n);
}

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

void watchdog(Board& b) {
    b.hand.note_loop();
    const uint32_t t = b.hand.ticks();
    const uint32_t ms = hal::millis();
    if (t != b.watch_ticks) {
        b.watch_ticks = t;
        b.watch_ms = ms;
    }
    if (ms - b.watch_ms > kTickDeadMs) {
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

bool queue_reply(uint8_t seq, uint8_t msg_id, const uint8_t* body, uint8_t len) {
    Board& b = g_board;
    if (b.reply_len != 0) return false;
    b.reply_len = framing::encode_frame(seq, msg_id, body, len, b.reply);
    return b.reply_len != 0;
}

void apply_finger_config(uint8_t f) {
    Board& b = g_board;
    pid::Coeffs c;
    const finger::Params p = finger::compile(b.cfg.finger[f], hand::kDt, c);
    Lock lock;
    b.hand.configure_finger(f, p, c);
    // A target outside new limits is never kept: clamp it in.
    finger::Finger& fg = b.hand.finger(f);
    const int16_t t = fg.target();
    if (t < p.theta_min || t > p.theta_max) {
        fg.set_target(t < p.theta_min ? p.theta_min : p.theta_max);
    }
}

void apply_all_config() {
    for (uint8_t f = 0; f < hand::kFingers; ++f) apply_finger_config(f);
    Lock lock;
    g_board.hand.set_safety(g_board.cfg.safety.heartbeat_timeout_ms, g_board.cfg.safety.safe_action);
}

void setup() {
    Board& b = g_board;
    b.save_seq = -1;
    b.board_seq = proto::kBoardSeqFlag;
    b.boot_sent = false;
    // A lone 0x00 ahead of boot ends whatever frame the reset cut off on the host's side, so
    // boot arrives whole (protocol/README.md, Receiving). The transmit buffer is empty here.
    static const uint8_t kDelimiter = 0;
    hal::serial_write(&kDelimiter, 1);
    b.reply_len = 0;
    b.telemetry_hz = 0;
    b.telemetry_acc = 0;
    b.telemetry_tick = 0;
    b.link = LinkStats();
    b.reset_cause = hal::reset_cause();
    kin::init();
    b.config_status = (uint8_t)config::load(b.cfg);
    apply_all_config();
    b.watch_ticks = 0;
    b.watch_ms = hal::millis();
    hal::watchdog_clear_hang_mark();
    hal::watchdog_start();
    hal::tick_start();
}

void loop() {
    Board& b = g_board;
    watchdog(b);
    if (!b.boot_sent) {
        uint8_t body[proto::kMaxPayload];
        const uint8_t n = dispatch::encode_boot(b, body);
        b.boot_sent = send_board_frame(b, proto::Boot::kId, body, n);
    }
    if (b.reply_len != 0 && hal::serial_tx_room() >= b.reply_len) {
        hal::serial_write(b.reply, b.reply_len);
        b.reply_len = 0;
    }
    receive(b);
    if (b.reply_len != 0 && hal::serial_tx_room() >= b.reply_len) {
        hal::serial_write(b.reply, b.reply_len);
        b.reply_len = 0;
    }
    save_progress(b);
    report_faults(b);
    stream(b);
    // Nothing left for this pass: sleep until the next interrupt (the tick comes every
    // millisecond, a received byte at once), so the CPU idles instead of spinning.
    if (b.reply_len == 0 && !b.writer.busy()) hal::idle();
}

void tick() {
    g_board.hand.tick(hal::encoders_read());
    hal::encoders_sample();
}

void tick_done(uint16_t cycles, bool overran) { g_board.hand.record_timing(cycles, overran); }

}  // namespace app
}  // namespace utrf
