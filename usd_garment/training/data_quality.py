"""How good a dataset's simulations are, from its manifest: each sequence's simulation checks
(written by ``make_dataset``) summed up per split, per motion kind or per sequence, against the
ground truth's targets (inside the body elsewhere at most 0.05 % of the vertices on average and
0.5 % in any frame, no NaN, no vertex farther than 10 cm from the body).

Shares are fractions of the garment's vertices; "elsewhere" is inside the body where the pose
does not force it (``usd_garment.eval.metrics``). Means over several sequences are weighted by
their frames; maxima are over every frame of every sequence of the group.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from usd_garment.sim.checks import CheckLimits

#: Targets of the ground truth: mean and single-frame share of vertices inside elsewhere, and
#: the largest distance (m) of a vertex from the body (the T-shirt's, the simulator's own target).
ELSEWHERE_MEAN_TARGET = 5e-4
ELSEWHERE_FRAME_TARGET = 5e-3
DISTANCE_TARGET = CheckLimits().far_distance
#: Ways of grouping the sequences.
GROUPINGS = ("split", "kind", "sequence")


@dataclass(frozen=True)
class GroupQuality:
    """The simulation checks of one group of sequences.

    Attributes:
        group: the split, the motion kind (a capture: its file's stem) or the sequence; "all"
            for the whole set.
        sequences: sequences planned in the group.
        ok: sequences simulated (the others are bad or not done yet).
        frames: frames of the ok sequences.
        elsewhere_mean: frame-weighted mean share of vertices inside the body elsewhere.
        elsewhere_max: that share in the worst frame.
        forced_mean: frame-weighted mean share of vertices inside the body where the pose
            forces it (a limb pressed into the trunk).
        above_mean: ok sequences whose mean inside-elsewhere share is above the target.
        above_frame: ok sequences with a frame above the single-frame target.
        far: ok sequences with a vertex farther from the body than the distance target.
        max_distance_m: largest distance of a vertex from the body (m).
        stretch_p99_max: worst frame's 99th percentile of edge length over rest length.
        stretch_max: the most stretched single edge (edge length over rest length); None when
            no sequence's manifest entry records it (made before stop 40).
        nan_frames: frames with a non-finite vertex.
        retried_frames: frames simulated again with more substeps.
        bad_frames: frames kept although they failed their checks at the most substeps.
        seconds: simulation time summed over the ok sequences (s).
    """

    group: str
    sequences: int
    ok: int
    frames: int
    elsewhere_mean: float
    elsewhere_max: float
    forced_mean: float
    above_mean: int
    above_frame: int
    far: int
    max_distance_m: float
    stretch_p99_max: float
    stretch_max: float | None
    nan_frames: int
    retried_frames: int
    bad_frames: int
    seconds: float

    def to_json(self) -> dict[str, Any]:
        """The row as plain JSON values."""
        return asdict(self)


def _kind(entry: dict[str, Any]) -> str:
    return Path(entry["capture"]).stem if entry.get("capture") else entry["motion_kind"]


_KEYS: dict[str, Callable[[dict[str, Any]], str]] = {
    "split": lambda entry: entry["split"],
    "kind": _kind,
    "sequence": lambda entry: entry["name"],
}


def _group(name: str, entries: list[dict[str, Any]]) -> GroupQuality:
    ok = [e for e in entries if e["status"] == "ok" and "checks" in e]
    checks = [e["checks"] for e in ok]
    frames = sum(e["frames"] for e in ok)

    def mean(key: str) -> float:
        weighted = sum(c[key] * e["frames"] for c, e in zip(checks, ok, strict=True))
        return weighted / frames if frames else 0.0

    def most(key: str) -> float:
        return max((c[key] for c in checks), default=0.0)

    return GroupQuality(
        group=name,
        sequences=len(entries),
        ok=len(ok),
        frames=frames,
        elsewhere_mean=mean("inside_elsewhere_share_mean"),
        elsewhere_max=most("inside_elsewhere_share_max"),
        forced_mean=mean("inside_forced_share_mean"),
        above_mean=sum(c["inside_elsewhere_share_mean"] > ELSEWHERE_MEAN_TARGET for c in checks),
        above_frame=sum(c["inside_elsewhere_share_max"] > ELSEWHERE_FRAME_TARGET for c in checks),
        far=sum(c["max_distance_m"] > DISTANCE_TARGET for c in checks),
        max_distance_m=most("max_distance_m"),
        stretch_p99_max=most("stretch_p99_max"),
        stretch_max=max(
            (c["stretch_max"] for c in checks if c.get("stretch_max") is not None), default=None
        ),
        nan_frames=sum(c["nan_frames"] for c in checks),
        retried_frames=sum(len(c["retries"]) for c in checks),
        bad_frames=sum(c["bad_frames"] for c in checks),
        seconds=sum(e.get("seconds", 0.0) for e in ok),
    )


def dataset_quality(manifest: dict[str, Any], by: str = "split") -> list[GroupQuality]:
    """The simulation checks of a dataset, grouped.

    Args:
        manifest: a dataset manifest (``read_manifest``).
        by: one of ``GROUPINGS``: per split, per motion kind (each capture on its own) or per
            sequence.

    Returns:
        One row per group in the manifest's order of first appearance, then "all".

    Raises:
        ValueError: an unknown grouping.
    """
    if by not in _KEYS:
        raise ValueError(f"unknown grouping {by!r}: one of {', '.join(GROUPINGS)}")
    groups: dict[str, list[dict[str, Any]]] = {}
    for entry in manifest["sequences"]:
        groups.setdefault(_KEYS[by](entry), []).append(entry)
    rows = [_group(name, entries) for name, entries in groups.items()]
    return [*rows, _group("all", list(manifest["sequences"]))]


#: The checks of a sequence that time its simulation: a simulation made again gives every other
#: check equal when it is the same simulation.
TIME_CHECKS = ("seconds_per_frame",)


@dataclass(frozen=True)
class SequenceChange:
    """One sequence of a dataset made again, against the manifest it was made from before.

    Attributes:
        name: the sequence.
        kind: its motion kind (a capture: its file's stem).
        status: its status before and now ("absent" where a manifest lacks the sequence).
        changed: the checks whose figures differ (all but :data:`TIME_CHECKS`, and only those
            both manifests record: a check made before it was recorded is not compared), and
            "status" first when it differs; empty when the sequence came out the same.
        before: its checks before (empty if none).
        now: its checks now (empty if none).
    """

    name: str
    kind: str
    status: tuple[str, str]
    changed: tuple[str, ...]
    before: dict[str, Any]
    now: dict[str, Any]

    @property
    def same(self) -> bool:
        """Whether the sequence came out with the figures it had."""
        return not self.changed

    @property
    def largest_relative_change(self) -> float | None:
        """The largest ``|now - before| / max(|before|, |now|)`` over the changed checks that are
        numbers, to tell a few vertices from a changed simulation; None when no changed check is a
        number (only the status or the retried frames)."""
        ratios = [
            abs(b - a) / max(abs(a), abs(b))
            for a, b in ((self.before[k], self.now[k]) for k in self.changed if k != "status")
            if _is_number(a) and _is_number(b)
        ]
        return max(ratios, default=None)

    def to_json(self) -> dict[str, Any]:
        """The comparison as plain JSON values."""
        return {
            **asdict(self), "same": self.same,
            "largest_relative_change": self.largest_relative_change,
        }  # fmt: skip


def _is_number(value: Any) -> bool:
    """Whether a check's value is a number (not a bool, a list or a per-frame record)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def compare_manifests(before: dict[str, Any], now: dict[str, Any]) -> list[SequenceChange]:
    """Each sequence of a dataset made again (``now``) against the manifest it had
    (``before``, e.g. the committed one): the same simulation gives the same figures.

    Returns:
        One comparison per sequence, in ``now``'s order, then those only ``before`` has.
    """
    old = {entry["name"]: entry for entry in before["sequences"]}
    new = {entry["name"]: entry for entry in now["sequences"]}
    rows = []
    for name in [*new, *(n for n in old if n not in new)]:
        a, b = old.get(name), new.get(name)
        entry = new[name] if name in new else old[name]
        checks_a = (a or {}).get("checks") or {}
        checks_b = (b or {}).get("checks") or {}
        status = (a["status"] if a else "absent", b["status"] if b else "absent")
        changed = ("status",) if status[0] != status[1] else ()
        changed += tuple(
            key for key in checks_b
            if key not in TIME_CHECKS and key in checks_a and checks_a[key] != checks_b[key]
        )  # fmt: skip
        rows.append(SequenceChange(name, _kind(entry), status, changed, checks_a, checks_b))
    return rows
