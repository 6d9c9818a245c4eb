"""The one table formatter of ``rhbl evaluate``, ``rhbl experiment`` and ``rhbl demo``:
markdown rows (readable in a terminal, pasteable into docs/experiments.md).

    print(table(["world", "success"], [["room", "100%"]], title="Success"))
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

__all__ = ["EPISODE_HEADERS", "episode_row", "episode_table", "table"]


def table(headers: Sequence[str], rows: Iterable[Sequence[object]], title: str | None = None,
          notes: Iterable[str] = ()) -> str:
    """A markdown table: optional ``title`` line, the header row, ``|---|`` and one row per
    entry (cells with ``str``); ``notes`` lines follow the table."""
    lines = [] if title is None else [title]
    lines.append("| " + " | ".join(headers) + " |")
    lines.append("|" + "---|" * len(headers))
    for row in rows:
        cells = [str(c) for c in row]
        if len(cells) != len(headers):
            raise ValueError(f"a table row has {len(cells)} cells for {len(headers)} columns: "
                             f"{cells!r}")
        lines.append("| " + " | ".join(cells) + " |")
    lines.extend(notes)
    return "\n".join(lines)


EPISODE_HEADERS = ("driver", "start (x, y, yaw)", "seconds", "collisions", "distance m",
                   "in band", "goal", "oscillations", "agreement")


def episode_row(driver: str, m: dict) -> list[str]:
    """One row of ``episode_table`` from an episode's metrics (``lab.episode.Episode.metrics``;
    with a ``success`` key: one more cell)."""
    band = m["wall_band_fraction"]
    goal = ("-" if m["goal_reached"] is None else
            (f"yes, {m['time_to_goal']:.0f} s" if m["goal_reached"] else "no"))
    if m.get("goals_total"):  # goals in order: how many of them, in order
        goal = f"{m['goals_reached']}/{m['goals_total']} in order"
    agree = m.get("teacher_agreement")
    row = [driver, "(" + ", ".join(f"{v:.2f}" for v in (m["start"] or [])) + ")",
           f"{m['seconds']:.0f}", str(m["collisions"]), f"{m['distance']:.1f}",
           "-" if band is None else f"{100 * band:.0f}%", goal, str(m["oscillations"]),
           "-" if agree is None else f"{agree:.2f}"]
    if "success" in m:
        row.append("yes" if m["success"] else "no")
    return row


def episode_table(entries, title: str | None = None, notes=()) -> str:
    """What drivers did, one row per ``(driver, metrics)`` entry (sim seconds per episode; band
    = the fraction of time with the followed wall within the band of ``lab.metrics.BAND``)."""
    entries = list(entries)
    headers = list(EPISODE_HEADERS)
    if entries and "success" in entries[0][1]:
        headers.append("success")
    return table(headers, (episode_row(d, m) for d, m in entries), title=title, notes=notes)
