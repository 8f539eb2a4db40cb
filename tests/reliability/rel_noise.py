"""The noisy-line campaign: a Hand drives the emulated board (driven, simulated time) through
the emulator's seeded line faults and every command is checked against what the board did.

Commands, in turn: ``set_targets`` on one of fingers 0-3 (in POSITION), ``set_mode`` on the
little finger (BRAKE and COAST in turn, idle modes that keep the others' targets) and
``set_gains`` on the little finger (a new kp each time). Every value sent is distinct, so a
value the board shows can be traced to the command that sent it.

- **wrong applied**: the board shows (in the state stream, or in a read-back) a target, a mode
  or a kp that was never sent;
- **silent loss**: a command returned without error, but the board does not show its value
  (``get_state`` and ``get_status`` read back after it, or set_gains' own read-back);
- **errors**: a command raised (each is counted, with whether its value was applied after all);
- latency: simulated time from the call to its return (p50, p99, max).

The line's faults are per byte, both directions: the rate is split evenly between dropped
bytes, flipped bits, inserted bytes and (where the emulator has them) duplicated bytes, and
bursts of 8-32 random bytes start at rate / 100 per byte.

A target the board shows that was never sent is excused when the board applied HOST_TIMEOUT's
HOLD (it holds where the finger is): first seen as the measured angle (within HOLD_TOL), then
the same target for as long as it stays, clear_faults included, until the next set_targets
replaces it (the finger may be carried further than HOLD_TOL from it meanwhile). Counted as
``held_targets``, and only allowed in a campaign that saw a HOST_TIMEOUT.
"""

from __future__ import annotations

import inspect
import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from utrf.emulator import EmulatedBoard
from utrf.hand import Hand, HandState
from utrf.protocol import messages as M

HOLD_TOL = 0.03  # rad: a held finger stays this close to the target HOLD gave it
TARGET_TOL = 3e-4  # rad: the stream's target resolution (1e-4 rad) and the float rounding
TELEMETRY_HZ = 200


@dataclass
class NoiseResult:
    rate: float
    seed: int
    commands: int = 0
    wrong_applied: int = 0
    silent_losses: int = 0
    errors: int = 0
    errors_applied: int = 0  # of the errors: the value was applied after all
    error_kinds: dict[str, int] = field(default_factory=dict)
    latencies: list[float] = field(default_factory=list)
    stream_frames: int = 0
    host_timeouts: int = 0
    held_targets: int = 0
    host_timeout_events: list[dict[str, Any]] = field(default_factory=list)
    resends: int = 0
    line_faults: dict[str, int] = field(default_factory=dict)
    tx_frames: int = 0
    board_rx_frames: int = 0
    longest_tx_gap_s: float = 0.0
    recovered: bool = False
    recovery_ping_s: float = math.nan
    sim_seconds: float = 0.0
    notes: list[str] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        d = asdict(self)
        lat = np.asarray(self.latencies) if self.latencies else np.zeros(1)
        d.pop("latencies")
        d["p50_ms"] = float(np.percentile(lat, 50) * 1e3)
        d["p99_ms"] = float(np.percentile(lat, 99) * 1e3)
        d["max_ms"] = float(lat.max() * 1e3)
        return d


def line_faults(board: EmulatedBoard, rate: float) -> None:
    """``rate`` per byte, both directions, split between the kinds the emulator has."""
    params = inspect.signature(board.set_line_faults).parameters
    kinds = [k for k in ("drop", "corrupt", "insert", "duplicate") if k in params]
    kw: dict[str, float] = {k: rate / len(kinds) for k in kinds}
    if "burst" in params and rate:
        kw["burst"] = rate / 100  # 8-32 bytes each: about a fifth of the rate in bytes hit
    board.set_line_faults("both", **kw)


def _held(fs: Any) -> bool:
    """A finger's state shows HOST_TIMEOUT's HOLD: the fault latched, the target the angle."""
    return M.FaultBits.HOST_TIMEOUT in fs.faults and abs(fs.target - fs.theta2) <= HOLD_TOL


def _retry(fn: Any, attempts: int = 50) -> Any:
    for _ in range(attempts - 1):
        try:
            return fn()
        except Exception:
            continue
    return fn()


def _mode_cycle(k: int) -> M.ControlMode:
    return M.ControlMode.BRAKE if (k // 3) % 2 == 0 else M.ControlMode.COAST


def run_campaign(
    board: EmulatedBoard, hand: Hand, rate: float, commands: int, seed: int = 0
) -> NoiseResult:
    res = NoiseResult(rate=rate, seed=seed)
    rng = np.random.default_rng(seed)
    # On a clean line: fingers 0-3 in POSITION at 0, the little finger idle, the stream on.
    hand.set_telemetry(TELEMETRY_HZ)
    hand.set_targets({i: 0.0 for i in range(4)})
    hand.set_mode("coast", [4])
    kp0 = hand.gains(4).kp
    sent_targets: list[set[float]] = [{0.0} for _ in range(4)]
    held_targets: list[set[float]] = [set() for _ in range(4)]  # set by HOST_TIMEOUT's HOLD
    sent_modes = {M.ControlMode.COAST}
    sent_kp = {kp0}
    timed_out: list[float] = []  # when the stream first showed HOST_TIMEOUT, until cleared

    def trace(v: float, sent: set[float], tol: float) -> bool:
        return any(abs(v - s) <= tol for s in sent)

    def on_state(st: HandState) -> None:
        res.stream_frames += 1
        for i in range(4):
            if trace(st[i].target, sent_targets[i], TARGET_TOL):
                continue
            if abs(st[i].target - st[i].theta2) <= HOLD_TOL:
                # HOST_TIMEOUT's HOLD: the measured angle (the fault's report may come in a
                # later frame: the stream carries the faults only when they change)
                held_targets[i].add(st[i].target)
            if trace(st[i].target, held_targets[i], TARGET_TOL):
                # ... and the same target after clear_faults, until the next set_targets
                res.held_targets += 1
                continue
            res.wrong_applied += 1
            res.notes.append(f"stream: finger {i} target {st[i].target:.4f} never sent")
        if st.status_current and st[4].mode not in sent_modes:
            res.wrong_applied += 1
            res.notes.append(f"stream: finger 4 mode {st[4].mode.name} never sent")
        timeout = st.status_current and any(M.FaultBits.HOST_TIMEOUT in f.faults for f in st)
        if timeout and not timed_out:
            timed_out.append(board.sim_time)

    # When each frame went out (the longest silence the board could see from the host).
    tx_times: list[float] = []
    write = board.write

    def timed_write(data: bytes) -> int:
        tx_times.append(board.sim_time)
        return write(data)

    board.write = timed_write  # type: ignore[method-assign]
    unsubscribe = hand.on_state(on_state)
    stats0 = hand.link_stats()
    faults0 = board.stats
    board_rx0 = hand.stats().rx_frames
    t_start = board.sim_time
    line_faults(board, rate)
    try:
        for k in range(commands):
            kind = k % 3
            t0 = hand.clock.now()
            try:
                if kind == 0:
                    f = (k // 3) % 4
                    # distinct values on a 1 mrad grid: never within TARGET_TOL of another
                    while True:
                        v = round(float(rng.uniform(-0.3, 0.6)), 3)
                        if not trace(v, sent_targets[f], 2 * TARGET_TOL):
                            break
                    sent_targets[f].add(v)
                    hand.set_targets({f: v}, enable=False)
                    want: Any = ("target", f, v)
                elif kind == 1:
                    mode = _mode_cycle(k)
                    sent_modes.add(mode)
                    hand.set_mode(mode, [4])
                    want = ("mode", 4, mode)
                else:
                    kp = round(1.0 + 0.01 * (k // 3 + 1), 2)
                    sent_kp.add(kp)
                    back = hand.set_gains(4, kp=kp)
                    if abs(back.kp - kp) > 1e-5:
                        res.silent_losses += 1
                        res.notes.append(f"set_gains kp={kp} returned, board has {back.kp}")
                    if not trace(back.kp, sent_kp, 1e-5):
                        res.wrong_applied += 1
                    want = None
                failed = None
            except Exception as exc:
                failed = exc
                res.errors += 1
                name = type(exc).__name__
                res.error_kinds[name] = res.error_kinds.get(name, 0) + 1
                res.notes.append(f"command {k}: {exc!r}")
            res.latencies.append(hand.clock.now() - t0)
            res.commands += 1
            if timed_out:
                # The board heard no valid frame for heartbeat_timeout and applied the safe
                # action: what the host silences before it were, then clear and go on.
                before = [t for t in tx_times if t < timed_out[0]]
                res.host_timeout_events.append(
                    {
                        "command": k,
                        "at_s": timed_out[0] - t_start,
                        "host_tx_before_s": [round(t - timed_out[0], 4) for t in before[-6:]],
                    }
                )
                res.host_timeouts += 1
                _retry(lambda: hand.clear_faults())
                timed_out.clear()
            if want is None:
                continue
            # The board's state read back (get_state is answered after the command was
            # applied; a stream frame may carry a sample its tick took before).
            what, f, v = want
            st = _retry(hand.state)
            now_v = st[f].target if what == "target" else st[f].mode
            applied = abs(now_v - v) <= TARGET_TOL if what == "target" else now_v == v
            if failed is None and not applied and what == "target" and _held(st[f]):
                # The board heard nothing valid for heartbeat_timeout between the command's
                # reply and the read-back, and HOST_TIMEOUT's HOLD replaced the target: the
                # read-back says so (its stream frame may still be on its way).
                res.held_targets += 1
                continue
            if failed is None and not applied:
                res.silent_losses += 1
                res.notes.append(f"command {k} ({what} {v}) returned but the board shows {now_v}")
            if failed is not None and applied:
                res.errors_applied += 1
    finally:
        board.set_line_faults("both")
        res.sim_seconds = board.sim_time - t_start
        stats1 = hand.link_stats()
        res.resends = stats1.retries - stats0.retries
        board.write = write  # type: ignore[method-assign]
    gaps = np.diff(tx_times) if len(tx_times) > 1 else np.zeros(1)
    res.tx_frames = len(tx_times)
    res.longest_tx_gap_s = float(gaps.max())
    st = board.stats
    res.line_faults = {
        k: int(v) - int(faults0.get(k, 0))
        for k, v in st.items()
        if any(w in k for w in ("dropped", "corrupted", "inserted", "duplicat", "burst"))
    }
    # Recovery: the noise has stopped; the link answers at once and the hand obeys.
    try:
        t0 = hand.clock.now()
        hand.ping()
        res.recovery_ping_s = hand.clock.now() - t0
        sent_targets[0].add(0.1)
        hand.set_targets({0: 0.1}, enable=False)
        hand.clock.sleep(0.02)
        latest = hand.latest
        res.recovered = latest is not None and abs(latest[0].target - 0.1) <= TARGET_TOL
    except Exception as exc:
        res.notes.append(f"no recovery: {exc!r}")
    # Host frames the board took whole, of those sent (commands, resends, heartbeats).
    res.board_rx_frames = hand.stats().rx_frames - board_rx0
    unsubscribe()
    return res
