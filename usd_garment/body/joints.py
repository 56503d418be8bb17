"""The 24 SMPL joints: names, order and kinematic tree, in one place for the whole package."""

from __future__ import annotations

SMPL_JOINT_NAMES: tuple[str, ...] = (
    "pelvis",
    "left_hip",
    "right_hip",
    "spine1",
    "left_knee",
    "right_knee",
    "spine2",
    "left_ankle",
    "right_ankle",
    "spine3",
    "left_foot",
    "right_foot",
    "neck",
    "left_collar",
    "right_collar",
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_hand",
    "right_hand",
)

#: Parent index of each joint (-1 for the root), SMPL's kintree_table[0].
SMPL_PARENTS: tuple[int, ...] = (
    -1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21,
)  # fmt: skip

NUM_JOINTS: int = len(SMPL_JOINT_NAMES)
NUM_BETAS: int = 10


#: USD joint paths of the SMPL skeleton (parent/child/...), as UsdSkel wants them.
def smpl_joint_paths() -> list[str]:
    """Return the 24 UsdSkel joint paths, e.g. ``pelvis/spine1/spine2``, in SMPL order."""
    paths: list[str] = []
    for i, name in enumerate(SMPL_JOINT_NAMES):
        parent = SMPL_PARENTS[i]
        paths.append(name if parent < 0 else f"{paths[parent]}/{name}")
    return paths
