#include "dispatch.h"

#include <string.h>

#include "../generated/protocol_messages.h"
#include "../hal/hal.h"
#include "encoder.h"
#include "fixed.h"
#include "kinematics.h"
#include "path.h"

namespace utrf {
namespace dispatch {

using namespace proto;

static_assert(kFingerCount == hand::kFingers, "the protocol and the firmware count fingers alike");
static_assert((uint8_t)ControlMode::GRASP == finger::GRASP &&
                  (uint8_t)ControlMode::DUTY == finger::DUTY &&
                  (uint8_t)ControlMode::POSITION == finger::POSITION &&
                  (uint8_t)ControlMode::BRAKE == finger::BRAKE,
              "finger modes are the protocol's ControlMode values");
static_assert(FaultBits::ENCODER_RANGE == finger::ENCODER_RANGE &&
                  FaultBits::ENCODER_JUMP == finger::ENCODER_JUMP &&
                  FaultBits::STALL == finger::STALL && FaultBits::JOINT_LIMIT == finger::JOINT_LIMIT &&
                  FaultBits::HOST_TIMEOUT == finger::HOST_TIMEOUT &&
                  FaultBits::OVERRUN == finger::OVERRUN,
              "finger faults are the protocol's FaultBits");
static_assert((uint8_t)ConfigStatus::DEFAULTS_VERSION == (uint8_t)config::LoadStatus::DEFAULTS_VERSION,
              "config load status values are the protocol's ConfigStatus");

namespace {

const uint8_t kNoDetail = 0xFF;

// Protocol thousandths to Q15 (1000 -> 32767).
int16_t q15_from_milli(int32_t milli) {
    return fx::sat16((milli * fx::kOne15 + (milli < 0 ? -500 : 500)) / 1000);
}

using fx::duty_counts;
using app::Lock;

template <typename T>
struct RemoveRef {
    typedef T Type;
};
template <typename T>
struct RemoveRef<T&> {
    typedef T Type;
};

// A reply written straight into the reply slot (CRC and COBS as the bytes come).
template <typename Msg>
bool reply(app::Board&, uint8_t seq, const Msg& m) {
    uint8_t* slot = app::reply_slot();
    if (slot == 0) return false;
    framing::FrameWriter w(slot, seq, Msg::kId);
    write(w, m);
    app::reply_written(seq, w.finish());
    return true;
}

// Decode or nack: returns true when `out` holds a valid request.
template <typename Msg>
bool decode_or_nack(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len, Msg& out) {
    uint8_t bad = kNoDetail;
    const DecodeStatus st = decode(body, len, out, bad);
    if (st == DecodeStatus::OK) return true;
    if (st == DecodeStatus::BAD_LENGTH) {
        nack(b, seq, Msg::kId, (uint8_t)ErrorCode::BAD_LENGTH, Msg::kSize);
    } else {
        nack(b, seq, Msg::kId, (uint8_t)ErrorCode::OUT_OF_RANGE, bad);
    }
    return false;
}

bool config_busy(app::Board& b, uint8_t seq, uint8_t msg_id) {
    if (!b.writer.busy()) return false;
    nack(b, seq, msg_id, (uint8_t)ErrorCode::BUSY, kNoDetail);
    return true;
}

// ---- requests ----------------------------------------------------------------------------------

void identify(app::Board& b, uint8_t seq) {
    Identity m;
    m.protocol_version = kProtocolVersion;
    m.schema_hash = kSchemaHash;
    m.fw_major = app::kFwMajor;
    m.fw_minor = app::kFwMinor;
    m.fw_patch = app::kFwPatch;
#ifdef UTRF_BUILD_ID
    m.build_id = UTRF_BUILD_ID;
#else
    m.build_id = 0;
#endif
    m.finger_count = kFingerCount;
    for (uint8_t f = 0; f < kFingerCount; ++f) m.actuation[f] = b.cfg.finger[f].hw.actuation;
    m.loop_rate_hz = hand::kTickHz;
    m.reset_cause = b.reset_cause;
    m.config_status = b.config_status;
    m.max_telemetry_hz = kMaxTelemetryHz;
    reply(b, seq, m);
}

// The Joint-2 angle a set_targets value stands for; false when it is off the finger's range.
bool target_angle(uint8_t kind, uint8_t f, int32_t raw, float& theta2) {
    const uint8_t geo = kin::finger_geometry(f);
    const float v = (float)raw * SetTargets::kValueScale;
    switch ((TargetKind)kind) {
        case TargetKind::JOINT2_ANGLE:
            theta2 = v;
            return true;
        case TargetKind::TENDON_Q:
            return kin::theta2_from_q(geo, v, theta2);
        case TargetKind::FLEXION:
            if (!(v >= 0.0f && v <= 1.0f)) return false;
            return kin::theta2_from_q(geo, v * kin::q_full_flexion(geo), theta2);
    }
    return false;
}

// A target in the unit of `kind` to BU (not yet clamped to the finger's limits); kNoTarget
// when it has none. JOINT2_ANGLE in integers, the others through the kinematics (floats).
// The float path out of line: its frame (registers saved for the float calls) is not paid by
// the integer one, which set_targets and move take five times.
const int32_t kNoTarget = 0x7FFFFFFF;
__attribute__((noinline)) int32_t kin_target_bu(uint8_t kind, uint8_t f, int32_t raw) {
    float th;
    return target_angle(kind, f, raw, th) ? fx::round_sat(th * fx::kBuPerRad) : kNoTarget;
}
inline int32_t target_bu(uint8_t kind, uint8_t f, int32_t raw) {
    if (kind == (uint8_t)TargetKind::JOINT2_ANGLE) {
        return raw >= -kMaxUrad && raw <= kMaxUrad ? bu_from_urad(raw) : kNoTarget;
    }
    return kin_target_bu(kind, f, raw);
}

// The targets of the fingers in `mask` (in `kind`'s unit) as setpoints, BU, by the target range
// rule (finger::Params::accepts()): set_targets' and move's. False, with a nack naming the
// first finger beyond its limits, when one is: nothing is set.
bool setpoints(app::Board& b, uint8_t seq, uint8_t msg_id, uint8_t kind, uint8_t mask,
               const int32_t* value, int16_t* out) {
    uint8_t bit = 1;  // the finger's bit of the mask (a shift by f is a loop on the AVR)
    for (uint8_t f = 0; f < kFingerCount; ++f, bit = (uint8_t)(bit << 1)) {
        if (!(mask & bit)) continue;
        const finger::Params& p = b.hand.finger(f).params();
        const int32_t a = target_bu(kind, f, value[f]);
        if (!p.accepts(a)) {
            nack(b, seq, msg_id, (uint8_t)ErrorCode::OUT_OF_RANGE, (uint8_t)(0x80 | f));
            return false;
        }
        out[f] = p.clamp(a);
    }
    return true;
}

// The frequent requests (set_targets, ping) are functions of their own, not inlined into
// handle(), whose frame is sized for every handler.
// JOINT2_ANGLE targets (the usual kind) take the fast path: checked against each finger's
// window of values (target_window(), in micro-radians, exactly the values the general rule,
// setpoints(), accepts), so the ack goes out before they are converted and set, and the
// conversion runs while the ack is on the line. Nothing else runs in between: a request after
// this one finds the targets set.
__attribute__((noinline)) void set_targets(app::Board& b, uint8_t seq, const uint8_t* body,
                                           uint8_t len) {
    SetTargets m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    int16_t bu[kFingerCount];
    uint8_t bit = 1;  // the finger's bit of the mask (a shift by f is a loop on the AVR)
    const bool angle = m.kind == (uint8_t)TargetKind::JOINT2_ANGLE;
    if (angle) {
        for (uint8_t f = 0; f < kFingerCount; ++f, bit = (uint8_t)(bit << 1)) {
            if ((m.mask & bit) && (m.value[f] < b.urad_lo[f] || m.value[f] > b.urad_hi[f])) {
                nack(b, seq, m.kId, (uint8_t)ErrorCode::OUT_OF_RANGE, (uint8_t)(0x80 | f));
                return;
            }
        }
        b.move_memo = false;  // the paths it ends cannot be resumed by a resent move
        ack(b, seq, m.kId);
        app::flush_reply();
        bit = 1;
        for (uint8_t f = 0; f < kFingerCount; ++f, bit = (uint8_t)(bit << 1)) {
            if (!(m.mask & bit)) continue;
            const finger::Params& p = b.hand.finger(f).params();
            bu[f] = p.clamp(bu_from_urad(m.value[f]));
        }
    } else if (!setpoints(b, seq, m.kId, m.kind, m.mask, m.value, bu)) {
        return;
    }
    {
        Lock lock;
        bit = 1;
        for (uint8_t f = 0; f < kFingerCount; ++f, bit = (uint8_t)(bit << 1)) {
            if (m.mask & bit) b.hand.finger(f).set_target(bu[f]);
        }
    }
    if (angle) return;
    b.move_memo = false;
    ack(b, seq, m.kId);
}

// ---- move: a path per finger on the board's clock (core/path.h) -------------------------------

static_assert(sizeof(((app::Board*)0)->move_body) == Move::kSize &&
                  sizeof(((app::Board*)0)->move_reply) == Moving::kSize,
              "the move memo holds one move and its reply");

void move(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    Move m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    // A resend of the last move (same seq and bytes: the host lost the reply): the same
    // reply, and the paths under way go on.
    if (b.move_memo && b.move_seq == seq && memcmp(b.move_body, body, Move::kSize) == 0) {
        app::queue_reply(seq, Moving::kId, b.move_reply, Moving::kSize);
        return;
    }
    int16_t end[kFingerCount];
    if (!setpoints(b, seq, m.kId, m.kind, m.mask, m.value, end)) return;
    // The paths start from the setpoints in use: read them (a moving finger's changes a few
    // counts before its new path starts, which moves its start by as much), plan outside the
    // lock, then check the modes again and start them under one lock.
    int16_t from[kFingerCount];
    {
        Lock lock;
        for (uint8_t f = 0; f < kFingerCount; ++f) from[f] = b.hand.finger(f).target();
    }
    path::Plan plan[kFingerCount];
    Moving r;
    r.move_id = m.move_id;
    r.stretched = 0;
    for (uint8_t f = 0; f < kFingerCount; ++f) {
        r.duration[f] = 0;
        if (!(m.mask & (1u << f))) continue;
        const float d = (float)(int16_t)(end[f] - from[f]) * (1.0f / fx::kBuPerRad);
        plan[f] = path::plan(d, (float)m.duration[f] * Move::kDurationScale, end[f], b.motion[f]);
        r.duration[f] = plan[f].ticks;  // ms: one tick is 1 ms
        app::keep_stream();
        if (plan[f].stretched) r.stretched |= (uint8_t)(1u << f);
    }
    static_assert(hand::kTickHz == 1000, "moving.duration counts ticks as ms");
    uint8_t code = 0;
    uint8_t detail = kNoDetail;
    {
        Lock lock;
        for (uint8_t f = 0; f < kFingerCount && code == 0; ++f) {
            if (!(m.mask & (1u << f))) continue;
            const finger::Finger& fg = b.hand.finger(f);
            if (fg.faults() != 0) {
                code = (uint8_t)ErrorCode::FAULTED;
                detail = f;
            } else if (fg.mode() != finger::POSITION && fg.mode() != finger::GRASP) {
                code = (uint8_t)ErrorCode::BUSY;
                detail = f;
            }
        }
        if (code == 0) {
            for (uint8_t f = 0; f < kFingerCount; ++f) {
                // first segments of 1..5 ticks: the fingers' segment ends fall on
                // different ticks (core/path.h)
                if (m.mask & (1u << f)) b.hand.finger(f).start_path(plan[f], (uint8_t)(f + 1));
            }
        }
    }
    if (code != 0) {
        nack(b, seq, m.kId, code, detail);
        return;
    }
    b.hand.plan_paths();  // the first segments, before the next tick if it can
    b.move_seq = seq;
    memcpy(b.move_body, body, Move::kSize);
    encode(r, b.move_reply);
    b.move_memo = true;
    reply(b, seq, r);
}

void set_mode(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    SetMode m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    int16_t duty[kFingerCount];
    int16_t effort[kFingerCount];
    for (uint8_t f = 0; f < kFingerCount; ++f) {  // divisions outside the lock
        duty[f] = q15_from_milli(m.duty[f]);
        effort[f] = q15_from_milli(m.effort[f]);
    }
    uint8_t refused = kNoDetail;
    {
        // Check and apply under one lock: a fault the tick latches in between cannot slip by.
        // The tick waits meanwhile, so nothing in here may take long.
        Lock lock;
        for (uint8_t f = 0; f < kFingerCount && refused == kNoDetail; ++f) {
            if (!(m.mask & (1u << f))) continue;
            const bool drives = m.mode[f] == (uint8_t)ControlMode::POSITION ||
                                m.mode[f] == (uint8_t)ControlMode::DUTY ||
                                m.mode[f] == (uint8_t)ControlMode::GRASP;
            const finger::Finger& fg = b.hand.finger(f);
            if (drives && (fg.faults() != 0 || !fg.has_theta())) refused = f;
        }
        if (refused == kNoDetail) {
            for (uint8_t f = 0; f < kFingerCount; ++f) {
                if (!(m.mask & (1u << f))) continue;
                b.hand.finger(f).set_mode(m.mode[f], duty[f], effort[f]);
            }
        }
    }
    if (refused != kNoDetail) {
        nack(b, seq, m.kId, (uint8_t)ErrorCode::FAULTED, refused);
        return;
    }
    b.move_memo = false;  // as set_targets
    ack(b, seq, m.kId);
}

void set_telemetry(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    SetTelemetry m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    {
        Lock lock;
        b.hand.set_stream(m.rate_hz);
    }
    ack(b, seq, m.kId);
}

// ---- configuration: one get and one set handler for every [[config]] block of the spec ----

// What a set_ request needs besides its checks (true: go on), and what its change does.
bool may_set(app::Board&, uint8_t, const SetGains&) { return true; }
bool may_set(app::Board&, uint8_t, const SetLimits&) { return true; }
bool may_set(app::Board&, uint8_t, const SetSafety&) { return true; }
bool may_set(app::Board&, uint8_t, const SetMotion&) { return true; }
bool may_set(app::Board& b, uint8_t seq, const SetFingerConfig& m) {
    if (b.hand.finger(m.finger).idle()) return true;
    nack(b, seq, m.kId, (uint8_t)ErrorCode::BUSY, m.finger);
    return false;
}

void applied(app::Board&, const SetGains& m) { app::apply_finger_config(m.finger); }
void applied(app::Board&, const SetLimits& m) { app::apply_finger_config(m.finger); }
void applied(app::Board&, const SetFingerConfig& m) { app::apply_finger_config(m.finger); }
void applied(app::Board&, const SetMotion& m) { app::apply_motion(m.finger); }
void applied(app::Board& b, const SetSafety&) {
    Lock lock;
    b.hand.set_safety(b.cfg.safety.heartbeat_timeout, b.cfg.safety.safe_action);
}

template <typename Get, typename Reply>
void get_config(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    Get m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    Reply r;
    config::reply_of(b.cfg, m, r);
    reply(b, seq, r);
}

template <typename Set>
void set_config(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    Set m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    if (config_busy(b, seq, m.kId)) return;
    if (!may_set(b, seq, m)) return;
    typename RemoveRef<decltype(config::slot(b.cfg, m))>::Type v = config::slot(b.cfg, m);
    config::take(m, v);
    const uint8_t bad = config::check(m, v);
    if (bad != 0xFF) {
        nack(b, seq, m.kId, (uint8_t)ErrorCode::OUT_OF_RANGE, bad);
        return;
    }
    config::slot(b.cfg, m) = v;
    applied(b, m);
    ack(b, seq, m.kId);
}

void save_config(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    SaveConfig m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    if (config_busy(b, seq, m.kId)) return;
    b.writer.start(b.cfg);
    b.save_seq = seq;  // the ack goes out when the write is done (app::loop)
}

void load_config(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    LoadConfig m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    if (config_busy(b, seq, m.kId)) return;
    for (uint8_t f = 0; f < kFingerCount; ++f) {
        if (!b.hand.finger(f).idle()) {
            nack(b, seq, m.kId, (uint8_t)ErrorCode::BUSY, f);
            return;
        }
    }
    if (m.source == (uint8_t)ConfigSource::DEFAULTS) {
        config::defaults(b.cfg);
        b.config_status = (uint8_t)ConfigStatus::DEFAULTS_REQUESTED;
    } else {
        b.config_status = (uint8_t)config::load(b.cfg);
    }
    app::apply_all_config();
    ack(b, seq, m.kId);
}

void calibrate_zero(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    CalibrateZero m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    if (config_busy(b, seq, m.kId)) return;
    const uint8_t enc_faults = finger::ENCODER_RANGE | finger::ENCODER_JUMP;
    uint16_t turn[kFingerCount];
    uint8_t code = 0;
    uint8_t detail = kNoDetail;
    {
        Lock lock;
        for (uint8_t f = 0; f < kFingerCount && code == 0; ++f) {
            if (!(m.mask & (1u << f))) continue;
            const finger::Finger& fg = b.hand.finger(f);
            if (!fg.idle()) {
                code = (uint8_t)ErrorCode::BUSY;
                detail = f;
            } else if ((fg.faults() & enc_faults) || !fg.encoder_ok() || !fg.has_theta()) {
                code = (uint8_t)ErrorCode::FAULTED;
                detail = f;
            }
            turn[f] = fg.last_turn();
        }
    }
    if (code != 0) {
        nack(b, seq, m.kId, code, detail);
        return;
    }
    for (uint8_t f = 0; f < kFingerCount; ++f) {
        if (!(m.mask & (1u << f))) continue;
        b.cfg.finger[f].hw.encoder_offset = encoder::rad_from_turn(turn[f]);
        app::apply_finger_config(f);
    }
    ack(b, seq, m.kId);
}

void clear_faults(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    ClearFaults m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    {
        Lock lock;
        for (uint8_t f = 0; f < kFingerCount; ++f) {
            if (m.mask & (1u << f)) b.hand.finger(f).clear_faults();
        }
    }
    ack(b, seq, m.kId);
}

void get_state(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    GetState m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    uint8_t* slot = app::reply_slot();
    if (slot == 0) return;
    hand::StateSample s;
    uint8_t mode[kFingerCount];
    uint8_t faults[kFingerCount];
    {
        // Copy under the lock (the tick waits meanwhile), write after it.
        Lock lock;
        s.tick = (uint16_t)b.hand.ticks();
        for (uint8_t f = 0; f < kFingerCount; ++f) {
            const finger::Finger& fg = b.hand.finger(f);
            s.theta[f] = fg.theta();
            s.target[f] = fg.target();
            s.duty_a[f] = fg.duty_a();
            s.duty_b[f] = fg.duty_b();
            mode[f] = fg.mode();
            faults[f] = fg.faults();
        }
    }
    // The status the sample belongs to: a change seen here is numbered before the reply.
    app::note_status(b, mode, faults);
    app::reply_written(seq, write_state_frame(b, seq, s, slot));
}

void get_status(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    GetStatus m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    app::poll_status(b);  // a fault the tick latched since this pass began is in the reply
    Status r;
    fill_status(b, r);
    reply(b, seq, r);
}

uint16_t us_from_cycles(uint32_t cycles) {
    const uint32_t us = (cycles + hal::kCpuHz / 2000000UL) / (hal::kCpuHz / 1000000UL);
    return (uint16_t)(us > 65535u ? 65535u : us);
}

void get_stats(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    GetStats m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    hand::TickTiming t;
    {
        Lock lock;
        t = b.hand.timing();
    }
    Stats r;
    r.rx_frames = b.link.rx_frames;
    r.rx_crc_errors = b.link.rx_crc_errors;
    r.rx_framing_errors = b.link.rx_framing_errors;
    r.rx_overruns = b.link.rx_overruns;
    r.nacks = b.link.nacks;
    r.tx_dropped = b.link.tx_dropped;
    r.ticks = t.ticks;
    r.tick_overruns = t.overruns;
    r.tick_worst = us_from_cycles(t.worst_cycles);
    r.tick_mean = us_from_cycles(t.mean_cycles);
    r.rx_ignored = b.link.rx_ignored;
    r.rx_repeats = b.link.rx_repeats;
    r.uart_overruns = b.link.uart_overruns;
    r.uart_frame_errors = b.link.uart_frame_errors;
    reply(b, seq, r);
}

void reset_stats(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    ResetStats m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    b.link = app::LinkStats();
    {
        Lock lock;
        b.hand.reset_timing();
    }
    ack(b, seq, m.kId);
}

}  // namespace

void nack(app::Board& b, uint8_t seq, uint8_t msg_id, uint8_t code, uint8_t detail) {
    Nack m;
    m.msg_id = msg_id;
    m.code = code;
    m.detail = detail;
    ++b.link.nacks;
    reply(b, seq, m);
}

void ack(app::Board& b, uint8_t seq, uint8_t msg_id) {
    Ack m;
    m.msg_id = msg_id;
    reply(b, seq, m);
}

uint8_t write_state_frame(app::Board& b, uint8_t seq, const hand::StateSample& s, uint8_t* out,
                          uint8_t start) {
    // The angles go out in the board's own units and the duties as their rounded high bytes
    // (the sample has them in Q15: the tick only copies).
    framing::FrameWriter w(out, start, seq, State::kId);
    put_u16(w, s.tick);
    w.put(b.status_change);
    for (uint8_t f = 0; f < kFingerCount; ++f) put_i16(w, s.theta[f]);
    for (uint8_t f = 0; f < kFingerCount; ++f) put_i16(w, s.target[f]);
    for (uint8_t f = 0; f < kFingerCount; ++f) w.put((uint8_t)duty_counts(s.duty_a[f]));
    for (uint8_t f = 0; f < kFingerCount; ++f) w.put((uint8_t)duty_counts(s.duty_b[f]));
    return w.finish();
}

namespace {
// The smallest x in [-kMaxUrad, kMaxUrad + 1] with bu_from_urad(x) >= t (kMaxUrad + 1: none).
// bu_from_urad(x) rounds x / 191.7476 (micro-radians a count), so x >= (t - 1/2) 191.7476 to
// within the float's rounding: start there and step to the exact boundary (a step or two).
int32_t first_at_least(int32_t t) {
    const float kUradPerBu = 191.74759848f;  // 2 pi 1e6 / 32768
    float e = ((float)t - 0.5f) * kUradPerBu;
    if (e < -(float)kMaxUrad) e = -(float)kMaxUrad;
    if (e > (float)kMaxUrad) e = (float)kMaxUrad;
    int32_t x = (int32_t)e;
    while (x > -kMaxUrad && bu_from_urad(x - 1) >= t) --x;
    while (x <= kMaxUrad && bu_from_urad(x) < t) ++x;
    return x;
}
}  // namespace

void target_window(int16_t theta_min, int16_t theta_max, int32_t& lo, int32_t& hi) {
    // bu_from_urad() never decreases: the accepted values are one interval of
    // [-kMaxUrad, kMaxUrad].
    lo = first_at_least((int32_t)theta_min - 1);
    hi = first_at_least((int32_t)theta_max + 2) - 1;
}

void fill_status(const app::Board& b, Status& m) {
    m.change = b.status_change;
    for (uint8_t f = 0; f < kFingerCount; ++f) {
        m.mode[f] = b.status_mode[f];
        m.faults[f] = b.status_faults[f];
    }
}

void fill_boot(const app::Board& b, Boot& m) {
    m.protocol_version = kProtocolVersion;
    m.schema_hash = kSchemaHash;
    m.reset_cause = b.reset_cause;
    m.config_status = b.config_status;
}

void handle(app::Board& b, uint8_t seq, uint8_t msg_id, const uint8_t* body, uint8_t len) {
    // A halted board (its loop or tick hung: every motor off, a watchdog reset coming) drives
    // nothing again: say so rather than accept a command it will not carry out.
    if (b.hand.halted() && (msg_id == MsgId::SET_TARGETS || msg_id == MsgId::SET_MODE ||
                              msg_id == MsgId::MOVE)) {
        nack(b, seq, msg_id, (uint8_t)ErrorCode::HALTED, 0);
        return;
    }
    switch (msg_id) {
        case MsgId::IDENTIFY: {
            Identify m;
            if (decode_or_nack(b, seq, body, len, m)) identify(b, seq);
            return;
        }
        case MsgId::PING: {
            Ping m;
            if (!decode_or_nack(b, seq, body, len, m)) return;
            Pong r;
            r.token = m.token;
            r.board_time = app::board_time_us();
            reply(b, seq, r);
            return;
        }
        case MsgId::HEARTBEAT: {
            Heartbeat m;
            if (decode_or_nack(b, seq, body, len, m)) ack(b, seq, msg_id);
            return;
        }
        case MsgId::GOODBYE: {
            Goodbye m;
            if (!decode_or_nack(b, seq, body, len, m)) return;
            {
                Lock lock;
                b.hand.host_left();  // after take_request's note_frame(): this frame feeds nothing
            }
            b.request_seq = -1;  // not cached: a resend does this again (a lost ack re-arms nothing)
            ack(b, seq, msg_id);
            return;
        }
        case MsgId::SET_TARGETS: set_targets(b, seq, body, len); return;
        case MsgId::SET_MODE: set_mode(b, seq, body, len); return;
        case MsgId::MOVE: move(b, seq, body, len); return;
        case MsgId::SET_TELEMETRY: set_telemetry(b, seq, body, len); return;
#define UTRF_SET_CASE(Msg, ID) \
    case MsgId::ID: set_config<Msg>(b, seq, body, len); return;
#define UTRF_GET_CASE(Msg, ID, Reply) \
    case MsgId::ID: get_config<Msg, Reply>(b, seq, body, len); return;
        UTRF_CONFIG_SETS(UTRF_SET_CASE)
        UTRF_CONFIG_GETS(UTRF_GET_CASE)
#undef UTRF_SET_CASE
#undef UTRF_GET_CASE
        case MsgId::SAVE_CONFIG: save_config(b, seq, body, len); return;
        case MsgId::LOAD_CONFIG: load_config(b, seq, body, len); return;
        case MsgId::CALIBRATE_ZERO: calibrate_zero(b, seq, body, len); return;
        case MsgId::CLEAR_FAULTS: clear_faults(b, seq, body, len); return;
        case MsgId::GET_STATE: get_state(b, seq, body, len); return;
        case MsgId::GET_STATS: get_stats(b, seq, body, len); return;
        case MsgId::GET_STATUS: get_status(b, seq, body, len); return;
        case MsgId::RESET_STATS: reset_stats(b, seq, body, len); return;
        default:
            nack(b, seq, msg_id, (uint8_t)ErrorCode::UNKNOWN_ID, 0);
            return;
    }
}

}  // namespace dispatch
}  // namespace utrf
