"""Bench hardware-in-the-loop runs: the paper's static loading experiment (Sec. IV-A) and the
grasp hold (Sec. IV-C), on the real bench or the emulated board. See ``hil/README.md``."""
