"""The grasp hold (paper Sec. IV-C): a grasp pose held for a long time (the paper: 10 minutes)
while hammer hits disturb it.

The hand closes on the object with a grasp pose of the library (GRASP mode with the pose's
effort: each closing finger pushes with at most that duty and holds on contact), then holds.
On the emulated rig the object is a set of obstacles that stop the closing fingers part of
their way (``contact_fraction``), and seeded hammer hits (force pulses at the fingertips) come
at random times; on the real rig the operator hits and the run only records.

Everything is logged as it is taken (append-safe): ``samples.csv`` (every finger's Joint-2
angle, target, duties, faults and, emulated, motor currents, with the tracker's reading of the
tracked fingertip), ``hits.csv`` (the emulated hits), ``telemetry.csv`` (the Hand's stream).
:mod:`.analysis` works from those files alone: per finger the drift (slip) over the hold, the
largest deviation, the disturbances found in the data with their largest deviation and
recovery time, faults, and duty and current statistics; :mod:`.report` draws and tabulates
them. The run (:mod:`.run`) and ``utrf hil analyse`` share the analysis and nothing else;
:mod:`.config` holds the configuration and the files' columns.
"""
