"""The controller's decision for a scan, published for viewers.

``Decider(session, robot).publish(policy, x, scan)`` takes the root-to-winner path of the
features ``x`` (``decision_path``: its winner's label is what ``predict_one`` answered) and
publishes a ``Decision`` on ``rhbl/<robot>/controller/decision`` (docs/protocol.md) without
blocking. The controller calls it after it has sent the scan's command, so the path and its
encoding never delay the robot; and it does that work only while something subscribes to the
key (zenoh's matching status: a console, a recorder), so a controller nobody watches answers
scans back to back as fast as without decisions. A viewer that cannot keep up loses decisions.
"""

from __future__ import annotations

import contextlib

import zenoh

from protocol import keys
from protocol.messages import Decision, DecisionGoal, Scan

__all__ = ["Decider", "snapshot_id"]


def snapshot_id(metadata: dict) -> str:
    """``<lineage>:<records>`` of a learner's snapshot (as its notices name it), else ``""``."""
    j = (metadata.get("provenance") or {}).get("journal") or {}
    if j.get("lineage") is None:
        return ""
    return f"{j['lineage']}:{j.get('records', 0)}"


class Decider:
    def __init__(self, session: zenoh.Session, robot: str):
        self._pub = session.declare_publisher(keys.controller_decision_key(robot),
                                              congestion_control=zenoh.CongestionControl.DROP)
        self._tree = None
        self._sid = ""
        # whether any subscriber matches the key: kept current by zenoh's matching listener
        self._watched = self._pub.matching_status.matching
        self._matching = self._pub.declare_matching_listener(self._on_matching)

    def _on_matching(self, status: zenoh.MatchingStatus) -> None:
        self._watched = status.matching

    def publish(self, policy, x, scan: Scan, executed: str | None = None,
                looping: bool = False, goal: DecisionGoal | None = None,
                goal_why: str | None = None) -> str | None:
        """Publish the decision of the policy's tree for the features ``x`` of ``scan``; returns
        the action (the winner's label), or None when nothing subscribes to decisions.
        ``executed``: the action commanded, when the loop guard overruled the tree's (said
        only when it differs); ``looping``: the guard stepped in lately; a tree with goals:
        ``goal`` the goal pursued, ``goal_why`` why the last goal changed (cut to
        ``Decision.MAX_GOAL_WHY`` characters)."""
        if not self._watched:
            return None
        clf = policy.classifier
        path = clf.decision_path(x)
        action = str(path[-1]["label"])
        if clf is not self._tree:  # a swapped-in tree (--follow)
            self._tree, self._sid = clf, snapshot_id(policy.metadata)
        self._pub.put(Decision(
            scan_id=scan.id, ts=scan.ts, action=action, snapshot_id=self._sid,
            nodes=int(getattr(clf, "node_count_", 0)),
            path=tuple((e["index"], e["depth"], e["radius"], str(e["label"])) for e in path),
            executed=executed if executed is not None and executed != action else None,
            looping=bool(looping), goal=goal,
            goal_why=None if goal_why is None else goal_why[:Decision.MAX_GOAL_WHY],
        ).encode())
        return action

    def close(self) -> None:
        with contextlib.suppress(Exception):  # the session is closing
            self._matching.undeclare()
        with contextlib.suppress(Exception):
            self._pub.undeclare()
