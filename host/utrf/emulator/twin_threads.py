"""How many threads the twin's lockstep takes: the one place that chooses.

With two, the MCU runs each exchange period on the caller's thread while the plant (MuJoCo)
steps the same period on a thread of its own (``harness/plant_thread.c``); the results are the
same to the bit as with one. Two pay wherever a core is free for the plant beside the MCU's: a
single run on two cores or more. With two, the MCU's thread checks that at every period
(``harness/lockstep.c``): where handing the period over costs it more than stepping the plant
itself would (no core free: other work on the machine), it steps the plant itself for a
stretch of periods. On fewer than three cores the plant's thread sleeps at once while a client
works beside the board (a sampling client: ``SimLink.sleep_each``), and the MCU's thread steps
the plant itself meanwhile (:func:`plant_spins`): the client has the other core then.
Measured on two cores: docs/benchmarks.md, the twin's section.
Where every core already has a run of its own (campaign workers, as many as the cores), one
thread each is the better use of them: set ``UTRF_TWIN_THREADS=1`` in the workers'
environment, or pass ``plant_threads=1`` to ``EmulatedBoard``.
"""

from __future__ import annotations

import os

from utrf.emulator.board_types import EmulatorError

ENV = "UTRF_TWIN_THREADS"


def usable_cores() -> int:
    """The cores this process may run on (its affinity, not the machine's count)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not Linux
        return os.cpu_count() or 1


def plant_threads(requested: int | None = None, *, paced: bool = False) -> int:
    """1 or 2: ``requested`` if given, else ``UTRF_TWIN_THREADS`` if set, else 2 when the
    process may use two cores or more (the MCU's and the plant's; a client working beside
    them takes the plant's core meanwhile) and the board is not paced to the wall clock (a
    paced board has time to spare: a second thread would only wait)."""
    source = "plant_threads"
    if requested is None:
        text = os.environ.get(ENV, "").strip()
        if text:
            source = ENV
            try:
                requested = int(text)
            except ValueError:
                raise EmulatorError(f"{ENV} must be 1 or 2, got {text!r}") from None
    if requested is None:
        return 2 if usable_cores() >= 2 and not paced else 1
    if requested not in (1, 2) or isinstance(requested, bool):
        raise EmulatorError(f"{source} must be 1 or 2, got {requested!r}")
    return int(requested)


def plant_spins() -> bool:
    """With two twin threads, whether the plant's thread spins for the MCU's next period
    before it sleeps while a client works beside the board: only with a core for each of the
    MCU, the plant and the client (three or more). On fewer it sleeps at once then, and the
    MCU's thread steps the plant itself (waking it each period would cost more than its step),
    leaving the client the other core; it spins while the client waits."""
    return usable_cores() >= 3
