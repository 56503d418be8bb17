"""Match a rig's joints to the 24 SMPL joints by leaf name through an alias table.

Accepted spellings of, e.g., ``left_knee``: ``left_knee``, ``L_Knee``, ``m_avg_L_Knee``,
``LeftKnee``, ``knee_l``, ``Knee.L`` — with any namespace prefix (``smplx:``), in any order and
at any depth (``root/pelvis/...``). Joints that match nothing (fingers, face, an extra ``root``)
are ignored. SMPL-H and SMPL-X rigs have no ``left_hand`` / ``right_hand`` joints (fingers hang
from the wrists), so those two are optional.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

from usd_garment.body.joints import SMPL_JOINT_NAMES
from usd_garment.usd.errors import UsdInputError

#: SMPL joints a rig may lack; their local rotation is then zero.
OPTIONAL_JOINTS: frozenset[str] = frozenset({"left_hand", "right_hand"})

#: Extra spellings of a joint's base name (after the side is removed).
_BASE_SYNONYMS: dict[str, tuple[str, ...]] = {
    "pelvis": ("pelvis",),
    "collar": ("collar", "clavicle"),
    "spine1": ("spine1", "spine01"),
    "spine2": ("spine2", "spine02"),
    "spine3": ("spine3", "spine03"),
}

#: Prefixes of SMPL exports that carry no meaning (Maya / Unity ``m_avg_``, ``f_avg_``, ...).
_PREFIXES = re.compile(r"^(?:[mf]_avg_|smpl[hx]?_|j_)", re.IGNORECASE)


def normalize_joint_name(leaf: str) -> str:
    """Lower-case key of a joint leaf name: namespace and export prefix dropped, no separators."""
    name = leaf.rsplit(":", 1)[-1]
    name = _PREFIXES.sub("", name)
    return re.sub(r"[^a-z0-9]", "", name.lower())


def _build_alias_table() -> dict[str, str]:
    table: dict[str, str] = {}
    for smpl in SMPL_JOINT_NAMES:
        side, _, base = smpl.partition("_")
        if side not in ("left", "right"):
            for key in _BASE_SYNONYMS.get(smpl, (smpl,)):
                table[key] = smpl
            continue
        s = side[0]
        for b in _BASE_SYNONYMS.get(base, (base,)):
            for key in (f"{side}{b}", f"{s}{b}", f"{b}{side}", f"{b}{s}"):
                table[key] = smpl
    return table


#: Normalized leaf name -> SMPL joint name.
JOINT_ALIASES: dict[str, str] = _build_alias_table()


def match_smpl_joints(joint_paths: Sequence[str], where: str = "skeleton") -> list[int | None]:
    """Index of each SMPL joint in ``joint_paths`` (UsdSkel joint tokens), in SMPL order.

    Returns:
        24 entries: the rig joint index, or None for an absent optional joint.

    Raises:
        UsdInputError: a required SMPL joint is missing, or two rig joints claim the same one.
    """
    found: dict[str, int] = {}
    for i, path in enumerate(joint_paths):
        smpl = JOINT_ALIASES.get(normalize_joint_name(str(path).rsplit("/", 1)[-1]))
        if smpl is None:
            continue
        if smpl in found:
            first = joint_paths[found[smpl]]
            raise UsdInputError(
                f"{where}: joints '{first}' and '{path}' both match SMPL joint '{smpl}'"
            )
        found[smpl] = i
    missing = [n for n in SMPL_JOINT_NAMES if n not in found and n not in OPTIONAL_JOINTS]
    if missing:
        raise UsdInputError(f"{where}: missing SMPL joints: {', '.join(missing)}")
    return [found.get(n) for n in SMPL_JOINT_NAMES]
