"""Undefined behaviour in the firmware core fails the tests.

The host build the tests load (build/firmware/host/libutrf_fw.so) is compiled with UBSan and
-fno-sanitize-recover: the first undefined operation aborts the process. The workloads below
run in a child process, so a finding fails this test with UBSan's message rather than taking
the whole suite down (any other test meeting one still aborts: that is the point).
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

from fwsim import LIB_PATH, REPO


def test_the_host_core_is_built_with_ubsan_that_aborts() -> None:
    syms = subprocess.run(
        ["nm", "-D", str(LIB_PATH)], capture_output=True, text=True, check=True
    ).stdout
    assert "__ubsan_handle_" in syms
    assert "_abort" in syms  # the non-recovering handlers: -fno-sanitize-recover


def run_child(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        cwd=REPO / "tests" / "firmware",
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_the_pid_on_a_falling_angle_is_defined_behaviour() -> None:
    """The derivative of a falling measurement (negative d(measured)): once a left shift of a
    negative value (pid.h, issue 13), now a multiply."""
    r = run_child(
        """
        import fwsim
        lib = fwsim.load_library()
        fwsim.pid_config(lib, 22937, kp=3.0, ki=2.0, kd=0.05, deadband_duty=0.04)
        lib.fw_pid_reset(0, 0)
        for k in range(400):  # down and up through +-63 BU a tick and beyond
            lib.fw_pid_step(0, 3000 - 70 * k if k < 200 else -11000 + 70 * (k - 200))
        print("done")
        """
    )
    assert r.returncode == 0 and "runtime error" not in r.stderr, r.stderr[-2000:]
    assert r.stdout.strip() == "done"


def test_the_board_closing_a_loop_is_defined_behaviour() -> None:
    """The whole core (ticks, loop, dispatch) on the reference plant: a step down and back."""
    r = run_child(
        """
        import fwsim
        lib = fwsim.load_library()
        sim = fwsim.Sim(lib)
        for step in (-0.5, 0.7):
            sim.power_on()
            fwsim.step_response(sim, step)
        print("done")
        """
    )
    assert r.returncode == 0 and "runtime error" not in r.stderr, r.stderr[-2000:]
    assert r.stdout.strip() == "done"
