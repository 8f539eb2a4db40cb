"""The dashboard's goals, measured (``make bench-dashboard``; results in docs/benchmarks.md):

- Live: from a board sample to its pixels in the page, with the 1 kHz stream on. In headless
  chromium a probe watches the page's newest-sample label (its board time mapped to the
  host's wall clock by the server: ``DashboardHub.wall_time_of``) and takes the time after
  the frame that drew it (``requestAnimationFrame`` then a task): p50, p99, worst.
- The server's CPU with the stream on and one page open (psutil, user+system over the window,
  as a fraction of one core), with the board emulated in another process (``utrf emulate``).
- The page's frame rate in headless chromium (``requestAnimationFrame`` callbacks a second)
  and how many live updates it drew a second.

The hand moves all along (a pose, then another, clicked on the page). The machine is shared
and loaded: its load average is printed beside the figures.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

import numpy as np
import psutil
from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import WebDriverWait

from tools.doc_sections import cpu_name, write_section
from utrf.dashboard import hub as dashboard_hub
from utrf.dashboard.server import ServerOptions

REPO = Path(__file__).resolve().parents[1]
BENCH_DOC = REPO / "docs" / "benchmarks.md"
BEGIN = "<!-- BEGIN dashboard (make bench-dashboard) -->"
END = "<!-- END dashboard -->"
FLAGS = [
    *("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run"),
    *("--disable-background-networking", "--disable-component-update", "--disable-sync"),
    "--enable-unsafe-swiftshader",
    "--window-size=1400,1000",
]
STATUS = "return fetch('/api/status').then(r => r.text())"
# The probe (measurement only, not part of the page): the time after each frame that drew a
# new sample, minus that sample's time on the wall clock, and when that frame was drawn. It
# asks for a frame only when the page changed: a requestAnimationFrame loop would make
# chromium draw 60 frames a second for nothing (the page's own updates come at most 30 times a
# second), and that drawing took the CPU the board, the server and the page need.
PROBE = """
window.utrfLat = []; window.utrfParts = []; window.utrfDrawn = [];
const el = document.querySelector('.utrf-sample-wall');
new MutationObserver(() => {
  const [wall, pushed] = el.textContent.split(' ').map(Number);
  const seen = performance.timeOrigin + performance.now();
  requestAnimationFrame(() => setTimeout(() => {
    const now = performance.timeOrigin + performance.now();
    window.utrfLat.push(now - wall);
    window.utrfParts.push([pushed - wall, seen - pushed, now - seen]);
    window.utrfDrawn.push([now, wall]);
  }, 0));
}).observe(el, {childList: true, characterData: true, subtree: true});
"""
# The page's frame rate, after the latency window (the stream on, the page as before): a
# requestAnimationFrame loop, which has chromium draw every frame it can (what the page can
# draw a second, not what it needs to).
FRAME_PROBE = """
window.utrfFrames = [];
const frame = (t) => { window.utrfFrames.push(t); requestAnimationFrame(frame); };
requestAnimationFrame(frame);
"""
#: the poses the page clicks in turn during the latency window, one every POSE_S seconds
POSES = ("fist", "open", "point", "open")
POSE_S = 5.0
#: the latency window (s): at 20 s the p99 of about 500 samples drawn was the 5th worst, and
#: moved by 10 ms from run to run on a quiet machine; at 60 s it is the 15th of about 1500
WINDOW_S = 60.0
#: seconds of the frame-rate window
FRAME_WINDOW_S = 5.0


def display_age(drawn: np.ndarray) -> np.ndarray:
    """What a person sees: the age of the newest sample on the page at every millisecond
    between the first and last frame that drew one (``drawn``: rows of (frame's wall time,
    its sample's wall time), ms), from the samples drawn, so the probe need not draw a frame
    every 16 ms to look."""
    if len(drawn) < 2:
        return np.array([])
    drawn = drawn[np.argsort(drawn[:, 0])]
    t = np.arange(drawn[0, 0], drawn[-1, 0], 1.0)
    i = np.searchsorted(drawn[:, 0], t, side="right") - 1
    return t - drawn[i, 1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start(cmd: list[str], log: Path) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if k != "PYTEST_CURRENT_TEST"}
    return subprocess.Popen(cmd, stdout=log.open("w"), stderr=subprocess.STDOUT, env=env)


def wait_for(test: object, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not test():  # type: ignore[operator]
        if time.monotonic() > deadline:
            raise SystemExit(f"bench-dashboard: {what} did not come up in {timeout:g} s")
        time.sleep(0.2)


def cpu_s(p: psutil.Process) -> float:
    t = p.cpu_times()
    return float(t.user + t.system)


def thread_cpu_s(p: psutil.Process) -> dict[int, float]:
    """Each thread's user + system time (the main thread's id is the process's)."""
    return {t.id: float(t.user_time + t.system_time) for t in p.threads()}


def named_thread_cpu_s(procs: list[psutil.Process]) -> dict[str, float]:
    """The CPU time (user + system, s) of these processes' threads, summed by thread name
    (``CrRendererMain``, ``Compositor``, ``CompositorTileW``, ...; Linux only)."""
    out: dict[str, float] = {}
    for p in procs:
        for t in p.threads():
            try:
                name = Path(f"/proc/{p.pid}/task/{t.id}/comm").read_text().strip()
            except OSError:
                continue
            out[name] = out.get(name, 0.0) + t.user_time + t.system_time
    return out


def browser_kinds(procs: list[psutil.Process]) -> dict[int, str]:
    """Each of chromium's processes by its ``--type`` (renderer, gpu-process, ...; the
    browser process has none)."""
    out = {}
    for p in procs:
        try:
            args = p.cmdline()
        except psutil.Error:
            continue
        kind = next((a.split("=", 1)[1] for a in args if a.startswith("--type=")), "browser")
        out[p.pid] = kind
    return out


def page_metrics(driver: webdriver.Chrome) -> dict[str, float]:
    """The page's counters from the DevTools protocol (``Performance.getMetrics``: the main
    thread's task, script, style and layout time in seconds, ...)."""
    out = driver.execute_cdp_cmd("Performance.getMetrics", {})
    return {m["name"]: float(m["value"]) for m in out["metrics"]}


def profile_summary(profile: dict, top: int = 25) -> list[tuple[float, str]]:
    """The JavaScript CPU profile (``Profiler.stop``) as self time per function, in ms,
    largest first, each named with its script's file and line."""
    nodes = {n["id"]: n for n in profile["nodes"]}
    self_us: dict[int, float] = {}
    for node_id, dt in zip(profile["samples"], profile["timeDeltas"], strict=True):
        self_us[node_id] = self_us.get(node_id, 0.0) + dt
    by_name: dict[str, float] = {}
    for node_id, us in self_us.items():
        f = nodes[node_id]["callFrame"]
        name = f"{f['functionName'] or '(anon)'} {f['url'].rsplit('/', 1)[-1]}:{f['lineNumber']}"
        by_name[name] = by_name.get(name, 0.0) + us / 1000
    return sorted(((ms, n) for n, ms in by_name.items()), reverse=True)[:top]


def _rate(extra: list[str] | None, flag: str, default: float) -> float:
    """The rate ``flag`` given to the dashboard (``--flag=X``, ``--flag X``), else ``default``."""
    args = list(extra or [])
    for i, a in enumerate(args):
        if a.startswith(flag + "="):
            return float(a.split("=", 1)[1])
        if a == flag and i + 1 < len(args):
            return float(args[i + 1])
    return default


def measure(
    elf: Path | None,
    seconds: float,
    rate: int,
    tmp: Path,
    extra: list[str] | None = None,
    js_profile: bool = False,
) -> dict:
    url_file = tmp / "emulator.url"
    emu_cmd = [sys.executable, "-m", "utrf", "emulate", "--no-pty", "--url-file", str(url_file),
               "--status-interval", "0", "--no-commands"]  # fmt: skip
    if elf:
        emu_cmd += ["--elf", str(elf)]
    emu = start(emu_cmd, tmp / "emulate.log")
    dash = None
    driver = None
    try:
        wait_for(lambda: url_file.exists() and "socket://" in url_file.read_text(), 60, "emulate")
        board_url = next(w for w in url_file.read_text().split() if w.startswith("socket://"))
        port = free_port()
        dash = start(
            [
                sys.executable,
                "-m",
                "utrf",
                "dashboard",
                "--port",
                board_url,
                "--boot-wait",
                "0.5",
                "--http-port",
                str(port),
                "--rate",
                str(rate),
                "--record-dir",
                str(tmp),
                *(extra or []),
            ],
            tmp / "dashboard.log",
        )
        wait_for(lambda: "open http" in (tmp / "dashboard.log").read_text(), 90, "dashboard")
        options = webdriver.ChromeOptions()
        options.binary_location = "/usr/bin/chromium"
        for flag in [*FLAGS, f"--user-data-dir={tmp / 'chromium'}"]:
            options.add_argument(flag)
        driver = webdriver.Chrome(options=options, service=Service("/usr/bin/chromedriver"))
        driver.get(f"http://127.0.0.1:{port}/")
        WebDriverWait(driver, 120).until(
            lambda d: (
                d.execute_script("return !!(window.socket && window.socket.connected)")
                and "you control" in d.find_element(By.CSS_SELECTOR, ".utrf-control").text
            )
        )
        time.sleep(3.0)  # the page settles
        driver.execute_script(PROBE)
        driver.execute_cdp_cmd("Performance.enable", {})
        metrics0 = page_metrics(driver)
        if js_profile:
            driver.execute_cdp_cmd("Profiler.enable", {})
            driver.execute_cdp_cmd("Profiler.setSamplingInterval", {"interval": 200})
            driver.execute_cdp_cmd("Profiler.start", {})
        server = psutil.Process(dash.pid)
        browser = psutil.Process(driver.service.process.pid).children(recursive=True)
        kinds = browser_kinds(browser)
        b0 = {p.pid: cpu_s(p) for p in browser}
        rt0 = named_thread_cpu_s([p for p in browser if kinds.get(p.pid) == "renderer"])
        status0 = json.loads(driver.execute_script(STATUS))
        pushed0 = status0["pushed"].get("live", 0)
        samples0 = status0["samples"]
        t0 = thread_cpu_s(server)
        c0, w0 = cpu_s(server), time.monotonic()
        # a pose every POSE_S (whatever the window's length: the same work each second)
        clicks = max(round(seconds / POSE_S), 1)
        for k in range(clicks):
            pose = POSES[k % len(POSES)]
            driver.find_element(By.CSS_SELECTOR, f".utrf-pose-{pose}").click()
            time.sleep(max((k + 1) * seconds / clicks - (time.monotonic() - w0), 0.1))
        c1, w1 = cpu_s(server), time.monotonic()
        t1 = thread_cpu_s(server)
        b1 = {p.pid: cpu_s(p) for p in browser if p.is_running()}
        rt1 = named_thread_cpu_s([p for p in browser if kinds.get(p.pid) == "renderer"])
        metrics1 = page_metrics(driver)
        profile = driver.execute_cdp_cmd("Profiler.stop", {})["profile"] if js_profile else None
        renderer = [pid for pid, kind in kinds.items() if kind == "renderer"]
        lat_, drawn_, parts_ = driver.execute_script(
            "return [window.utrfLat, window.utrfDrawn, window.utrfParts]"
        )
        if lat_ is None:
            raise SystemExit("bench-dashboard: the page reloaded during the run: the probe is gone")
        # the counts of the window (samples received, updates pushed), not of the frame window
        status = json.loads(driver.execute_script(STATUS))
        driver.execute_script(FRAME_PROBE)
        time.sleep(FRAME_WINDOW_S)
        frames_ = driver.execute_script("return window.utrfFrames")
        lat, frames = np.array(lat_, dtype=float), np.array(frames_, dtype=float)
        age = display_age(np.array(drawn_, dtype=float).reshape(-1, 2))
        parts = np.array(parts_, dtype=float).reshape(-1, 3)
    finally:
        if driver is not None:
            driver.quit()
        for p in (dash, emu):
            if p is not None and p.poll() is None:
                p.send_signal(signal.SIGINT)
                try:
                    p.wait(20)
                except subprocess.TimeoutExpired:
                    p.kill()
    span = (frames[-1] - frames[0]) / 1000 if len(frames) > 1 else float("nan")
    main_cpu = t1.get(server.pid, 0.0) - t0.get(server.pid, 0.0)
    by_kind: dict[str, float] = {}
    for pid, kind in kinds.items():
        if pid in b1:
            by_kind[kind] = by_kind.get(kind, 0.0) + (b1[pid] - b0[pid]) / (w1 - w0)
    samples = status["samples"] - samples0
    # per live update drawn (one frame each, and the charts' and 3D hand's drawing between):
    # the window has no other frames since the probe asks for none
    n_updates = max(len(lat), 1)

    def per_update_ms(name: str) -> float:
        return 1000 * (metrics1.get(name, 0.0) - metrics0.get(name, 0.0)) / n_updates

    return {
        # the page's main thread per live update drawn (DevTools' counters): all its tasks,
        # and of them JavaScript, style and layout
        "main_ms_per_update": {
            k: per_update_ms(name)
            for k, name in (
                ("cpu", "ThreadTime"),  # the main thread's CPU time
                ("tasks", "TaskDuration"),  # its tasks' wall time
                ("script", "ScriptDuration"),
                ("style", "RecalcStyleDuration"),
                ("layout", "LayoutDuration"),
            )
        },
        "js_profile_ms": profile_summary(profile) if profile else [],
        # the renderer's threads, ms of CPU per live update drawn (the main thread, the
        # compositor, the raster workers, ...)
        "renderer_threads_ms_per_update": {
            name: 1000 * (t - rt0.get(name, 0.0)) / n_updates
            for name, t in sorted(rt1.items(), key=lambda kv: -kv[1])
            if t - rt0.get(name, 0.0) > 0.01
        },
        "seconds": w1 - w0,
        "rate_hz": rate,
        # (0 in a commit before the reader lingered: the bench runs on either, side by side)
        "read_linger_s": getattr(dashboard_hub, "READ_LINGER_S", 0.0),
        "ui_hz": _rate(extra, "--ui-hz", ServerOptions().ui_hz),
        "plot_hz": _rate(extra, "--plot-hz", ServerOptions().plot_hz),
        "samples": status["samples"],
        "latency_ms": {
            "n": len(lat),
            "p50": float(np.percentile(lat, 50)),
            "p99": float(np.percentile(lat, 99)),
            "max": float(lat.max()),
            # the p99 of each third of the window (in the order drawn): how steady it is
            "p99_thirds": [float(np.percentile(x, 99)) for x in np.array_split(lat, 3)],
        },
        # the latency in three: the sample's age when the server sent it, from then to the
        # page's DOM holding it, from then to the frame drawn (p50 and p99 of each); and the
        # browser's whole part, from the send to the frame (the last two, sample by sample)
        "parts_ms": {
            **{
                name: [float(np.percentile(parts[:, k], q)) for q in (50, 99)]
                for k, name in enumerate(("to_push", "push_to_dom", "dom_to_frame"))
            },
            "push_to_frame": [float(np.percentile(parts[:, 1] + parts[:, 2], q)) for q in (50, 99)],
        },
        "display_age_ms": {
            "p50": float(np.percentile(age, 50)) if len(age) else math.nan,
            "p99": float(np.percentile(age, 99)) if len(age) else math.nan,
        },
        "server_cpu_core": (c1 - c0) / (w1 - w0),
        # load moves these less than the fractions of a core: CPU time per unit of work
        "server_us_per_sample": 1e6 * (c1 - c0) / max(samples, 1),
        "server_loop_cpu_core": main_cpu / (w1 - w0),  # NiceGUI's event loop (main thread)
        "server_other_cpu_core": (c1 - c0 - main_cpu) / (w1 - w0),  # the Hand's threads
        "browser_cpu_by_kind": by_kind,
        "browser_cpu_core": sum(b1[k] - b0[k] for k in b1) / (w1 - w0),
        "renderer_cpu_core": sum(b1[k] - b0[k] for k in renderer if k in b1) / (w1 - w0),
        "fps": (len(frames) - 1) / span,
        "updates_per_s": len(lat) / (w1 - w0),
        "renderer_ms_per_update": 1000 * by_kind.get("renderer", 0.0) * (w1 - w0) / n_updates,
        "gpu_ms_per_update": 1000 * by_kind.get("gpu-process", 0.0) * (w1 - w0) / n_updates,
        "pushed_per_s": (status["pushed"].get("live", 0) - pushed0) / (w1 - w0),
        "load_average": os.getloadavg()[0],
        "sent": status["sent"],
        "pushed": {k: v - status0["pushed"].get(k, 0) for k, v in status["pushed"].items()},
    }


def section(r: dict) -> str:
    lat = r["latency_ms"]
    parts = r["parts_ms"]
    thirds = ", ".join(f"{x:.1f}" for x in lat.get("p99_thirds", [])) + " ms"

    def ok(good: bool) -> str:
        return "met" if good else "**not met**"

    return "\n".join(
        [
            BEGIN,
            "## Dashboard",
            "",
            f"`make bench-dashboard` ({date.today().isoformat()}, {cpu_name()}, 2 cores shared "
            f"with other work: load average {r['load_average']:.1f} at the end). The board is "
            f"`utrf emulate` in its own process, streaming at {r['rate_hz']} Hz; the dashboard "
            f"(`utrf dashboard --port`, rates: live view up to {r.get('ui_hz', 30):g} Hz, paced "
            f"by the page's frames, each started by a sample's arrival; its numbers drawn in a "
            "frame of their own, then in the frame after either the 3D hand (drawn when it "
            f"moved) or one chart (each {r.get('plot_hz', 5):g} Hz); the Hand's reader waiting "
            f"{1000 * r['read_linger_s']:.0f} ms after each read unless a page asks for the "
            "newest sample, as each update does) with one "
            f"page open in headless chromium, for {r['seconds']:.0f} s while the page moves the "
            f"hand to a pose every {POSE_S:g} s, in turn {', '.join(POSES)} "
            f"({r['samples']} samples reached the server).",
            "",
            "| goal | measured | |",
            "|---|---|---|",
            f"| board sample to pixels, p99 <= 50 ms | p50 {lat['p50']:.1f} ms, p99 "
            f"{lat['p99']:.1f} ms, worst {lat['max']:.1f} ms ({lat['n']} samples drawn; the p99 "
            f"of each third of the window {thirds}) | "
            f"{ok(lat['p99'] <= 50)} |",
            f"| server CPU <= 25 % of one core | {100 * r['server_cpu_core']:.1f} % | "
            f"{ok(r['server_cpu_core'] <= 0.25)} |",
            f"| page draws >= 30 frames/s | {r['fps']:.1f} frames/s when asked for every frame "
            f"({FRAME_WINDOW_S:g} s after the window); in the window it drew "
            f"{r['updates_per_s']:.1f} frames/s with a new sample, of the "
            f"{r['pushed_per_s']:.1f}/s the server sent (at most 30/s, one per frame drawn) | "
            f"{ok(r['fps'] >= 30)} |",
            "",
            "The frame rate: a `requestAnimationFrame` loop has chromium draw every frame it can "
            "(60 a second when it keeps up), so it says what the page can draw; during the "
            "latency window nothing asks for frames the page does not need (such a loop made "
            "chromium draw 60 frames a second for at most 30 updates, and took the CPU the "
            "board, the server and the page share), and the page draws a frame for each update's "
            "numbers and one for its 3D hand or chart. "
            f"What a person sees: over the window, the newest sample on the page was "
            f"{r['display_age_ms']['p50']:.0f} ms old (p50), {r['display_age_ms']['p99']:.0f} ms "
            "(p99), each millisecond: the figure above plus the wait for the next update. "
            f"The browser (all its processes) had {100 * r['browser_cpu_core']:.0f} % of one "
            f"core over the window, its page's renderer {100 * r['renderer_cpu_core']:.0f} %. "
            f"With the machine's load average near {r['load_average']:.0f} on 2 cores, each "
            f"busy thread gets about {200 / max(r['load_average'], 1):.0f} % of a core; above "
            "2 the figures measure that starvation as much as the dashboard. Re-measure on a "
            "quiet machine.",
            "",
            "Per unit of work (load moves these less than the shares of a core): the server "
            f"spent {r['server_us_per_sample']:.0f} us of CPU per sample received (its event "
            f"loop {100 * r['server_loop_cpu_core']:.1f} % of a core, the Hand's threads "
            f"{100 * r['server_other_cpu_core']:.1f} %), the page's renderer "
            f"{r['renderer_ms_per_update']:.1f} ms per update drawn (its main thread "
            f"{r['main_ms_per_update']['cpu']:.1f} ms), chromium's GPU process "
            f"{r['gpu_ms_per_update']:.1f} ms ("
            f"{100 * r['browser_cpu_by_kind'].get('gpu-process', 0.0):.0f} % of a core); the 3D "
            f"hand was drawn {r['pushed'].get('hand3d', 0) / r['seconds']:.1f} times a second. "
            "The latency in parts (p50 / p99, ms): the sample's age when the server sent it "
            f"{parts['to_push'][0]:.1f} / {parts['to_push'][1]:.1f}, from then to the page's "
            f"DOM {parts['push_to_dom'][0]:.1f} / {parts['push_to_dom'][1]:.1f}, from then to "
            f"the frame drawn {parts['dom_to_frame'][0]:.1f} / {parts['dom_to_frame'][1]:.1f} "
            f"(the browser's whole part, from the send to the frame: "
            f"{parts['push_to_frame'][0]:.1f} / {parts['push_to_frame'][1]:.1f}).",
            "",
            "Latency: the probe takes the time after the frame that drew each new sample "
            "(`requestAnimationFrame`, then a task) minus the sample's board time on the host's "
            "wall clock (the server maps the board's clock through the least-delayed samples of "
            "the last 2 s, so it includes the serial line's and the host's delays beyond the "
            "quickest sample's). CPU: user + system time of the dashboard's process over the "
            "window.",
            END,
        ]
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--elf", type=Path)
    p.add_argument("--seconds", type=float, default=WINDOW_S)
    p.add_argument("--rate", type=int, default=1000)
    p.add_argument("--update", type=Path, help="write the section into this Markdown file")
    p.add_argument("--json", type=Path)
    p.add_argument(
        "--dashboard-arg",
        action="append",
        default=[],
        help="an option for `utrf dashboard` (repeatable, e.g. --dashboard-arg=--plot-hz=2)",
    )
    p.add_argument(
        "--js-profile",
        action="store_true",
        help="also sample the page's JavaScript (DevTools' profiler) and list its costliest "
        "functions (diagnosis: the profiler slows the page)",
    )
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="utrf-bench-dash-") as tmp:
        r = measure(
            args.elf, args.seconds, args.rate, Path(tmp), args.dashboard_arg, args.js_profile
        )
    print(json.dumps(r, indent=1))
    text = section(r)
    print(text)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(r, indent=1))
    if args.update:
        write_section(args.update, text, BEGIN, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
