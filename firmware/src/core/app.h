// The firmware as a whole, in plain C++: what setup(), loop() and the tick interrupt do.
//
// The Arduino entry (utrf_main.cpp) and the host tests (firmware/test/) call these three
// functions; everything else is reached through board().
#ifndef UTRF_CORE_APP_H
#define UTRF_CORE_APP_H

#include <stdint.h>

#include "../hal/hal.h"
#include "config.h"
#include "framing.h"
#include "hand.h"

namespace utrf {
namespace app {

static const uint8_t kFwMajor = 0;
static const uint8_t kFwMinor = 1;
static const uint8_t kFwPatch = 0;
// Longest the tick may stand still before loop() turns the motors off and lets the watchdog
// reset the board.
static const uint8_t kTickDeadMs = 20;
// Longest a request arriving holds the state stream back (ticks); garbage with no 0x00 after
// it holds it no longer.
static const uint8_t kRequestHoldTicks = 2;
// Samples the state stream lets wait while a request comes in (the ring holds
// hand::kStreamSlots = 8): beyond, they go out whatever comes in.
static const uint8_t kStreamBacklog = 4;
// After a tick loop() is woken only when it has work (tick_done()): a sample to send, a fault
// the tick latched, a move's next segment, or every kLoopEveryTicks ticks for the checks that
// need no pass a tick (the stall rules, every kStallEvery ticks; the watchdog's feeding).
static const uint8_t kLoopEveryTicks = 5;

struct LinkStats {
    uint32_t rx_frames;
    uint32_t rx_crc_errors;
    uint32_t rx_framing_errors;
    uint32_t rx_overruns;
    uint32_t nacks;
    uint32_t tx_dropped;
    uint32_t rx_ignored;  // requests with the board's seq flag: never answered
    uint32_t rx_repeats;  // resent requests answered from the reply cache
    uint32_t uart_overruns;      // DOR0 reports: bytes the UART lost
    uint32_t uart_frame_errors;  // FE0 reports: bytes with a bad stop bit
};

// The last request answered and its reply frame. A request with the same seq, id and CRC is
// a resend (the host lost the reply): the board sends this frame again and does nothing.
struct ReplyCache {
    uint8_t frame[framing::kMaxFrameBytes];
    uint8_t len;  // 0: empty
    uint8_t seq;
    uint8_t msg_id;
    uint16_t crc;
};

struct Board {
    hand::Hand hand;
    config::Config cfg;
    uint8_t config_status;  // proto::ConfigStatus
    config::Writer writer;
    int16_t save_seq;  // seq of the save_config being written, -1 when none
    uint8_t reset_cause;

    framing::FrameDecoder decoder;
    LinkStats link;
    uint8_t board_seq;  // running seq of board-initiated frames
    bool boot_sent;

    // One reply waits here until the transmit buffer has room; meanwhile no input is read.
    uint8_t reply[framing::kMaxFrameBytes];
    uint8_t reply_len;
    ReplyCache cache;
    bool cache_reply;  // the reply waiting is to be cached (once it is in the transmit buffer)
    int16_t request_seq;  // the request being dispatched (its reply is cached), -1 when none
    uint8_t request_id;
    uint16_t request_crc;

    // Board-initiated frames go to the UART only when its transmit buffer is empty (its room
    // is tx_capacity), so a reply waits behind at most one of them.
    uint16_t tx_capacity;
    // The tick when the frame now arriving began: while a request comes in, no state frame is
    // started (for at most kRequestHoldTicks), so its reply finds the line free.
    uint32_t rx_frame_tick;

    // The status (modes, faults) last reported; status_change counts its changes.
    uint8_t status_change;
    uint8_t status_mode[hand::kFingers];
    uint8_t status_faults[hand::kFingers];
    bool status_pending;  // changed, the status frame not yet sent


    // millis() when this loop() pass began (its watchdog check): idle() finds whether timer 0
    // came since.
    uint32_t pass_ms;
    // Set by tick_done() when the tick gave loop() work, cleared as a pass begins: idle() finds
    // whether one came since.
    volatile uint8_t loop_due;
    uint8_t loop_countdown;  // ticks to the next pass every kLoopEveryTicks
    bool paths_running;      // a move under way (loop()'s view): a pass every tick

    // The last move (dispatch.cpp): a resend (same seq and body) gets its reply again and
    // restarts nothing. Zero at start-up (static storage): no move yet.
    bool move_memo;
    uint8_t move_seq;
    uint8_t move_body[34];   // proto::Move::kSize
    uint8_t move_reply[13];  // proto::Moving::kSize
    path::Limits motion[hand::kFingers];  // cfg's motion, compiled for path::plan()
    // Each finger's window of JOINT2_ANGLE set_targets values, micro-radians
    // (dispatch::target_window(), with its limits).
    int32_t urad_lo[hand::kFingers];
    int32_t urad_hi[hand::kFingers];
};

Board& board();

// The tick does not run while one of these lives (hal::tick_lock()); loop() context.
struct Lock {
    Lock() { hal::tick_lock(); }
    ~Lock() { hal::tick_unlock(); }
};

void setup();  // after hal init: load the configuration, arm the tick and the watchdog
void loop();   // one pass: link, dispatch, reports, telemetry, EEPROM, watchdog
// After a pass, called by the hardware layer with interrupts disabled: true when a pass run
// now would find nothing to do, so the CPU may sleep until the next interrupt (whatever gives
// loop() work comes from an interrupt: a byte received or sent, a tick that asks for a pass,
// timer 0's millisecond). False when a byte waits to be read, a reply or a board frame can go,
// the EEPROM is being written, or a tick that asked for a pass or timer 0 came during the
// pass (its work, or the tick-alive check at the new millisecond, is not left for the next
// interrupt).
bool idle();
// Between passes, while a frame comes in (the AVR layer's sleep, interrupts on): the bytes
// received so far, up to any 0x00, into the decoder, which decodes them as they come; the
// 0x00 and what it completes are left to loop(). Nothing while a reply waits.
void take_bytes();
void tick();   // the control tick (timer interrupt context)
// After each tick, from the hardware layer that timed it: its length in CPU cycles, and
// whether the next period began before it ended (an overrun). True when loop() has work from
// it (a sample, a new fault, a move's segment, the halt, or the kLoopEveryTicks pass): the
// AVR layer wakes loop() only then.
bool tick_done(uint16_t cycles, bool overran);

// A long request (a move's plans) calls this between its parts: the board's own frames that
// fell due meanwhile go out (the state stream drops a frame after two periods without one).
void keep_stream();

// Apply a finger's configuration (compile in loop() context, swap under the tick lock).
void apply_finger_config(uint8_t f);
void apply_motion(uint8_t f);  // set_motion's block: loop() alone reads it
void apply_all_config();

// Queue one frame for the host (the reply slot). False when the slot is taken.
bool queue_reply(uint8_t seq, uint8_t msg_id, const uint8_t* body, uint8_t len);
// The reply slot, for a reply written in place with a framing::FrameWriter; then
// reply_written(seq, length). Null when the slot is taken.
uint8_t* reply_slot();
// A sample's modes and faults against the status last reported: a change is a new status.
void note_status(Board& b, const uint8_t* mode, const uint8_t* faults);
// The status snapshot brought up to the fingers' modes and faults now (noted if changed).
void poll_status(Board& b);
void reply_written(uint8_t seq, uint8_t len);
// The reply waiting into the transmit buffer now, if it has room (a handler that has work left
// after its reply: the reply goes on the line meanwhile).
void flush_reply();
// Board time in microseconds (the tick count, refined by the tick timer).
uint32_t board_time_us();

}  // namespace app
}  // namespace utrf

#endif  // UTRF_CORE_APP_H
