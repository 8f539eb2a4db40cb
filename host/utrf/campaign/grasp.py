"""The ``grasp`` kind: object holds on the twin, one per task (``utrf.hil.object_hold``: the
real firmware ELF on the emulated board, the MuJoCo hand, an object of the library).

Parameters: object (names in the object library), mass_kg and friction (the object's,
replacing the library's), hit_impulse_n_s and hits (the hammer), effort (the GRASP duty
limit), kp ki kd (every finger's gains, within the protocol's limits), seed, duration_s,
firmware (labels of the ``[firmware]`` table: two for an A/B). Options: ``library`` (an
objects TOML of one's own), ``sample_hz``.

Per run: held or dropped (and when), slip, the largest displacement, the largest contact
force, broke (fragile objects), the largest tracking error of the fingers that hold still
(|target − θ2| in the telemetry, the fingers not closing on the object), the firmware's
build id (its identity) and the ELF's SHA-256.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import tempfile
from pathlib import Path
from typing import Any

from utrf.campaign.spec import Campaign, CampaignError
from utrf.protocol import messages as m

DEFAULT_DURATION_S = 10.0
_GAINS = {f.name: (f.min, f.max) for f in m.SetGains.FIELDS if f.name in ("kp", "ki", "kd")}
# name -> (lowest, highest): what the run and the protocol accept (ObjectHoldConfig's checks)
BOUNDS: dict[str, tuple[float, float]] = {
    "mass_kg": (1e-3, 5.0),
    "friction": (0.05, 3.0),
    "hit_impulse_n_s": (0.0, 5.0),
    "hits": (0, 10_000),
    "effort": (0.01, 1.0),
    "seed": (0, 2**31 - 1),
    "duration_s": (2.0, 3600.0),
    **{
        k: (float(lo or 0.0), float(hi if hi is not None else math.inf))
        for k, (lo, hi) in _GAINS.items()
    },
}
TEXT = ("object", "firmware")
IMPORTS = ("utrf.hil.object_hold", "utrf.emulator", "utrf.emulator.mujoco_plant", "utrf.hand")
OPTIONS = ("library", "sample_hz")


def check(campaign: Campaign) -> None:
    from utrf.models import objects

    library_path = campaign.options.get("library")
    for key in campaign.options:
        if key not in OPTIONS:
            raise campaign.error(
                f"options.{key}", f"unknown grasp option {key!r}; known: {', '.join(OPTIONS)}"
            )
    try:
        library = objects.load_objects(library_path)
    except (objects.ObjectError, OSError) as exc:
        raise campaign.error("options.library", str(exc)) from None
    for p in campaign.params:
        where = f"parameters.{p.name}"
        if p.name not in BOUNDS and p.name not in TEXT:
            raise campaign.error(
                where,
                f"unknown grasp parameter {p.name!r}; known: {', '.join([*TEXT, *BOUNDS])}",
            )
        if p.name in TEXT:
            if p.values is None:
                raise campaign.error(where, f"{p.name} takes a list of names, not a range")
            known = sorted(library) if p.name == "object" else sorted(campaign.firmware)
            for v in p.values:
                if v not in known:
                    what = "object" if p.name == "object" else "firmware label ([firmware])"
                    raise campaign.error(where, f"unknown {what} {v!r}; known: {known}")
            continue
        lo, hi = BOUNDS[p.name]
        values = (p.range.low, p.range.high) if p.range is not None else p.values or ()
        for v in values:
            if isinstance(v, bool) or not isinstance(v, int | float) or not lo <= v <= hi:
                raise campaign.error(
                    where,
                    f"{p.name} = {v!r} is outside [{lo:g}, {hi:g}]"
                    " (the run's or the protocol's limits)",
                )
    if campaign.param("firmware") is None:
        if campaign.firmware:
            raise campaign.error(
                "firmware", "[firmware] names ELFs but no parameter firmware = [labels] uses them"
            )
        from utrf.artifacts import ArtifactError, firmware_elf

        try:
            firmware_elf()
        except ArtifactError as exc:
            raise CampaignError(f"{campaign.source}: no firmware ELF: {exc}") from None


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def _library_with(obj: Any, path: Path) -> None:
    """A one-object library TOML holding ``obj`` (with a campaign's mass and friction)."""

    def value(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, tuple | list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(float(v))

    lines = [f"[object.{obj.name}]"]
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if f.name != "name" and v is not None:
            lines.append(f"{f.name} = {value(v)}")
    path.write_text("\n".join(lines) + "\n")


def run_one(options: dict[str, Any], params: dict[str, Any]) -> dict[str, Any]:
    """One object hold on the twin; its figures as a flat row."""
    import numpy as np

    from utrf.artifacts import firmware_elf
    from utrf.hil import object_hold
    from utrf.models import objects

    library = options.get("library")
    obj = objects.get_object(str(params.get("object", "bottle")), library)
    obj = dataclasses.replace(
        obj,
        mass_kg=float(params.get("mass_kg", obj.mass_kg)),
        friction=float(params.get("friction", obj.friction)),
    )
    label = params.get("firmware")
    elf = Path(options["firmware_paths"][label]) if label else firmware_elf()
    gains = {k: float(params[k]) for k in ("kp", "ki", "kd") if k in params}
    seen: dict[str, Any] = {"error": 0.0, "identity": None}

    def on_hand(hand: Any) -> None:
        seen["identity"] = hand.identity
        for finger in range(5):
            if gains:
                hand.set_gains(finger, **gains)

        def listen(t: Any) -> None:
            msg = t.message
            if isinstance(msg, m.State):
                theta, target = np.asarray(msg.theta2), np.asarray(msg.target)
                still = np.abs(target) < 0.2  # the fingers not closing on the object
                if still.any():
                    err = float(np.abs(target - theta)[still].max())
                    seen["error"] = max(seen["error"], err)

        hand.link.add_telemetry_callback(listen)

    with tempfile.TemporaryDirectory(prefix="utrf-grasp-") as tmp:
        lib = Path(tmp) / "objects.toml"
        _library_with(obj, lib)
        config = object_hold.ObjectHoldConfig(
            object=obj.name,
            duration_s=float(params.get("duration_s", DEFAULT_DURATION_S)),
            hits=int(params.get("hits", 3)),
            hit_impulse_n_s=(
                float(params["hit_impulse_n_s"]) if "hit_impulse_n_s" in params else None
            ),
            effort=float(params["effort"]) if "effort" in params else None,
            seed=int(params.get("seed", 0)),
            sample_hz=float(options.get("sample_hz", 50.0)),
            picture=False,
            library=str(lib),
        )
        result = object_hold.run(
            config, Path(tmp) / "run", elf=elf, progress=lambda _: None, on_hand=on_hand
        )
    if not result.get("complete", True):  # neither held to the end nor dropped: no verdict
        raise RuntimeError(f"the hold was cut short at {result.get('duration_s', 0.0):.2f} s")
    forces = result["largest_contact_force_n"]
    identity = seen["identity"]
    return {
        "held": not result["dropped"],
        "dropped_at_s": result["dropped_at_s"],
        "slip_mm": result["slip_mm"],
        "largest_displacement_mm": result["largest_displacement_mm"],
        "largest_contact_force_n": max(forces.values()),
        **{f"contact_force_{k}_n": v for k, v in forces.items()},
        "broke": result["broke"],
        "largest_tracking_error_rad": seen["error"],
        "effort_used": result["effort"],
        "firmware_build_id": f"{identity.build_id:08x}" if identity is not None else None,
        "firmware_sha256": _sha256(elf),
    }
