#include "dispatch.h"

#include "../generated/protocol_messages.h"
#include "../hal/hal.h"
#include "encoder.h"
#include "fixed.h"
#include "kinematics.h"

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

// Q15 to the state message's hundredths, rounded half away from zero (x 200 / 65536: the
// shift is a byte move on the AVR).
int8_t hundredths(int16_t q15) {
    const int32_t v = (int32_t)(q15 < 0 ? -q15 : q15) * 200 + 32768;
    const int8_t h = (int8_t)(v >> 16);
    return q15 < 0 ? (int8_t)-h : h;
}

using app::Lock;

template <typename Msg>
bool reply(app::Board&, uint8_t seq, const Msg& m) {
    uint8_t body[kMaxPayload];
    const uint8_t n = encode(m, body);
    return app::queue_reply(seq, Msg::kId, body, n);
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

void set_targets(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    SetTargets m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    int16_t bu[kFingerCount];
    for (uint8_t f = 0; f < kFingerCount; ++f) {
        if (!(m.mask & (1u << f))) continue;
        float th;
        const finger::Params& p = b.hand.finger(f).params();
        if (!target_angle(m.kind, f, m.value[f], th)) {
            nack(b, seq, m.kId, (uint8_t)ErrorCode::OUT_OF_RANGE, (uint8_t)(0x80 | f));
            return;
        }
        const int32_t a = fx::round_sat(th * fx::kBuPerRad);
        // The exact limit is allowed: the float round trip may land a count beyond it.
        if (a < (int32_t)p.theta_min - 1 || a > (int32_t)p.theta_max + 1) {
            nack(b, seq, m.kId, (uint8_t)ErrorCode::OUT_OF_RANGE, (uint8_t)(0x80 | f));
            return;
        }
        bu[f] = (int16_t)fx::clamp32(a, p.theta_min, p.theta_max);
    }
    {
        Lock lock;
        for (uint8_t f = 0; f < kFingerCount; ++f) {
            if (m.mask & (1u << f)) b.hand.finger(f).set_target(bu[f]);
        }
    }
    ack(b, seq, m.kId);
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
    ack(b, seq, m.kId);
}

void set_telemetry(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    SetTelemetry m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    b.telemetry_hz = m.rate_hz;
    b.telemetry_acc = 0;
    b.telemetry_tick = b.hand.ticks();
    ack(b, seq, m.kId);
}

void get_gains(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    GetGains m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    Gains r;
    config::fill_gains(b.cfg.finger[m.finger].gains, m.finger, r);
    reply(b, seq, r);
}

void set_gains(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    SetGains m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    if (config_busy(b, seq, m.kId)) return;
    config::Gains g;
    g.kp = m.kp;
    g.ki = m.ki;
    g.kd = m.kd;
    g.d_cutoff_hz = m.d_cutoff_hz;
    g.deadband_milli = m.deadband_duty;
    g.slew_per_s = m.slew_per_s;
    g.max_duty_milli = m.max_duty;
    g.pretension_milli = m.pretension_duty;
    const uint8_t bad = config::check_gains(g);
    if (bad != 0xFF) {
        nack(b, seq, m.kId, (uint8_t)ErrorCode::OUT_OF_RANGE, bad);
        return;
    }
    b.cfg.finger[m.finger].gains = g;
    app::apply_finger_config(m.finger);
    ack(b, seq, m.kId);
}

void get_limits(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    GetLimits m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    Limits r;
    config::fill_limits(b.cfg.finger[m.finger].limits, m.finger, r);
    reply(b, seq, r);
}

void set_limits(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    SetLimits m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    if (config_busy(b, seq, m.kId)) return;
    config::Limits l;
    l.theta2_min = m.theta2_min;
    l.theta2_max = m.theta2_max;
    l.limit_margin = m.limit_margin;
    l.stall_error = m.stall_error;
    l.stall_motion = m.stall_motion;
    l.stall_time_ms = m.stall_time;
    l.encoder_jump = m.encoder_jump;
    const uint8_t bad = config::check_limits(m.finger, l);
    if (bad != 0xFF) {
        nack(b, seq, m.kId, (uint8_t)ErrorCode::OUT_OF_RANGE, bad);
        return;
    }
    b.cfg.finger[m.finger].limits = l;
    app::apply_finger_config(m.finger);
    ack(b, seq, m.kId);
}

void get_safety(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    GetSafety m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    Safety r;
    r.heartbeat_timeout = b.cfg.safety.heartbeat_timeout_ms;
    r.safe_action = b.cfg.safety.safe_action;
    reply(b, seq, r);
}

void set_safety(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    SetSafety m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    if (config_busy(b, seq, m.kId)) return;
    b.cfg.safety.heartbeat_timeout_ms = m.heartbeat_timeout;
    b.cfg.safety.safe_action = m.safe_action;
    {
        Lock lock;
        b.hand.set_safety(m.heartbeat_timeout, m.safe_action);
    }
    ack(b, seq, m.kId);
}

void get_finger_config(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    GetFingerConfig m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    FingerConfig r;
    config::fill_hardware(b.cfg.finger[m.finger].hw, m.finger, r);
    reply(b, seq, r);
}

void set_finger_config(app::Board& b, uint8_t seq, const uint8_t* body, uint8_t len) {
    SetFingerConfig m;
    if (!decode_or_nack(b, seq, body, len, m)) return;
    if (config_busy(b, seq, m.kId)) return;
    if (!b.hand.finger(m.finger).idle()) {
        nack(b, seq, m.kId, (uint8_t)ErrorCode::BUSY, m.finger);
        return;
    }
    config::Hardware& h = b.cfg.finger[m.finger].hw;
    h.actuation = m.actuation;
    h.encoder_offset = m.encoder_offset;
    h.encoder_invert = m.encoder_invert;
    h.motor_invert = m.motor_invert;
    app::apply_finger_config(m.finger);
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
    uint8_t out[kMaxPayload];
    const uint8_t n = encode_state(b, out);
    app::queue_reply(seq, State::kId, out, n);
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

uint8_t encode_state(app::Board& b, uint8_t* body) {
    // Copy under the lock (the tick waits meanwhile), convert after it.
    State s;
    int16_t duty_a[kFingerCount];
    int16_t duty_b[kFingerCount];
    uint32_t t;
    {
        Lock lock;
        t = b.hand.ticks();
        for (uint8_t f = 0; f < kFingerCount; ++f) {
            const finger::Finger& fg = b.hand.finger(f);
            s.theta2[f] = fg.theta();
            s.target[f] = fg.target();
            duty_a[f] = fg.duty_a();
            duty_b[f] = fg.duty_b();
            s.mode[f] = fg.mode();
            s.faults[f] = fg.faults();
        }
    }
    s.board_time = t * 1000UL;
    for (uint8_t f = 0; f < kFingerCount; ++f) {
        s.theta2[f] = fx::au_from_bu(s.theta2[f]);  // BU to the protocol's 1e-4 rad
        s.target[f] = fx::au_from_bu(s.target[f]);
        s.duty_a[f] = hundredths(duty_a[f]);
        s.duty_b[f] = hundredths(duty_b[f]);
        kin::tip_raw(kin::finger_geometry(f), s.theta2[f], s.tip_x[f], s.tip_y[f]);
    }
    return encode(s, body);
}

uint8_t encode_boot(const app::Board& b, uint8_t* body) {
    Boot m;
    m.protocol_version = kProtocolVersion;
    m.schema_hash = kSchemaHash;
    m.reset_cause = b.reset_cause;
    m.config_status = b.config_status;
    return encode(m, body);
}

void handle(app::Board& b, uint8_t seq, uint8_t msg_id, const uint8_t* body, uint8_t len) {
    // A halted board (its loop or tick hung: every motor off, a watchdog reset coming) drives
    // nothing again: say so rather than accept a command it will not carry out.
    if (b.hand.halted() && (msg_id == MsgId::SET_TARGETS || msg_id == MsgId::SET_MODE)) {
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
        case MsgId::SET_TARGETS: set_targets(b, seq, body, len); return;
        case MsgId::SET_MODE: set_mode(b, seq, body, len); return;
        case MsgId::SET_TELEMETRY: set_telemetry(b, seq, body, len); return;
        case MsgId::GET_GAINS: get_gains(b, seq, body, len); return;
        case MsgId::SET_GAINS: set_gains(b, seq, body, len); return;
        case MsgId::GET_LIMITS: get_limits(b, seq, body, len); return;
        case MsgId::SET_LIMITS: set_limits(b, seq, body, len); return;
        case MsgId::GET_SAFETY: get_safety(b, seq, body, len); return;
        case MsgId::SET_SAFETY: set_safety(b, seq, body, len); return;
        case MsgId::GET_FINGER_CONFIG: get_finger_config(b, seq, body, len); return;
        case MsgId::SET_FINGER_CONFIG: set_finger_config(b, seq, body, len); return;
        case MsgId::SAVE_CONFIG: save_config(b, seq, body, len); return;
        case MsgId::LOAD_CONFIG: load_config(b, seq, body, len); return;
        case MsgId::CALIBRATE_ZERO: calibrate_zero(b, seq, body, len); return;
        case MsgId::CLEAR_FAULTS: clear_faults(b, seq, body, len); return;
        case MsgId::GET_STATE: get_state(b, seq, body, len); return;
        case MsgId::GET_STATS: get_stats(b, seq, body, len); return;
        case MsgId::RESET_STATS: reset_stats(b, seq, body, len); return;
        default:
            nack(b, seq, msg_id, (uint8_t)ErrorCode::UNKNOWN_ID, kNoDetail);
            return;
    }
}

}  // namespace dispatch
}  // namespace utrf
