"""Host software for the UTRF-RoboHand.

``from utrf import Hand`` is the user-facing client (:mod:`utrf.hand`). Subpackages:
``models`` (finger geometry, kinematics, statics, planning), ``protocol`` (generated messages,
framing, transport), ``emulator`` (the real firmware on simavr with a Python plant), ``hand``
(the client) and ``cli`` (the ``utrf`` command). SI units throughout: m, rad, N, s.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"
__all__ = ["Hand", "__version__"]

if TYPE_CHECKING:
    from utrf.hand import Hand


def __getattr__(name: str) -> Any:
    # Imported on first use: `import utrf.protocol` stays light for the tools that need no more.
    if name == "Hand":
        from utrf.hand import Hand

        return Hand
    raise AttributeError(f"module 'utrf' has no attribute {name!r}")
