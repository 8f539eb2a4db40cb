"""Hardware-in-the-loop runs on the rig: the paper's static loading experiment (Sec. IV-A) and the
grasp hold (Sec. IV-C), on the real rig or the emulated one. See ``hil/README.md``."""
