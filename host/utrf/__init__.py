"""Host software for the UTRF-RoboHand.

Subpackages: ``models`` (finger geometry, kinematics, statics, planning), ``protocol``
(generated messages, framing, transport), ``emulator`` (the real firmware on simavr with a
Python plant) and ``cli`` (the ``utrf`` command). SI units throughout: m, rad, N, s.
"""

__version__ = "0.1.0"
