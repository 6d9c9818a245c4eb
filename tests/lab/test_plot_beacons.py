"""World pictures (lab.plot) draw a world's beacons where they draw its walls."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

import server  # noqa: E402
from lab.plot import draw_world, plot_paths  # noqa: E402
from server.world import load_world  # noqa: E402


def test_the_beacons_are_drawn_in_their_colour_with_their_id(tmp_path):
    import matplotlib.pyplot as plt

    spec = load_world(server.world_path("beacons-room"))
    fig, ax = plt.subplots()
    draw_world(ax, spec)
    discs = [p for p in ax.patches if p.get_zorder() == 3]
    assert [tuple(np.round(np.array(p.get_facecolor()[:3]) * 255)) for p in discs] == [
        (220, 40, 40), (40, 170, 60)]
    assert [t.get_text() for t in ax.texts if t.get_text() in ("1", "2")][-2:] == ["1", "2"]
    plt.close(fig)
    out = plot_paths(spec, {"teacher": np.array([[5.0, 1.2, 1.57], [5.0, 1.6, 1.57]])},
                     tmp_path / "w.png", title="beacons-room")
    assert out.stat().st_size > 1000
