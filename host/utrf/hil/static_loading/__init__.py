"""The static loading experiment (paper Sec. IV-A) on the real or the emulated rig.

One finger is held straight and horizontal; payloads hang from its tip (the paper: 0.5 to
3 kg in 0.5 kg steps, three repeats); a tracker's sensor on the tip gives its position.

**How the finger is held, and what the model predicts for it.** The firmware holds the
Joint-2 angle in closed loop (its encoder is on Joint 2). The paper's slide stage held the
tendon displacement q instead. The two are different boundary conditions: with q held,
every tendon's stretch lets the finger sag (24.4 mm at 3 kg); with θ2 held the controller
pulls the actuating tendon until Joint 2 is back, so Tendon 1's stretch drops out, Tendon 2's
stretch turns Joint 1 up (R1 θ1 = R2 θ2 + e2) and Tendon 3's turns Joint 3 down. The run
predicts with the matching boundary condition: per step, the q at which the loaded model
finger has the Joint-2 angle the encoder measured (``utrf.models.calibration.hold_q``, the
same matching as ``planning.plan(match="theta2")``), then the statics there. It reports the
slide-stage (q held) prediction alongside, for comparison with the paper's figures.

Files in the output directory (every CSV append-safe, ``utrf.datalog``):

- ``meta.json``: the run's configuration (what ``--resume`` continues);
- ``registration.json``, ``registration.csv``: the tracker-to-finger registration and the
  samples it was fitted from;
- ``samples.csv``: every tracker sample with the board's telemetry at that moment (step,
  attempt, repeat, load, tracker position raw and in the finger frame, the encoder's θ2 as
  the mean of every telemetry frame since the previous sample and their count and spread,
  duties, motor currents where known);
- ``steps.csv``: one row per *completed* step (the samples' attempt it used): the resume
  marker; ``telemetry.csv``: the Hand's full telemetry stream;
- ``results.json``, ``static_loading.png``: :mod:`.analysis` and :mod:`.report`
  (recomputable from the CSVs); the calibration's uncertainty carries the Joint-2 reading's
  (:func:`.analysis.calibrate`, ``utrf.hil.joint2``, ``hil/README.md``).

The modules, one job each: :mod:`.config` (the run's configuration and its files' columns),
:mod:`.run` (takes the data: writes the CSVs as it goes), :mod:`.analysis` (the results from
the CSVs alone), :mod:`.report` (the figure and the table for people). The run and
``utrf hil analyse`` share the analysis and nothing else.
"""

from __future__ import annotations
