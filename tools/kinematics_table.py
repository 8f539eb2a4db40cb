"""Generate the firmware's coupled-kinematics lookup table from the host's kinematics model.

The routing couples the joints, so the measured Joint-2 angle fixes the whole finger. For each
distinct finger geometry in the hand file, the table holds rows at uniformly spaced θ2 of
q, θ1, θ3 and the tip (x, y) as scaled int16 in PROGMEM; the firmware interpolates linearly.
The row count is the smallest that keeps the worst interpolated tip error, quantisation
included, within ``max_tip_error_m``.

    python -m tools.kinematics_table            # write firmware/src/generated/kinematics_table.h
    python -m tools.kinematics_table --check    # exit 1 if the committed file is stale

Part of ``make generate``; tests/tools/test_kinematics_table.py fails when the header is stale.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.generated import write_or_check
from utrf.models.geometry import HandGeometry
from utrf.models.kinematics_table import (  # the table writer's core, in the package
    COMMAND,
    DEFAULT_MAX_TIP_ERROR_M,
    GeometryTable,
    build_table,
    build_tables,
    interpolate,
    render_header,
)

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUT = REPO / "firmware" / "src" / "generated" / "kinematics_table.h"


def _relative(path: str) -> str:
    try:
        return str(Path(path).resolve().relative_to(REPO))
    except ValueError:
        return Path(path).name


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=COMMAND, description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--hand", type=Path, help="hand file (default: the package's hand.toml)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--max-tip-error-mm", type=float, default=DEFAULT_MAX_TIP_ERROR_M * 1e3)
    parser.add_argument("--check", action="store_true", help="fail if --out is not up to date")
    args = parser.parse_args(argv)
    hand = HandGeometry.from_toml(args.hand) if args.hand else HandGeometry.default()
    tables, finger_table = build_tables(hand, args.max_tip_error_mm * 1e-3)
    text = render_header(hand, tables, finger_table, source_name=_relative)
    for gi, t in enumerate(tables):
        print(
            f"geometry {gi} ({_relative(t.geometry.source)}): {t.rows} rows, {t.nbytes} bytes, "
            f"worst tip error {t.worst_tip_error_m * 1e3:.4f} mm"
        )
    print(f"total {sum(t.nbytes for t in tables)} bytes of PROGMEM")
    return write_or_check(
        {args.out: text}, check=args.check, tool="kinematics_table", command=COMMAND, root=REPO
    )


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["DEFAULT_MAX_TIP_ERROR_M", "DEFAULT_OUT", "GeometryTable", "build_table", "build_tables",
           "interpolate", "main"]  # fmt: skip
