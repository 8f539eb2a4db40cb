"""One design of a sweep, ready to flash and to simulate (``utrf campaign export DIR KEY``):

OUT/finger.toml           its geometry (the hand file's schema)
OUT/hand.toml             the hand with it as the four fingers (the package's thumb kept)
OUT/hand.xml              the hand in MuJoCo (``utrf.models.mjcf``)
OUT/kinematics_table.h    the firmware's table for that hand: copy it over
                          firmware/src/generated/kinematics_table.h and build
OUT/workspace.json        its swept areas from the raster model (``workspace.areas``)
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import pyarrow.compute as pc

from utrf.campaign import design
from utrf.campaign.spec import CampaignError
from utrf.campaign.store import Store

FOUR = ("index", "middle", "ring", "little")


def _toml_value(v: Any) -> str:
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(float(v))


def export(root: Path, run_key: str, out: Path) -> dict[str, Path]:
    from utrf.models import mjcf, workspace
    from utrf.models.geometry import HandGeometry, package_data
    from utrf.models.kinematics_table import build_tables, render_header

    table = Store(root).read()
    rows = table.filter(pc.equal(table.column("run_key"), run_key)).to_pylist()
    if not rows:
        raise CampaignError(f"{root}: no run {run_key!r} (utrf campaign report lists the front)")
    row = rows[0]
    if "link1_m" not in row and "radius1_m" not in row and "plan_safe" not in row:
        raise CampaignError(f"{root}: run {run_key} is not a design")
    params = {k: row[k] for k in design.PARAMETERS if row.get(k) is not None}
    out.mkdir(parents=True, exist_ok=True)
    finger = out / "finger.toml"
    geom = design.geometry(params, source=str(finger))
    body = "\n".join(f"{k} = {_toml_value(v)}" for k, v in geom.to_dict().items())
    finger.write_text(f"# design {run_key} of the campaign in {root}\n[finger]\n{body}\n")
    with package_data("geometry", "thumb.toml") as thumb:
        shutil.copyfile(thumb, out / "thumb.toml")
    entries = [("thumb", "thumb.toml")] + [(name, "finger.toml") for name in FOUR]
    hand_text = (
        f'# the hand with design {run_key} as its four fingers\n[hand]\nname = "{run_key}"\n'
    )
    for name, file in entries:
        hand_text += (
            f'\n[[hand.finger]]\nname = "{name}"\ngeometry = "{file}"\nactuation = "antagonistic"\n'
        )
    (out / "hand.toml").write_text(hand_text)
    hand = HandGeometry.from_toml(out / "hand.toml")
    (out / "hand.xml").write_text(mjcf.hand_xml(hand))
    tables, finger_table = build_tables(hand)
    header = render_header(
        hand, tables, finger_table, command=f"utrf campaign export {root} {run_key}"
    )
    (out / "kinematics_table.h").write_text(header)
    areas = workspace.areas(geom)
    (out / "workspace.json").write_text(json.dumps(areas.to_json(), indent=2) + "\n")
    return {
        "finger": finger,
        "hand": out / "hand.toml",
        "mjcf": out / "hand.xml",
        "table": out / "kinematics_table.h",
        "workspace": out / "workspace.json",
    }
