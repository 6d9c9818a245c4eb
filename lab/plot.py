"""Pictures: a world with paths (the paper's figures 3 and 4), optionally a tree's spheres.

    plot_paths(world, paths, out, title=None, spheres=None, dims=(0, 1), feature_names=None) -> Path
        world : server.world.WorldSpec (walls, goal, start poses, beacons) or an (M, 4) array of
                segments
        paths : {"teacher": poses (N, 3), "learner": poses, ...} drawn in that order; a list of
                pose arrays per name draws several episodes of the same kind
        out   : PNG path (matplotlib's Agg backend, no display needed)
        spheres: an rhbl.HypersphereClassifier: adds a panel with its spheres projected on the two
                features ``dims`` (a sphere's projection is a circle of its radius, coloured by label)
    draw_world(ax, world) ; draw_path(ax, poses, label, color) ; draw_spheres(ax, clf, dims)
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402

from process import files  # noqa: E402

__all__ = ["COLORS", "draw_path", "draw_spheres", "draw_world", "plot_paths"]

COLORS = {"teacher": "tab:blue", "learner": "tab:red", "controller": "tab:red"}
_LABEL_COLORS = ["tab:green", "tab:orange", "tab:purple", "tab:cyan", "tab:brown", "tab:pink",
                 "tab:olive", "tab:gray"]


def _segments(world) -> np.ndarray:
    if hasattr(world, "segments"):
        segs = world.segments() if callable(world.segments) else world.segments
    else:
        segs = world
    return np.asarray(segs, dtype=np.float64).reshape(-1, 4)


def draw_world(ax, world) -> None:
    for x0, y0, x1, y1 in _segments(world):
        ax.plot([x0, x1], [y0, y1], color="black", lw=2, solid_capstyle="round")
    goal = getattr(world, "goal", None)
    if goal is not None:
        ax.add_patch(Circle(goal.center, goal.radius, color="gold", alpha=0.4, label="goal"))
    for b in getattr(world, "beacons", ()) or ():  # fiducial beacons: their colour, their id
        ax.add_patch(Circle(b.pos, max(b.size / 2, 0.08), facecolor=np.array(b.colour) / 255.0,
                            edgecolor="black", lw=1, zorder=3))
        ax.text(b.pos[0], b.pos[1] + max(b.size / 2, 0.08) + 0.05, str(b.id), fontsize=8,
                ha="center", va="bottom", zorder=3)
    for k, (x, y, yaw) in enumerate(getattr(world, "start_poses", []) or []):
        ax.annotate("", xy=(x + 0.4 * math.cos(yaw), y + 0.4 * math.sin(yaw)), xytext=(x, y),
                    arrowprops={"arrowstyle": "->", "color": "green"})
        ax.text(x, y, str(k), fontsize=7, color="green")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def draw_path(ax, poses, label: str | None = None, color: str | None = None, **kw) -> None:
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        return
    ax.plot(p[:, 0], p[:, 1], color=color, lw=kw.pop("lw", 1.2), label=label, alpha=kw.pop("alpha", 0.85), **kw)
    ax.plot(p[0, 0], p[0, 1], "o", color=color, ms=4)
    ax.plot(p[-1, 0], p[-1, 1], "x", color=color, ms=6)


def draw_spheres(ax, clf, dims=(0, 1), feature_names=None, max_spheres: int = 3000) -> None:
    arrays = clf.tree_arrays() if hasattr(clf, "tree_arrays") else None
    if arrays is None:
        return
    centers = np.asarray(arrays.get("centers", arrays.get("center")))
    radii = np.asarray(arrays.get("radii", arrays.get("radius")))
    labels = np.asarray(arrays.get("labels", arrays.get("label")))
    classes = list(getattr(clf, "classes_", []))
    distance = getattr(clf, "distance", "squared")
    order = np.argsort(-radii)[:max_spheres]
    seen: set = set()
    for i in order:
        lab = labels[i]
        name = classes[int(lab)] if classes and np.issubdtype(np.asarray(lab).dtype, np.integer) \
            and int(lab) < len(classes) else lab
        color = _LABEL_COLORS[(classes.index(name) if name in classes else hash(str(name))) % len(_LABEL_COLORS)]
        r = float(radii[i])
        r = math.sqrt(r) if distance == "squared" else r  # a squared radius r encloses sqrt(r)
        ax.add_patch(Circle((centers[i][dims[0]], centers[i][dims[1]]), r, fill=False, color=color,
                            lw=0.6, alpha=0.7, label=None if name in seen else str(name)))
        seen.add(name)
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.set_aspect("equal")
    names = feature_names or [f"feature {d}" for d in range(max(dims) + 1)]
    ax.set_xlabel(names[dims[0]])
    ax.set_ylabel(names[dims[1]])
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title(f"spheres on features {dims[0]}, {dims[1]}")


def plot_paths(world, paths: dict, out, title: str | None = None, spheres=None, dims=(0, 1),
               feature_names=None, overlay: bool = False) -> Path:
    """One panel per driver, side by side like the paper's figures 3 and 4 ((a) the teacher's
    path, (b) the learned robot's), or every path on one panel with ``overlay=True``; a sphere
    panel is appended when ``spheres`` is given."""
    out = Path(out)
    groups = [dict(paths)] if overlay else [{name: ps} for name, ps in paths.items()] or [{}]
    ncols = len(groups) + (spheres is not None)
    fig, axes = plt.subplots(1, ncols, figsize=(6.5 * ncols, 6), squeeze=False)
    for g, (ax, group) in enumerate(zip(axes[0], groups, strict=False)):
        draw_world(ax, world)
        for k, (name, ps) in enumerate(group.items()):
            color = COLORS.get(name, _LABEL_COLORS[(g + k) % len(_LABEL_COLORS)])
            runs = ps if (len(ps) and np.ndim(ps[0]) == 2) else [ps]
            for j, p in enumerate(runs):
                draw_path(ax, p, label=name if j == 0 else None, color=color)
        if group:
            ax.legend(fontsize=8, loc="best")
        if not overlay and len(groups) > 1:
            ax.set_title(f"({chr(ord('a') + g)}) {next(iter(group))}")
    if title:
        fig.suptitle(title)
    if spheres is not None:
        draw_spheres(axes[0][-1], spheres, dims=dims, feature_names=feature_names)
    fig.tight_layout()
    try:  # a regular file or a new one only, written atomically (process.files)
        with files.replace_file(out) as tmp:
            fig.savefig(tmp, dpi=110, format=out.suffix[1:].lower() or "png")
    finally:
        plt.close(fig)
    return out
