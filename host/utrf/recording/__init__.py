"""Recordings the robotics tools open: MCAP with Foxglove and ROS 2 schemas
(:class:`~utrf.recording.mcap_recorder.McapRecorder`, :class:`~utrf.recording.session.Recording`
for a live Hand), and Parquet exports with SI column names and units
(:mod:`utrf.recording.export`). Needs the ``record`` extra (``pip install utrf[record]``).
See ``docs/recording.md``."""
