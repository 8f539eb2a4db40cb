// Firmware benchmark: runs build/firmware/utrf.elf on simavr's ATmega2560 and measures the
// control tick under protocol traffic, as the firmware itself reports it (get_stats:
// tick_worst, tick_mean, overruns), plus the telemetry it streams.
//
//   tick_bench <elf> <scenario> <seconds> [<tick entry> <tick return>]   prints one JSON object
//
// Scenarios (all five fingers in POSITION, encoders moving, 500 Hz telemetry):
//   idle      no requests beyond heartbeats (20 Hz)
//   typical   set_targets at 200 Hz
//   stress    set_targets back to back: the receive line saturated at 1 Mbaud
//   silent    nothing at all: after the heartbeat timeout (0.5 s by default) the safe action
//             (HOLD by default) takes every finger in one tick, the tick this row's worst shows
// The host's frames drift against the tick (its clock is not the board's): each period is a
// little longer than nominal, so that over a run of a second or more the frames start at every
// phase of the tick, the worst (a frame arriving while the tick runs) included.
// And `pins` (<seconds> unused): the driver pins and PWM timers through a sequence of modes,
// for tests/firmware/test_fw_avr.py to check against board_pins.h (the table the emulator's
// harness reads too).
//
// Frames are built and parsed with the firmware's own framing and generated messages, so the
// bench speaks exactly the protocol the firmware does.
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <algorithm>
#include <deque>
#include <vector>
#include <string>

#include <simavr/avr_adc.h>
#include <simavr/avr_uart.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_cycle_timers.h>
#include <simavr/sim_elf.h>

#include "board_pins.h"
#include "core/framing.h"
#include "generated/protocol_messages.h"

using namespace utrf;

namespace {

const double kCpuHz = 16e6;
const uint32_t kByteCycles = 160;  // 10 bits at 1 Mbaud
// The ATmega2560's vector table: 57 vectors of 4 bytes. The simulator leaves the PC there
// in the step that accepts an interrupt.
const uint32_t kVectorTableEnd = 57 * 4;
const uint16_t kSpl = 0x5D;  // SPL/SPH in data space
const uint32_t kTickVector = 13 * 4;  // TIMER2_COMPA

struct Bench {
    avr_t* avr = nullptr;
    std::deque<uint8_t> to_board;
    bool xon = true;
    uint64_t next_byte_cycle = 0;
    bool feeding = false;  // feed_byte() is scheduled
    avr_irq_t* uart_in = nullptr;
    framing::FrameDecoder decoder;
    uint8_t seq = 0;
    uint32_t state_frames = 0;
    uint32_t state_gaps = 0;
    int last_state_seq = -1;
    uint32_t nacks = 0;
    uint32_t faults = 0;
    bool have_stats = false;
    proto::Stats stats;
    // Independent measure from the simulator: cycles from app::tick()'s entry to the return
    // into the timer interrupt (addresses from the ELF, given on the command line).
    uint32_t tick_entry = 0;
    uint32_t tick_return = 0;
    uint64_t tick_start = 0;
    bool in_tick = false;
    uint64_t sim_ticks = 0;
    uint64_t sim_sum = 0;
    uint64_t sim_worst = 0;
    // Interrupts served while app::tick() runs (UART receive, timer 0, ...): their cycles are
    // part of the tick's elapsed time but not of its own work, so both are reported.
    int nest_depth = 0;
    uint16_t nest_sp[4];          // SP once each nested interrupt had pushed its return
    uint64_t nest_start[4];
    uint64_t tick_nested = 0;     // nested cycles in the running tick
    uint64_t sim_own_sum = 0;
    uint64_t sim_own_worst = 0;
    uint64_t sim_nested_sum = 0;
    uint64_t sim_nested_worst = 0;
    uint64_t sim_nested_count = 0;
    // The whole timer interrupt that runs the tick, from its vector to its reti: the tick plus
    // what surrounds it (register saves, the tick's own timing and bookkeeping).
    bool in_isr = false;
    uint16_t isr_sp = 0;
    uint64_t isr_start = 0;
    uint64_t isr_ticks_before = 0;
    uint64_t isr_count = 0;
    uint64_t isr_sum = 0;
    uint64_t isr_worst = 0;
    // Optional profile (UTRF_TICK_PROFILE=file): own cycles per instruction address, of the
    // tick and of the timer interrupt around it.
    std::vector<uint64_t> profile;
    // loop()'s passes (UTRF_LOOP_ENTRY=<hex byte address of app::loop()>): cycles from one
    // entry to the next, the worst and when it began; with UTRF_LOOP_PROFILE=file, cycles per
    // instruction address of the worst pass (interrupts included).
    uint32_t loop_entry = 0;
    uint64_t loop_start = 0;
    uint64_t loop_worst = 0;
    uint64_t loop_worst_at = 0;
    uint64_t loop_passes = 0;
    bool profile_all = false;  // UTRF_LOOP_PROFILE_ALL: every cycle of the run, not one pass
    bool measuring = false;
    std::vector<uint64_t> pass_profile;
    std::vector<uint32_t> pass_touched;  // addresses of pass_profile to clear at the next pass
    std::vector<std::pair<uint32_t, uint64_t>> worst_profile;
    // Round trips (the latency scenario): from the request's first byte on the line to its
    // reply's last byte off it, in cycles, per message id.
    int rt_seq = -1;          // the request waiting for its reply
    uint8_t rt_id = 0;
    uint64_t rt_start = 0;
    bool rt_started = false;  // its first byte went out
    std::vector<uint64_t> rt_ping, rt_targets;
    // Where a round trip's time goes (UTRF_DISPATCH_ENTRY=<hex byte address of
    // dispatch::handle()>): the request's last byte in, dispatch's entry, the reply frame's
    // first byte out; per request, the segments between them.
    uint32_t dispatch_entry = 0;
    uint64_t rt_last_in = 0;
    uint64_t rt_dispatch = 0;
    uint64_t out_frame_start = 0;  // the first byte of the frame coming out now
    bool out_in_frame = false;
    std::vector<uint64_t> seg_in, seg_notice, seg_reply, seg_out;
};

Bench g;

bool g_pins = false;         // the pins scenario holds the encoders still
int g_broken_encoder = -1;   // ... and may unplug one (0 V)

double angle(int finger, double t) {
    if (g_pins) return 0.0;
    // Each finger sweeps +-0.4 rad at 1.3 Hz, phase-shifted: the PIDs always have work.
    return 0.4 * sin(2 * M_PI * 1.3 * t + finger);
}

void adc_trigger(avr_irq_t*, uint32_t value, void*) {
    union {
        avr_adc_mux_t mux;
        uint32_t v;
    } e;
    e.v = value;
    const int ch = e.mux.src;
    if (ch < 0 || ch > 4) return;
    const double t = g.avr->cycle / kCpuHz;
    // AS5600 analog: 10 % of 5 V at 0, 90 % at one turn; straight finger mounted mid-band.
    double turn = fmod((angle(ch, t) + M_PI) / (2 * M_PI), 1.0);
    if (turn < 0) turn += 1.0;
    uint32_t mv = (uint32_t)lround(5000.0 * (0.1 + 0.8 * turn));
    if (ch == g_broken_encoder) mv = 0;
    avr_raise_irq(avr_io_getirq(g.avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC0 + ch), mv);
}

bool g_trace = false;
std::vector<uint64_t> g_notice_profile;  // UTRF_NOTICE_PROFILE=file
std::vector<uint64_t> g_dispatch_profile;  // UTRF_DISPATCH_PROFILE=file
uint32_t g_trace_pc = 0;
void uart_out(avr_irq_t*, uint32_t value, void*) {
    if (g_trace && g.rt_seq >= 0) fprintf(stderr, "  out %02x at %llu\n", value, (unsigned long long)(g.avr->cycle - g.rt_start));
    if (value != 0 && !g.out_in_frame) g.out_frame_start = g.avr->cycle;
    g.out_in_frame = value != 0;
    const framing::RxEvent ev = g.decoder.feed((uint8_t)value);
    if (ev != framing::RxEvent::FRAME) return;
    const uint8_t id = g.decoder.msg_id();
    if (g.rt_seq >= 0 && g.decoder.seq() == (uint8_t)g.rt_seq && g.rt_started) {
        const uint64_t c = g.avr->cycle - g.rt_start;
        (g.rt_id == proto::Ping::kId ? g.rt_ping : g.rt_targets).push_back(c);
        if (g_trace) fprintf(stderr, " reply %s done at %llu, its first byte at %llu\n", g.rt_id == proto::Ping::kId ? "ping" : "targets", (unsigned long long)c, (unsigned long long)(g.out_frame_start - g.rt_start));
        g.rt_seq = -1;
        if (g.dispatch_entry && g.rt_dispatch > g.rt_last_in) {
            g.seg_in.push_back(g.rt_last_in + kByteCycles - g.rt_start);
            g.seg_notice.push_back(g.rt_dispatch - (g.rt_last_in + kByteCycles));
            g.seg_reply.push_back(g.out_frame_start - g.rt_dispatch);
            g.seg_out.push_back(g.avr->cycle - g.out_frame_start);
        }
    }
    if (id == proto::MsgId::STATE && (g.decoder.seq() & proto::kBoardSeqFlag)) {
        ++g.state_frames;
        if (g.last_state_seq >= 0 && g.decoder.seq() != proto::next_board_seq((uint8_t)g.last_state_seq)) {
            ++g.state_gaps;
        }
        g.last_state_seq = g.decoder.seq();
    } else if (id == proto::MsgId::NACK) {
        ++g.nacks;
    } else if (id == proto::MsgId::FAULT) {
        ++g.faults;
    } else if (id == proto::MsgId::STATS) {
        uint8_t bad;
        g.have_stats = proto::decode(g.decoder.body(), g.decoder.body_len(), g.stats, bad) ==
                       proto::DecodeStatus::OK;
    }
}

void uart_xon(avr_irq_t*, uint32_t, void*) { g.xon = true; }

// The firmware's idle sleep (SLEEP until the next interrupt): simavr skips the cycles and
// reports them here; counted, and never paced to the wall clock.
uint64_t g_sleep_cycles = 0;
void count_sleep(avr_t*, avr_cycle_count_t how_long) { g_sleep_cycles += 1 + how_long; }

// One byte of the host's into the UART, one byte time after the last.
avr_cycle_count_t feed_byte(avr_t* avr, avr_cycle_count_t when, void*) {
    if (g.to_board.empty() || !g.xon) {
        g.feeding = false;
        return 0;
    }
    if (g_trace && g.rt_seq >= 0) fprintf(stderr, "  in at %llu\n", (unsigned long long)(when - g.rt_start));
    if (g.rt_seq >= 0 && !g.rt_started) {
        g.rt_started = true;
        g.rt_start = when;
    }
    avr_raise_irq(g.uart_in, g.to_board.front());
    g.to_board.pop_front();
    if (g.rt_seq >= 0 && g.to_board.empty()) {
        g.rt_last_in = when;
        if (g_trace) fprintf(stderr, " last in at %llu\n", (unsigned long long)(when - g.rt_start));
    }
    g.next_byte_cycle = when + kByteCycles;
    (void)avr;
    if (g.to_board.empty()) {
        g.feeding = false;
        return 0;
    }
    return when + kByteCycles;
}
void uart_xoff(avr_irq_t*, uint32_t, void*) { g.xon = false; }

template <typename Msg>
void send(const Msg& msg) {
    uint8_t body[proto::kMaxPayload] = {0};
    uint8_t frame[framing::kMaxFrameBytes];
    const uint8_t n = proto::encode(msg, body);
    g.seq = (uint8_t)((g.seq + 1) & 0x7F);
    const uint8_t len = framing::encode_frame(g.seq, Msg::kId, body, n, frame);
    for (uint8_t i = 0; i < len; ++i) g.to_board.push_back(frame[i]);
}

void run_until(double t_end) {
    const uint64_t end = (uint64_t)ceil(t_end * kCpuHz);  // up, so that it always advances
    avr_irq_t* in = avr_io_getirq(g.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    while (g.avr->cycle < end) {
        const uint32_t pc0 = g.avr->pc;
        const uint64_t c0 = g.avr->cycle;
        // This step's instruction runs as the tick's own work, or the timer interrupt's around it.
        const bool own_step = (g.in_tick && g.nest_depth == 0) || (g.in_isr && !g.in_tick);
        // An interrupt ends with the reti that finds the stack where its entry left it (SP is
        // not watched for that: a function's epilogue writes SPH and SPL one at a time).
        const bool reti = (g.avr->flash[pc0] | (g.avr->flash[pc0 + 1] << 8)) == 0x9518;
        const uint16_t sp0 = (uint16_t)(g.avr->data[kSpl] | (g.avr->data[kSpl + 1] << 8));
        const int st = avr_run(g.avr);
        if (st == cpu_Done || st == cpu_Crashed) {
            fprintf(stderr, "tick_bench: the simulated CPU stopped (state %d)\n", st);
            exit(1);
        }
        if (g.tick_entry) {
            const uint16_t sp = (uint16_t)(g.avr->data[kSpl] | (g.avr->data[kSpl + 1] << 8));
            if (g.in_isr && reti && sp0 == g.isr_sp) {
                g.in_isr = false;
                if (g.sim_ticks > g.isr_ticks_before) {  // it ran a tick (not just deferred one)
                    const uint64_t c = g.avr->cycle - g.isr_start;
                    ++g.isr_count;
                    g.isr_sum += c;
                    if (c > g.isr_worst) g.isr_worst = c;
                }
            }
            if (!g.in_isr && !g.in_tick && g.avr->pc == kTickVector) {
                g.in_isr = true;
                g.isr_sp = sp;
                g.isr_start = c0;
                g.isr_ticks_before = g.sim_ticks;
            }
            if (g.in_tick) {
                if (g.nest_depth > 0 && reti && sp0 == g.nest_sp[g.nest_depth - 1]) {
                    --g.nest_depth;
                    g.tick_nested += g.avr->cycle - g.nest_start[g.nest_depth];
                    ++g.sim_nested_count;
                }
                if (g.avr->pc < kVectorTableEnd && g.nest_depth < 4) {
                    // Accepted in this step: the step (the instruction before it too, a few
                    // cycles) counts as the interrupt's.
                    g.nest_sp[g.nest_depth] = sp;
                    g.nest_start[g.nest_depth] = c0;
                    ++g.nest_depth;
                }
            }
            if (own_step && g.avr->pc >= kVectorTableEnd && !g.profile.empty() &&
                pc0 < g.profile.size()) {
                g.profile[pc0] += g.avr->cycle - c0;
            }
            if (g_trace && g.rt_seq >= 0 && g.rt_started && g.avr->pc == g.tick_entry && !g.in_tick)
                fprintf(stderr, " tick at %llu\n", (unsigned long long)(g.avr->cycle - g.rt_start));
            if (g_trace && g.rt_seq >= 0 && g.rt_started && g.avr->pc == g.tick_return && g.in_tick && g.nest_depth == 0)
                fprintf(stderr, " tickend at %llu\n", (unsigned long long)(g.avr->cycle - g.rt_start));
            if (g.avr->pc == g.tick_entry && !g.in_tick) {
                g.in_tick = true;
                g.tick_start = g.avr->cycle;
                g.tick_nested = 0;
                g.nest_depth = 0;
            } else if (g.avr->pc == g.tick_return && g.in_tick && g.nest_depth == 0) {
                g.in_tick = false;
                const uint64_t c = g.avr->cycle - g.tick_start;
                const uint64_t own = c - g.tick_nested;
                ++g.sim_ticks;
                g.sim_sum += c;
                if (c > g.sim_worst) g.sim_worst = c;
                g.sim_own_sum += own;
                if (own > g.sim_own_worst) g.sim_own_worst = own;
                g.sim_nested_sum += g.tick_nested;
                if (g.tick_nested > g.sim_nested_worst) g.sim_nested_worst = g.tick_nested;
            }
        }
        if (!g_notice_profile.empty() && g.rt_seq >= 0 && g.rt_last_in &&
            g.rt_dispatch <= g.rt_last_in && pc0 < g_notice_profile.size()) {
            g_notice_profile[pc0] += g.avr->cycle - c0;  // the notice segment's cycles
        }
        if (!g_dispatch_profile.empty() && g.rt_seq >= 0 && g.rt_last_in &&
            g.rt_dispatch > g.rt_last_in && pc0 < g_dispatch_profile.size()) {
            g_dispatch_profile[pc0] += g.avr->cycle - c0;  // from dispatch to the reply's end
        }
        if (g_trace && g_trace_pc && g.avr->pc == g_trace_pc && g.rt_seq >= 0)
            fprintf(stderr, " pc at %llu\n", (unsigned long long)(g.avr->cycle - g.rt_start));
        if (g.dispatch_entry && g.avr->pc == g.dispatch_entry && g.rt_seq >= 0 &&
            g.rt_dispatch <= g.rt_last_in) {
            g.rt_dispatch = g.avr->cycle;
            if (g_trace) fprintf(stderr, " dispatch at %llu\n", (unsigned long long)(g.avr->cycle - g.rt_start));
        }
        if (g.loop_entry) {
            if (!g.pass_profile.empty() && pc0 < g.pass_profile.size()) {
                if (g.pass_profile[pc0] == 0) g.pass_touched.push_back(pc0);
                g.pass_profile[pc0] += g.avr->cycle - c0;
            }
            if (g.avr->pc == g.loop_entry) {
                if (g_trace && g.rt_seq >= 0 && g.rt_started) fprintf(stderr, " loop at %llu\n", (unsigned long long)(g.avr->cycle - g.rt_start));
                const uint64_t c = g.avr->cycle - g.loop_start;
                if (g.measuring && g.loop_start) {
                    ++g.loop_passes;
                    if (c > g.loop_worst) {
                        g.loop_worst = c;
                        g.loop_worst_at = g.loop_start;
                        g.worst_profile.clear();
                        for (uint32_t a : g.pass_touched) g.worst_profile.push_back({a, g.pass_profile[a]});
                    }
                }
                if (!g.profile_all) {
                    for (uint32_t a : g.pass_touched) g.pass_profile[a] = 0;
                    g.pass_touched.clear();
                }
                g.loop_start = g.avr->cycle;
            }
        }
        if (!g.feeding && !g.to_board.empty() && g.xon) {
            // The host's bytes on simavr's clock (a cycle timer: exact even while the firmware
            // sleeps, when one step of the simulator skips many cycles).
            g.feeding = true;
            g.uart_in = in;
            const uint64_t at = std::max<uint64_t>(g.next_byte_cycle, g.avr->cycle + 1);
            avr_cycle_timer_register(g.avr, at - g.avr->cycle, feed_byte, nullptr);
        }
    }
}

proto::SetTargets targets(double t) {
    proto::SetTargets m;
    m.kind = (uint8_t)proto::TargetKind::JOINT2_ANGLE;
    m.mask = 0x1F;
    for (int f = 0; f < 5; ++f) m.value[f] = (int32_t)lround(angle(f, t + 0.05) * 1e6);
    return m;
}

// ---- the pins scenario ----------------------------------------------------------------------
// ATmega2560 data-space addresses (the datasheet's register summary).
uint16_t port_addr(char port) {
    switch (port) {
        case 'A': return 0x22;
        case 'B': return 0x25;
        case 'C': return 0x28;
        case 'D': return 0x2B;
        case 'E': return 0x2E;
        case 'F': return 0x31;
        case 'G': return 0x34;
        case 'H': return 0x102;
        case 'J': return 0x105;
        case 'K': return 0x108;
        default: return 0x10B;
    }
}
uint16_t tccra_addr(int timer) {
    return timer == 1 ? 0x80 : timer == 3 ? 0x90 : timer == 4 ? 0xA0 : 0x120;
}
uint8_t rd(uint16_t a) { return g.avr->data[a]; }
uint16_t rd16(uint16_t a) { return (uint16_t)(rd(a) | (rd((uint16_t)(a + 1)) << 8)); }
int pin(const utrf_pin_t& p) { return (rd(port_addr(p.port)) >> p.bit) & 1; }
int ddr(const utrf_pin_t& p) { return (rd((uint16_t)(port_addr(p.port) - 1)) >> p.bit) & 1; }

void print_motor(const utrf_motor_pins_t& m) {
    const uint16_t a = tccra_addr(m.pwm.timer);
    const int ch = m.pwm.channel - 'A';
    const uint8_t tccra = rd(a), tccrb = rd((uint16_t)(a + 1));
    const int wgm = (tccra & 3) | ((tccrb >> 1) & 0x0C);
    printf("{\"com\": %d, \"ocr\": %u, \"icr\": %u, \"wgm\": %d, \"cs\": %d, \"in1\": %d, "
           "\"in2\": %d, \"pwm_pin\": %d, \"outputs\": %d}",
           (tccra >> (6 - 2 * ch)) & 3, rd16((uint16_t)(a + 8 + 2 * ch)), rd16((uint16_t)(a + 6)),
           wgm, tccrb & 7, pin(m.in1), pin(m.in2), pin(m.pwm.pin),
           ddr(m.in1) && ddr(m.in2) && ddr(m.pwm.pin));
}

void print_pins(const char* label) {
    printf("%s\"%s\": [", strcmp(label, "boot") == 0 ? "" : ", ", label);
    for (int f = 0; f < UTRF_FINGER_COUNT; ++f) {
        const utrf_finger_pins_t& p = UTRF_FINGER_PINS[f];
        printf("%s{\"stby\": %d, \"stby_out\": %d, \"a\": ", f ? ", " : "", pin(p.stby),
               ddr(p.stby));
        print_motor(p.a);
        printf(", \"b\": ");
        print_motor(p.b);
        printf("}");
    }
    printf("]");
}

proto::SetMode all_modes(uint8_t mode, int16_t duty_milli) {
    proto::SetMode m;
    m.mask = 0x1F;
    for (int f = 0; f < 5; ++f) {
        m.mode[f] = mode;
        m.duty[f] = duty_milli;
        m.effort[f] = 0;
    }
    return m;
}

int run_pins() {
    g_pins = true;
    run_until(0.05);
    printf("{");
    print_pins("boot");
    double t = 0.05;
    send(proto::Heartbeat());
    // 80 ms a phase: the default slew limit (20 /s) takes the duty there within 50 ms.
    send(all_modes((uint8_t)proto::ControlMode::DUTY, 500));
    run_until(t += 0.08);
    print_pins("duty_plus");
    send(all_modes((uint8_t)proto::ControlMode::DUTY, -500));
    run_until(t += 0.08);
    print_pins("duty_minus");
    send(all_modes((uint8_t)proto::ControlMode::BRAKE, 0));
    run_until(t += 0.02);
    print_pins("brake");
    send(all_modes((uint8_t)proto::ControlMode::COAST, 0));
    run_until(t += 0.02);
    print_pins("coast");
    send(all_modes((uint8_t)proto::ControlMode::DUTY, 500));
    run_until(t += 0.08);
    g_broken_encoder = 2;  // finger 2's encoder unplugged: its driver goes off
    run_until(t += 0.003);
    print_pins("encoder_fault");
    const uint8_t tccr2a = rd(0xB0), tccr2b = rd(0xB1), ocr2a = rd(0xB3), timsk2 = rd(0x70);
    printf(", \"timer2\": {\"tccr2a\": %u, \"tccr2b\": %u, \"ocr2a\": %u, \"timsk2\": %u}",
           tccr2a, tccr2b, ocr2a, timsk2);
    printf(", \"ubrr0\": %u, \"ucsr0a\": %u}\n", rd16(0xC4), rd(0xC0));
    return 0;
}

// The tick-alive rule, to the cycle: at 0.3 s + `phase` seconds timer 2's clock is stopped
// (TCCR2B's clock select cleared, as the emulator's stop_tick_timer does); the time from the
// last tick's entry (and from the stop) until every STBY pin is low. Needs the tick's entry
// address (argv 4).
int run_tickdead(double phase) {
    run_until(0.3 + phase);
    const uint64_t stop = g.avr->cycle;
    // TCCR2B: CS22..CS20 = 0, written through the timer's own register hook.
    const uint8_t tccr2b = (uint8_t)(g.avr->data[0xB1] & ~0x07);
    const avr_io_addr_t io = AVR_DATA_TO_IO(0xB1);
    if (g.avr->io[io].w.c) {
        g.avr->io[io].w.c(g.avr, 0xB1, tccr2b, g.avr->io[io].w.param);
    } else {
        g.avr->data[0xB1] = tccr2b;
    }
    const uint64_t last_tick = g.tick_start;
    const uint64_t limit = stop + (uint64_t)(0.05 * kCpuHz);
    while (g.avr->cycle < limit) {
        run_until((g.avr->cycle + 1) / kCpuHz);
        bool any = false;
        for (int f = 0; f < UTRF_FINGER_COUNT; ++f) any = any || pin(UTRF_FINGER_PINS[f].stby);
        if (!any) {
            printf("{\"scenario\": \"tickdead\", \"from_stop_ms\": %.4f, \"from_last_tick_ms\": "
                   "%.4f}\n", (g.avr->cycle - stop) / kCpuHz * 1e3,
                   (g.avr->cycle - last_tick) / kCpuHz * 1e3);
            return 0;
        }
    }
    fprintf(stderr, "tick_bench: the motors stayed on 50 ms after the tick stopped\n");
    return 1;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 4 && argc != 6) {
        fprintf(stderr,
                "usage: tick_bench <elf> idle|typical|stress|silent|pins <seconds> [<tick entry> "
                "<tick return>] (byte addresses, hex)\n");
        return 2;
    }
    if (argc == 6) {
        g.tick_entry = (uint32_t)strtoul(argv[4], nullptr, 16);
        g.tick_return = (uint32_t)strtoul(argv[5], nullptr, 16);
    }
    const std::string scenario = argv[2];
    const double seconds = atof(argv[3]);
    if (scenario != "idle" && scenario != "typical" && scenario != "stress" &&
        scenario != "silent" && scenario != "pins" && scenario != "moves" &&
        scenario != "tickdead" &&
        scenario != "latency") {
        fprintf(stderr, "tick_bench: unknown scenario %s\n", scenario.c_str());
        return 2;
    }
    elf_firmware_t fw;
    memset(&fw, 0, sizeof fw);
    if (elf_read_firmware(argv[1], &fw) != 0) {
        fprintf(stderr, "tick_bench: cannot read %s\n", argv[1]);
        return 1;
    }
    g.avr = avr_make_mcu_by_name("atmega2560");
    if (!g.avr) return 1;
    avr_init(g.avr);
    avr_load_firmware(g.avr, &fw);
    g.avr->frequency = (uint32_t)kCpuHz;
    g.avr->vcc = g.avr->avcc = g.avr->aref = 5000;
    g.avr->log = 0;
    g.avr->sleep = count_sleep;

    uint32_t flags = 0;
    avr_ioctl(g.avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
    flags &= ~AVR_UART_FLAG_STDIO;
    avr_ioctl(g.avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    avr_irq_register_notify(avr_io_getirq(g.avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_OUT_TRIGGER),
                            adc_trigger, nullptr);
    avr_irq_register_notify(avr_io_getirq(g.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                            uart_out, nullptr);
    avr_irq_register_notify(avr_io_getirq(g.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON),
                            uart_xon, nullptr);
    avr_irq_register_notify(avr_io_getirq(g.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF),
                            uart_xoff, nullptr);

    if (scenario == "pins") return run_pins();

    // Boot, then every finger into closed loop and the stream on.
    run_until(0.1);
    send(proto::Heartbeat());
    send(targets(0.1));
    proto::SetMode mode;
    mode.mask = 0x1F;
    for (int f = 0; f < 5; ++f) {
        mode.mode[f] = (uint8_t)proto::ControlMode::POSITION;
        mode.duty[f] = 0;
        mode.effort[f] = 0;
    }
    send(mode);
    proto::SetTelemetry tel;
    tel.rate_hz = (scenario == "moves" || scenario == "latency") ? 1000 : 500;
    send(tel);
    run_until(0.3);
    if (scenario == "tickdead") return run_tickdead(seconds);
    send(proto::ResetStats());
    run_until(0.31);
    g.sim_ticks = g.sim_sum = g.sim_worst = 0;
    g.sim_own_sum = g.sim_own_worst = g.sim_nested_sum = g.sim_nested_worst = 0;
    g.sim_nested_count = 0;
    g.isr_count = g.isr_sum = g.isr_worst = 0;
    const char* profile_path = getenv("UTRF_TICK_PROFILE");
    if (profile_path && *profile_path) g.profile.assign(256 * 1024, 0);
    const char* loop_entry = getenv("UTRF_LOOP_ENTRY");
    if (loop_entry && *loop_entry) g.loop_entry = (uint32_t)strtoul(loop_entry, nullptr, 16);
    const char* loop_profile = getenv("UTRF_LOOP_PROFILE");
    if (g.loop_entry && loop_profile && *loop_profile) g.pass_profile.assign(256 * 1024, 0);
    g.profile_all = getenv("UTRF_LOOP_PROFILE_ALL") != nullptr;
    g_trace = getenv("UTRF_TRACE") != nullptr;
    if (getenv("UTRF_TRACE_PC")) g_trace_pc = (uint32_t)strtoul(getenv("UTRF_TRACE_PC"), nullptr, 16);
    const char* notice_path = getenv("UTRF_NOTICE_PROFILE");
    if (notice_path && *notice_path) g_notice_profile.assign(256 * 1024, 0);
    const char* dispatch_path = getenv("UTRF_DISPATCH_PROFILE");
    if (dispatch_path && *dispatch_path) g_dispatch_profile.assign(256 * 1024, 0);
    const char* dispatch_entry = getenv("UTRF_DISPATCH_ENTRY");
    if (dispatch_entry && *dispatch_entry) {
        g.dispatch_entry = (uint32_t)strtoul(dispatch_entry, nullptr, 16);
    }
    g.measuring = true;
    const uint64_t sleep_before = g_sleep_cycles;
    const uint64_t cycles_before = g.avr->cycle;
    uint16_t move_id = 0;
    const uint32_t frames_before = g.state_frames;
    const uint32_t gaps_before = g.state_gaps;
    const double t0 = g.avr->cycle / kCpuHz;
    const double t_end = t0 + seconds;
    double next_send = t0;
    bool waiting = false;  // the latency row: a request is out
    double phase = 0.0;
    while (g.avr->cycle / kCpuHz < t_end) {
        const double t = g.avr->cycle / kCpuHz;
        if (scenario == "stress") {
            if (g.to_board.size() < 64) send(targets(t));
            run_until(t + 0.0005);
        } else if (scenario == "moves") {
            // A move of all five fingers every 0.4 s (0.3 s paths, ends alternating), set_targets
            // at 100 Hz in between would end them: heartbeats at 20 Hz instead.
            if (t >= next_send) {
                const int k = (int)lround((next_send - t0) / 0.05 + 40e-6);
                if (k % 8 == 0) {
                    proto::Move m;
                    m.move_id = ++move_id;
                    m.kind = (uint8_t)proto::TargetKind::JOINT2_ANGLE;
                    m.mask = 0x1F;
                    for (int f = 0; f < 5; ++f) {
                        m.value[f] = (move_id & 1) ? 600000 : -300000;
                        m.duration[f] = 300;
                    }
                    send(m);
                } else {
                    send(proto::Heartbeat());
                }
                next_send += 0.05 + 40e-6;
            }
            run_until(next_send < t + 0.0005 ? next_send : t + 0.0005);
        } else if (scenario == "latency") {
            // One request at a time, ping and set_targets in turn, each sent when the last one
            // was answered plus 0.5-3 ms (a fixed irrational-ish step: every phase of the
            // tick and of the stream comes round).
            if (waiting && g.rt_seq < 0) {
                // Answered: the next one 0.5-3 ms after the reply, the step irrational so that
                // the requests sample every phase of the tick and of the stream evenly (a
                // fixed gap after the reply would lock onto one phase). Ahead of the send below:
                // after it, the last next_send, long past, sent the next request at once (back
                // to back, some 20 us after the reply, the row's first version).
                waiting = false;
                phase = fmod(phase + 0.6180339887, 1.0);
                next_send = g.avr->cycle / kCpuHz + 0.0005 + 0.0025 * phase;
            }
            if (g.rt_seq < 0 && t >= next_send) {
                g.rt_started = false;
                if ((g.rt_ping.size() + g.rt_targets.size()) % 2 == 0) {
                    send(proto::Ping());
                    g.rt_id = proto::Ping::kId;
                } else {
                    send(targets(t));
                    g.rt_id = proto::SetTargets::kId;
                }
                g.rt_seq = g.seq;
                waiting = true;
            }
            run_until(g.avr->cycle / kCpuHz + 0.00002);
        } else if (scenario == "silent") {
            run_until(t + 0.0005);
        } else {
            if (t >= next_send) {
                if (scenario == "typical") {
                    send(targets(t));
                    next_send += 0.005 + 4e-6;  // the phase drifts 0.8 ms a second
                } else {
                    send(proto::Heartbeat());
                    next_send += 0.05 + 40e-6;  // 0.8 ms a second
                }
            }
            // Up to the next frame's time exactly: it starts then, at its own phase.
            run_until(next_send < t + 0.0005 ? next_send : t + 0.0005);
        }
    }
    const double asleep = (double)(g_sleep_cycles - sleep_before) /
                          (double)(g.avr->cycle - cycles_before);
    const uint32_t frames = g.state_frames - frames_before;
    const uint32_t gaps = g.state_gaps - gaps_before;
    const uint64_t sim_ticks = g.sim_ticks;
    const uint64_t sim_worst = g.sim_worst;
    const double sim_mean = sim_ticks ? (double)g.sim_sum / (double)sim_ticks : 0.0;
    const double sim_own_mean = sim_ticks ? (double)g.sim_own_sum / (double)sim_ticks : 0.0;
    const double sim_nested_mean = sim_ticks ? (double)g.sim_nested_sum / (double)sim_ticks : 0.0;
    const uint64_t sim_own_worst = g.sim_own_worst;
    const uint64_t sim_nested_worst = g.sim_nested_worst;
    const uint64_t sim_nested_count = g.sim_nested_count;
    const double isr_mean = g.isr_count ? (double)g.isr_sum / (double)g.isr_count : 0.0;
    const uint64_t isr_worst = g.isr_worst;
    const uint64_t isr_ticks = g.isr_count;
    if (!g.profile.empty()) {
        FILE* pf = fopen(profile_path, "w");
        if (!pf) {
            fprintf(stderr, "tick_bench: cannot write %s\n", profile_path);
            return 1;
        }
        fprintf(pf, "# byte address, own cycles in the tick's interrupt over %llu ticks\n",
                (unsigned long long)sim_ticks);
        for (size_t a = 0; a < g.profile.size(); ++a) {
            if (g.profile[a]) fprintf(pf, "%zx %llu\n", a, (unsigned long long)g.profile[a]);
        }
        fclose(pf);
        g.profile.clear();
    }
    g.measuring = false;
    if (g.profile_all) {
        g.worst_profile.clear();
        for (uint32_t a : g.pass_touched) g.worst_profile.push_back({a, g.pass_profile[a]});
    }
    auto pct = [](std::vector<uint64_t> v, double q) -> double {
        if (v.empty()) return 0.0;
        std::sort(v.begin(), v.end());
        const size_t i = (size_t)std::min<double>(v.size() - 1, floor(q * (v.size() - 1) + 0.5));
        return v[i] / kCpuHz * 1e6;
    };
    char rt[1024] = "";
    if (scenario == "latency") {
        int n = snprintf(rt, sizeof rt,
                 ", \"ping_n\": %zu, \"ping_median_us\": %.1f, \"ping_p99_us\": %.1f, "
                 "\"ping_max_us\": %.1f, \"targets_n\": %zu, \"targets_median_us\": %.1f, "
                 "\"targets_p99_us\": %.1f, \"targets_max_us\": %.1f",
                 g.rt_ping.size(), pct(g.rt_ping, 0.5), pct(g.rt_ping, 0.99), pct(g.rt_ping, 1.0),
                 g.rt_targets.size(), pct(g.rt_targets, 0.5), pct(g.rt_targets, 0.99),
                 pct(g.rt_targets, 1.0));
        // The segments, both requests together: median and 99th percentile of each.
        const std::vector<uint64_t>* segs[] = {&g.seg_in, &g.seg_notice, &g.seg_reply, &g.seg_out};
        const char* names[] = {"in", "notice", "reply", "out"};
        for (int k = 0; k < 4 && !g.seg_in.empty(); ++k) {
            n += snprintf(rt + n, sizeof rt - n, ", \"seg_%s_median_us\": %.1f, \"seg_%s_p99_us\": %.1f",
                          names[k], pct(*segs[k], 0.5), names[k], pct(*segs[k], 0.99));
        }
    }
    if (!g_notice_profile.empty()) {
        FILE* pf = fopen(notice_path, "w");
        if (pf) {
            fprintf(pf, "# byte address, cycles between requests' last byte and dispatch\n");
            for (size_t a = 0; a < g_notice_profile.size(); ++a) {
                if (g_notice_profile[a]) fprintf(pf, "%zx %llu\n", a, (unsigned long long)g_notice_profile[a]);
            }
            fclose(pf);
        }
    }
    if (!g_dispatch_profile.empty()) {
        FILE* pf = fopen(dispatch_path, "w");
        if (pf) {
            fprintf(pf, "# byte address, cycles between dispatch's entry and the reply's end\n");
            for (size_t a = 0; a < g_dispatch_profile.size(); ++a) {
                if (g_dispatch_profile[a]) fprintf(pf, "%zx %llu\n", a, (unsigned long long)g_dispatch_profile[a]);
            }
            fclose(pf);
        }
    }
    if (!g.worst_profile.empty()) {
        FILE* pf = fopen(loop_profile, "w");
        if (!pf) {
            fprintf(stderr, "tick_bench: cannot write %s\n", loop_profile);
            return 1;
        }
        fprintf(pf, "# byte address, cycles in loop()'s longest pass (%llu cycles)\n",
                (unsigned long long)g.loop_worst);
        for (const auto& e : g.worst_profile) {
            fprintf(pf, "%x %llu\n", e.first, (unsigned long long)e.second);
        }
        fclose(pf);
    }
    // Let the board work off what it has received, then ask for its counters. A lone 0x00
    // first ends whatever partial frame the board holds (the queue was cut mid-frame).
    g.to_board.clear();
    run_until(g.avr->cycle / kCpuHz + 0.05);
    g.to_board.push_back(0x00);
    send(proto::GetStats());
    run_until(g.avr->cycle / kCpuHz + 0.02);
    if (!g.have_stats) {
        fprintf(stderr, "tick_bench: no stats reply\n");
        return 1;
    }
    const proto::Stats& s = g.stats;
    printf("{\"scenario\": \"%s\", \"seconds\": %.3f, \"ticks\": %u, \"tick_overruns\": %u, "
           "\"tick_worst_us\": %u, \"tick_mean_us\": %u, \"rx_frames\": %u, "
           "\"rx_crc_errors\": %u, \"rx_framing_errors\": %u, \"rx_overruns\": %u, "
           "\"nacks\": %u, \"tx_dropped\": %u, \"state_frames\": %u, \"state_seq_gaps\": %u, "
           "\"fault_frames\": %u, \"sim_ticks\": %llu, \"sim_tick_worst_cycles\": %llu, "
           "\"sim_tick_mean_cycles\": %.1f, \"sim_own_worst_cycles\": %llu, "
           "\"sim_own_mean_cycles\": %.1f, \"sim_nested_worst_cycles\": %llu, "
           "\"sim_nested_mean_cycles\": %.1f, \"sim_nested_interrupts\": %llu, "
           "\"sim_isr_mean_cycles\": %.1f, \"sim_isr_worst_cycles\": %llu, "
           "\"sim_isr_ticks\": %llu, \"loop_passes\": %llu, \"loop_worst_cycles\": %llu, "
           "\"loop_worst_at_s\": %.6f, \"asleep\": %.4f%s}\n",
           scenario.c_str(), seconds, (unsigned)s.ticks, (unsigned)s.tick_overruns,
           (unsigned)s.tick_worst, (unsigned)s.tick_mean, (unsigned)s.rx_frames,
           (unsigned)s.rx_crc_errors, (unsigned)s.rx_framing_errors, (unsigned)s.rx_overruns,
           (unsigned)s.nacks, (unsigned)s.tx_dropped, (unsigned)frames, (unsigned)gaps,
           (unsigned)g.faults, (unsigned long long)sim_ticks, (unsigned long long)sim_worst,
           sim_mean, (unsigned long long)sim_own_worst, sim_own_mean,
           (unsigned long long)sim_nested_worst, sim_nested_mean,
           (unsigned long long)sim_nested_count, isr_mean, (unsigned long long)isr_worst,
           (unsigned long long)isr_ticks, (unsigned long long)g.loop_passes,
           (unsigned long long)g.loop_worst, g.loop_worst_at / kCpuHz, asleep, rt);
    return 0;
}
