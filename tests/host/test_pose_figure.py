"""The demo's pose picture (``utrf.hand.figures.draw_pose``): target and measured both seen in
each finger's side view, every finger whole in its frame, each finger named on the render."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest

from utrf.hand import figures
from utrf.models.geometry import HandGeometry

HAND = HandGeometry.default()


def test_side_views_show_both_chains_whole_and_the_render_names_each_finger(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    target = np.array([0.0, 1.4, 1.4, 1.4, 0.0])  # shaka: two straight fingers, three flexed
    measured = target + np.array([0.01, -0.02, 0.015, -0.005, 0.02])
    drawn: dict[str, object] = {}
    monkeypatch.setattr(plt.Figure, "savefig", lambda fig, *_a, **_k: drawn.update(fig=fig))
    tips = {f.name: (40.0 + 10 * i, 30.0) for i, f in enumerate(HAND.fingers)}
    rendered = np.zeros((60, 120, 3), dtype=np.uint8)
    figures.draw_pose(HAND, measured, target, tmp_path / "p.png", title="t", rendered=rendered,
                      labels=tips)  # fmt: skip
    fig = drawn["fig"]
    side = [a for a in fig.axes if a.get_title().split("\n")[0] in {f.name for f in HAND.fingers}]
    assert len(side) == 5
    for ax, f, m, t in zip(side, HAND.fingers, measured, target, strict=True):
        lines = {ln.get_label(): ln for ln in ax.get_lines()}
        tgt, mea = lines["target"], lines["measured"]
        assert tgt.get_zorder() > mea.get_zorder()  # the thin dashed target over the band
        assert tgt.get_linewidth() < mea.get_linewidth() and mea.get_alpha() < 1
        chain_t = figures._side_xy(f.geometry, t)
        chain_m = figures._side_xy(f.geometry, m)
        assert np.allclose(np.column_stack(tgt.get_data()), chain_t)
        (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
        for x, y in np.vstack((chain_t, chain_m)):  # whole, with room for the line's width
            assert x0 + 5 < x < x1 - 5 and y0 + 5 < y < y1 - 5, (f.name, x, y)
    assert len({a.get_ylim() for a in side}) == 1  # one scale for all five
    render_ax = next(a for a in fig.axes if a.images)
    named = {t.get_text(): t.xy for t in render_ax.texts}
    assert named == tips  # every finger named, its line ending at its tip
