"""BVH motion captures (CMU, Mixamo, SMPL-named rigs) retargeted to SMPL motions.

Parsing follows the usual BVH conventions: a joint's rotation is the product of its Euler
channels in the listed order, ``R = R(ch1) · R(ch2) · R(ch3)`` (intrinsic, degrees); a joint
with position channels takes them as its local translation (its OFFSET is then ignored on those
axes); every joint's rest orientation is the identity, so the OFFSETs with all channels zero
are the rest pose.

Retargeting works on world (global) rotations, so BVH joints that SMPL lacks (CMU's
``LHipJoint``, ``Neck1``, ``lhand`` ...) are folded into the mapped joints below them:

1. BVH joints are matched to SMPL joints by name for the limbs (an alias table that knows CMU,
   Mixamo and SMPL spellings) and by structure for the spine (the joints between the hips and
   the chest, where the arms and the neck branch off, spread over ``spine1..3``).
2. Each mapped SMPL joint ``j`` takes the global rotation ``G_bvh`` of the BVH joint that
   drives its bone (the parent of the first BVH joint with a non-zero OFFSET on the way to the
   next mapped joint) times a rest correction ``C_j``: the rotation that takes SMPL's rest bone
   direction (child joint − joint, in the body's T-pose) to the BVH's rest bone direction (from
   the OFFSETs): the shortest arc for one child; for several (pelvis, chest), the primary bone
   exactly and the others, least-squares, fixing the twist about it; each fitted after the
   SMPL parent's correction, so a rig's overall turn carries down the chain. So
   ``G_smpl = G_bvh · C_j``, and SMPL's bones point along the BVH's in any pose. With
   ``collars="rest"`` the collars (:data:`REST_RELATIVE`) keep their parent's correction
   instead: they turn as the BVH's collars turn from the rig's rest, from SMPL's own rest
   collars (the default; ``"aimed"`` shrugs CMU captures: see :data:`COLLAR_MODES`).
3. SMPL local rotations follow in SMPL's hierarchy, ``R_local = G_parent^T · G``; SMPL joints
   without a BVH counterpart get the identity.
4. Where the body's proportions put an arm through the trunk (the capture's shoulders sit where
   the body's trunk is wider), the shoulders open outwards, smoothly over time, until each arm
   keeps :data:`ARM_CONTACT_CLEARANCE` from the torso
   (:func:`usd_garment.motion.procedural.open_shoulders`); arms may still rest against it.
5. The SMPL pelvis follows the BVH hips: ``trans = hips_world − J0`` (SMPL's root rotation pivots
   about the rest pelvis J0), then shifted vertically so that the body stands on y = 0
   (:func:`floor_height`; bone lengths differ, so the capture's own floor would not fit).
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from usd_garment.body.betas import MAX_ABS_BETA, as_betas
from usd_garment.body.joints import NUM_JOINTS, SMPL_JOINT_NAMES, SMPL_PARENTS
from usd_garment.body.model import BodyModel
from usd_garment.motion.amass import ZUP_TO_YUP, rest_pelvis
from usd_garment.motion.asf_amc import is_amc_path, read_amc
from usd_garment.motion.capture_clip import (
    BvhClip,
    BvhError,
    BvhSkeleton,
    has_suffix,
    parse_floats,
    read_text,
)
from usd_garment.motion.procedural import open_shoulders, turn_shoulders
from usd_garment.motion.resample import resample_motion
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.joint_aliases import normalize_joint_name

#: Metres per file unit of the unit names ``--units`` accepts; "cmu" is the length unit of the
#: CMU database's ASF skeletons (1/0.45 inch), kept by B. Hahne's BVH conversion (cgspeed).
UNITS: dict[str, float] = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "in": 0.0254,
    "ft": 0.3048,
    "cmu": 0.0254 / 0.45,
}

#: Units that ``units="auto"`` chooses between, by the rest skeleton's height.
AUTO_UNITS: tuple[str, ...] = ("m", "cm", "mm", "cmu")

#: Heights (m) of the rest skeleton that automatic unit detection accepts.
PLAUSIBLE_HEIGHT_M: tuple[float, float] = (0.5, 3.0)

#: Floor handling: ``"body"`` moves the clip vertically so that the body stands on y = 0 (see
#: :func:`floor_height`); ``"capture"`` keeps the capture's heights.
FLOOR_MODES: tuple[str, ...] = ("body", "capture")
#: Percentile of the per-frame lowest body point that ``"body"`` puts on the floor, and the
#: most frames it poses to find it.
FLOOR_PERCENTILE = 10.0
FLOOR_SAMPLES = 300

#: Default smallest distance (m) between the vertices of an arm and of the torso that the
#: retargeted motion keeps, opening the shoulders where needed (``arm_clearance``): small enough
#: for the arms to rest against the trunk, large enough that no arm passes through it (nearest
#: vertices closer than this are where the surfaces cross).
ARM_CONTACT_CLEARANCE = 0.005
#: Most frames per second at which the arm clearance is measured; the opening is interpolated
#: between (it is smoothed over 0.2 s anyway).
ARM_CHECK_FPS = 30.0

#: Up axes of the BVH file ``up_axis`` accepts (``"auto"``: the rest skeleton's hips→head axis).
UP_AXES: tuple[str, ...] = ("auto", "y", "z")

#: SMPL joints a BVH skeleton must have (the spine is found from where arms and head branch).
REQUIRED_JOINTS: tuple[str, ...] = (
    "pelvis", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
    "head", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist",
    "right_wrist",
)  # fmt: skip

#: The SMPL child whose bone a joint's rotation is fitted to first (chain order for joints
#: that a BVH may lack).
PRIMARY_CHILD: dict[str, str] = {
    "pelvis": "spine1", "spine1": "spine2", "spine2": "spine3", "spine3": "neck", "neck": "head",
    "left_hip": "left_knee", "left_knee": "left_ankle", "left_ankle": "left_foot",
    "right_hip": "right_knee", "right_knee": "right_ankle", "right_ankle": "right_foot",
    "left_collar": "left_shoulder", "left_shoulder": "left_elbow", "left_elbow": "left_wrist",
    "left_wrist": "left_hand", "right_collar": "right_shoulder",
    "right_shoulder": "right_elbow", "right_elbow": "right_wrist", "right_wrist": "right_hand",
}  # fmt: skip

#: SMPL joints that ``collars="rest"`` turns with their BVH joint's rotation from the rig's rest
#: instead of aiming their bone along the BVH's: where rigs place the joint differently, the
#: bones' rest directions differ by convention, not by posture.
REST_RELATIVE: tuple[str, ...] = ("left_collar", "right_collar")
#: How the collars are retargeted: ``"aimed"`` points SMPL's collar bones along the BVH's like
#: every other bone; CMU's collar starts at the middle of the chest, so its bone to the shoulder
#: rises by about 22° where SMPL's falls by 8°, and aimed along it SMPL's collars turn up by
#: 22–35° in every frame, the shoulder joints 6–9 cm higher along the chest than in SMPL's rest
#: (a shrug). ``"rest"`` (the default since stop 59) turns them from SMPL's rest collars
#: (:data:`REST_RELATIVE`): the body the capture shows. The T-shirt from version 8 on and the dress
#: from version 10 on were trained on ``"rest"`` captures; the dress's version 9 and the T-shirt's
#: version 7 on ``"aimed"`` ones (``docs/mocap.md``, "The collars").
COLLAR_MODES: tuple[str, ...] = ("aimed", "rest")
#: The collar mode of every reader and command that is not told one.
DEFAULT_COLLARS = "rest"

#: Frame 0 of a capture is a reference pose, not a frame of the motion (the CMU conversions'
#: added T-pose), where some joint turns more than this (rad) from it into frame 1, and more than
#: :data:`REFERENCE_RATIO` times any joint's turn from frame 1 to 2. The CMU BVH conversions here
#: turn a joint 59-180 degrees there; their next step, and the first step of every capture
#: without a reference pose, at most 28 degrees (120 fps; stop 81).
REFERENCE_JUMP = math.radians(45.0)
REFERENCE_RATIO = 2.0

_CHANNEL = re.compile(r"^([xyz])(position|rotation)$", re.IGNORECASE)
_FLOAT = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


@dataclass
class BvhRetarget:
    """How a BVH skeleton maps onto SMPL, besides the motion itself.

    Attributes:
        joint_map: SMPL joint name → BVH joint name, for the mapped joints.
        drivers: SMPL joint name → the BVH joint whose world rotation it takes (its mapped
            joint, or one below it at the same place, e.g. ``spine3`` ← ``lowerneck``).
        unmapped: SMPL joints without a counterpart (identity local rotation).
        folded: unmapped BVH joints between mapped ones (``LHipJoint``, ``Neck1``), whose
            rotations reach SMPL through the world rotations of the joints below them.
        ignored: BVH joints beyond the mapped ones (fingers, thumbs, toe ends).
        scale: metres per file unit.
        units: the unit name (``"cm"``), or ``"custom"`` for an explicit scale.
        units_detected: whether the units were detected from the skeleton's height.
        height_m: the rest skeleton's vertical extent (m).
        up_axis: the file's up axis, ``"y"`` or ``"z"``.
        floor: the floor mode (see :data:`FLOOR_MODES`).
        floor_shift_m: vertical shift added to the capture's heights (m).
        source_fps: the file's frame rate.
        rest_corrections: ``(24, 3, 3)`` rest corrections ``C_j`` (column convention).
        arm_clearance_m: the clearance the shoulders were opened to keep (None: off).
        shoulder_opening: ``(T, 2)`` rad, how far each shoulder (left, right) was opened per
            frame of the motion (zeros when off).
        reference_left_out: frame 0 was left out as a reference pose (:func:`leads_with_reference`).
    """

    joint_map: dict[str, str]
    drivers: dict[str, str]
    unmapped: list[str]
    folded: list[str]
    ignored: list[str]
    scale: float
    units: str
    units_detected: bool
    height_m: float
    up_axis: str
    floor: str
    floor_shift_m: float
    source_fps: float
    rest_corrections: np.ndarray
    arm_clearance_m: float | None = None
    shoulder_opening: np.ndarray | None = None
    reference_left_out: bool = False

    def opening_summary(self, threshold_deg: float = 0.1) -> dict[str, float | int]:
        """Shoulder opening in degrees over both sides: ``mean``, ``max``, and ``frames`` (how
        many frames either side opens by more than ``threshold_deg``)."""
        deg = np.degrees(
            np.zeros((0, 2)) if self.shoulder_opening is None else self.shoulder_opening
        )
        if deg.size == 0:
            return {"mean_deg": 0.0, "max_deg": 0.0, "frames": 0}
        return {
            "mean_deg": round(float(deg.mean()), 2),
            "max_deg": round(float(deg.max()), 2),
            "frames": int(np.count_nonzero(deg.max(axis=1) > threshold_deg)),
        }


# --------------------------------------------------------------------------------------------
# Parsing


def is_bvh_path(path: str | Path) -> bool:
    """Whether ``path`` names a BVH file by its suffix: ``.bvh``, or ``.bvh.xz`` / ``.bvh.gz``."""
    return has_suffix(path, ".bvh")


def read_capture(path: str | Path) -> BvhClip:
    """The capture at ``path``: a BVH file (:func:`read_bvh`) or an AMC one, its ASF found beside
    it (:func:`usd_garment.motion.asf_amc.read_amc`), by its name.

    Raises:
        BvhError: see :func:`read_bvh` and ``read_amc``.
        OSError: a file cannot be read.
    """
    return read_amc(path) if is_amc_path(path) else read_bvh(path)


def is_capture_path(path: str | Path) -> bool:
    """Whether ``path`` names a capture :func:`load_bvh` reads: BVH or AMC, by its suffix."""
    return is_bvh_path(path) or is_amc_path(path)


def read_bvh(path: str | Path) -> BvhClip:
    """Parse the BVH file at ``path``, xz- or gzip-compressed where its name ends in ``.xz`` or
    ``.gz``.

    Raises:
        BvhError: not a BVH file (or a broken compressed one), a broken HIERARCHY, or a MOTION
            section with missing or non-finite values.
        OSError: the file cannot be read.
    """
    return parse_bvh(read_text(path, "BVH"), str(path))


def parse_bvh(text: str, source: str = "<bvh>") -> BvhClip:
    """Parse BVH ``text``; ``source`` names it in error messages.

    Raises:
        BvhError: see :func:`read_bvh`.
    """
    lines = text.splitlines()
    first = next((line.split()[0] for line in lines if line.strip()), "")
    if first.upper() != "HIERARCHY":
        raise BvhError(f"{source}: not a BVH file (no HIERARCHY at the start)")
    motion_row = next((i for i, line in enumerate(lines) if line.strip().upper() == "MOTION"), None)
    if motion_row is None:
        raise BvhError(f"{source}: no MOTION section")
    statements = [
        (row + 1, piece.split())
        for row, line in enumerate(lines[:motion_row])
        for piece in re.split(r"([{}])", line)
        if piece.strip()
    ]
    skeleton = _parse_hierarchy(statements[1:], source)
    values, frame_time = _parse_motion(lines, motion_row + 1, skeleton.num_channels, source)
    return BvhClip(skeleton, values, frame_time)


def _parse_hierarchy(statements: list[tuple[int, list[str]]], source: str) -> BvhSkeleton:
    """The skeleton from the HIERARCHY's statements: (line number, words), braces apart."""
    names: list[str] = []
    parents: list[int] = []
    offsets: list[np.ndarray] = []
    channels: list[tuple[str, ...]] = []
    end_sites: dict[int, np.ndarray] = {}
    stack: list[int] = []  # open blocks: joint index, or -2 for an End Site
    pending: int | None = None  # block just declared, waiting for its "{"
    closed = False
    for row, words in statements:
        key = words[0].upper()
        where = f"{source}:{row}"
        if closed:
            raise BvhError(f"{where}: '{words[0]}' after the end of the HIERARCHY")
        if key in ("ROOT", "JOINT"):
            if (key == "ROOT") != (not stack) or len(words) < 2 or pending is not None:
                raise BvhError(f"{where}: misplaced {words[0]}")
            if stack and stack[-1] == -2:
                raise BvhError(f"{where}: a joint inside an End Site")
            names.append(" ".join(words[1:]))
            parents.append(stack[-1] if stack else -1)
            offsets.append(np.zeros(3))
            channels.append(())
            pending = len(names) - 1
        elif key == "END":
            if not stack or stack[-1] == -2 or pending is not None:
                raise BvhError(f"{where}: misplaced End Site")
            pending = -2
        elif key == "{":
            if pending is None:
                raise BvhError(f"{where}: '{{' without a joint")
            if pending == -2:
                end_sites[stack[-1]] = np.full(3, np.nan)
            stack.append(pending)
            pending = None
        elif key == "}":
            if not stack or pending is not None:
                raise BvhError(f"{where}: unbalanced '}}'")
            stack.pop()
            closed = not stack
        elif key == "OFFSET":
            if not stack or pending is not None or len(words) != 4:
                raise BvhError(f"{where}: bad OFFSET")
            vec = parse_floats(words[1:], where)
            if stack[-1] == -2:
                end_sites[stack[-2]] = vec
            else:
                offsets[stack[-1]] = vec
        elif key == "CHANNELS":
            if not stack or stack[-1] == -2 or pending is not None:
                raise BvhError(f"{where}: misplaced CHANNELS")
            channels[stack[-1]] = _channels(words, where)
        else:
            raise BvhError(f"{where}: unexpected '{words[0]}' in the HIERARCHY")
    if not closed:
        raise BvhError(f"{source}: the HIERARCHY is incomplete")
    ends = np.full((len(names), 3), np.nan)
    for joint, vec in end_sites.items():
        ends[joint] = vec
    skeleton = BvhSkeleton(
        names=names,
        parents=np.asarray(parents, dtype=np.int64),
        offsets=np.stack(offsets),
        channels=channels,
        end_sites=ends,
    )
    if skeleton.num_channels == 0:
        raise BvhError(f"{source}: the skeleton has no channels")
    return skeleton


def _channels(words: list[str], where: str) -> tuple[str, ...]:
    """The channel names of a ``CHANNELS n name...`` statement, checked."""
    names = tuple(words[2:])
    if len(words) < 2 or words[1] != str(len(names)):
        raise BvhError(f"{where}: the CHANNELS count does not match the names")
    matches = [_CHANNEL.match(c) for c in names]
    if not all(matches):
        raise BvhError(f"{where}: unknown channel in '{' '.join(names)}'")
    rotations = "".join(m.group(1).lower() for m in matches if m and m.group(2)[0] in "rR")
    positions = [m.group(1).lower() for m in matches if m and m.group(2)[0] in "pP"]
    if len(rotations) > 3 or any(a == b for a, b in pairwise(rotations)):
        raise BvhError(f"{where}: rotation channels must be 1 to 3 Euler angles")
    if len(set(positions)) != len(positions):
        raise BvhError(f"{where}: a position channel appears twice")
    return names


def _skip_blank(lines: list[str], row: int) -> int:
    while row < len(lines) and not lines[row].strip():
        row += 1
    return row


def _parse_motion(
    lines: list[str], row: int, num_channels: int, source: str
) -> tuple[np.ndarray, float]:
    """Channel values ``(T, C)`` and the frame time (s) from the lines after ``MOTION``."""
    row = _skip_blank(lines, row)
    frames_match = re.match(r"^\s*Frames:\s*(\d+)\s*$", lines[row] if row < len(lines) else "")
    if frames_match is None:
        raise BvhError(f"{source}:{row + 1}: expected 'Frames: N'")
    frames = int(frames_match.group(1))
    row = _skip_blank(lines, row + 1)
    time_match = re.match(
        rf"^\s*Frame\s+Time:\s*({_FLOAT})\s*$", lines[row] if row < len(lines) else ""
    )
    if time_match is None:
        raise BvhError(f"{source}:{row + 1}: expected 'Frame Time: seconds'")
    frame_time = float(time_match.group(1))
    if not (math.isfinite(frame_time) and frame_time > 0):
        raise BvhError(f"{source}: Frame Time must be positive, got {frame_time}")
    if frames == 0:
        raise BvhError(f"{source}: the MOTION section has no frames")
    body = " ".join(lines[row + 1 :]).split()
    expected = frames * num_channels
    if len(body) < expected:
        raise BvhError(
            f"{source}: truncated MOTION section: {len(body)} values for {frames} frames × "
            f"{num_channels} channels ({len(body) // num_channels} whole frames)"
        )
    if len(body) > expected:
        raise BvhError(
            f"{source}: {len(body) - expected} values after the {frames} frames that "
            "'Frames:' announces"
        )
    try:
        values = np.asarray(body, dtype=np.float64).reshape(frames, num_channels)
    except ValueError:
        raise BvhError(f"{source}: the MOTION section holds something other than numbers") from None
    if not np.isfinite(values).all():
        raise BvhError(f"{source}: the MOTION section holds NaN or infinite values")
    return values, frame_time


# --------------------------------------------------------------------------------------------
# Forward kinematics


def rest_positions(skeleton: BvhSkeleton) -> np.ndarray:
    """``(J, 3)`` joint positions (file units) in the rest pose (OFFSETs, all channels zero)."""
    pos = np.zeros((skeleton.num_joints, 3))
    for j, p in enumerate(skeleton.parents):
        pos[j] = skeleton.offsets[j] + (pos[p] if p >= 0 else 0.0)
    return pos


def forward_kinematics(
    clip: BvhClip, frames: slice | np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """World rotations and positions of every joint, in the file's frame and units.

    Args:
        clip: the parsed file.
        frames: the frames to evaluate (all by default).

    Returns:
        rotations ``(T, J, 3, 3)`` (column convention, world from joint) and positions
        ``(T, J, 3)`` (file units).
    """
    sk = clip.skeleton
    values = clip.values if frames is None else clip.values[frames]
    t = values.shape[0]
    rotations = np.zeros((t, sk.num_joints, 3, 3))
    positions = np.zeros((t, sk.num_joints, 3))
    column = 0
    for j, parent in enumerate(sk.parents):
        names = sk.channels[j]
        chunk = values[:, column : column + len(names)]
        column += len(names)
        local_t = np.repeat(sk.offsets[j][None], t, axis=0)
        axes, angles = "", []
        for k, name in enumerate(names):
            match = _CHANNEL.match(name)
            assert match is not None  # checked while parsing
            axis, kind = match.group(1).lower(), match.group(2).lower()
            if kind == "position":
                local_t[:, "xyz".index(axis)] = chunk[:, k]
            else:
                axes += axis.upper()
                angles.append(chunk[:, k])
        local_r = (
            Rotation.from_euler(axes, np.stack(angles, axis=1), degrees=True).as_matrix()
            if axes
            else np.repeat(np.eye(3)[None], t, axis=0)
        )
        if parent < 0:
            rotations[:, j] = local_r
            positions[:, j] = local_t
        else:
            rotations[:, j] = rotations[:, parent] @ local_r
            positions[:, j] = positions[:, parent] + np.einsum(
                "tab,tb->ta", rotations[:, parent], local_t
            )
    return rotations, positions


# --------------------------------------------------------------------------------------------
# Joint mapping

#: Base names (side removed, normalized) of sided limb joints → SMPL base name. ``shoulder``,
#: ``hand`` and ``foot`` (``?``) depend on the rest of the rig, see :func:`map_joints`.
_LIMB_BASES: dict[str, str] = {
    "upleg": "hip", "upperleg": "hip", "thigh": "hip", "hip": "hip", "femur": "hip",
    "leg": "knee", "lowerleg": "knee", "knee": "knee", "shin": "knee", "calf": "knee",
    "tibia": "knee",
    "ankle": "ankle",
    "toebase": "foot", "toe": "foot", "toes": "foot", "ball": "foot",
    "collar": "collar", "clavicle": "collar",
    "arm": "shoulder", "upperarm": "shoulder", "humerus": "shoulder",
    "forearm": "elbow", "lowerarm": "elbow", "elbow": "elbow", "radius": "elbow",
    "wrist": "wrist",
    "fingerbase": "hand", "fingers": "hand", "handmiddle1": "hand", "middle1": "hand",
    "shoulder": "?shoulder", "hand": "?hand", "foot": "?foot",
}  # fmt: skip

#: Names of unsided joints → SMPL joint.
_CENTRE_NAMES: dict[str, str] = {"hips": "pelvis", "pelvis": "pelvis", "hip": "pelvis",
                                 "neck": "neck", "head": "head"}  # fmt: skip

#: Preference among BVH names that claim the same SMPL joint (lower wins; then the shallower).
_PRIORITY: dict[str, int] = {"?hand": 1, "?foot": 1, "?shoulder": 1}


def _split_side(key: str) -> tuple[str, str] | None:
    """``("left" | "right", base)`` of a normalized joint name, or None if it has no side."""
    for side in ("left", "right"):
        if key.startswith(side) and key[len(side) :] in _LIMB_BASES:
            return side, key[len(side) :]
        if key.endswith(side) and key[: -len(side)] in _LIMB_BASES:
            return side, key[: -len(side)]
    for side in ("left", "right"):
        s = side[0]
        if key.startswith(s) and key[1:] in _LIMB_BASES:
            return side, key[1:]
        if key.endswith(s) and key[:-1] in _LIMB_BASES:
            return side, key[:-1]
    return None


def map_joints(skeleton: BvhSkeleton) -> list[int | None]:
    """The BVH joint that stands for each SMPL joint.

    Limbs, pelvis, neck and head are matched by name (CMU, Mixamo and SMPL spellings, any
    namespace: ``mixamorig:LeftForeArm``, ``LeftElbow``, ``L_Elbow``, ``lowerarm_l``). Names
    that change meaning between rigs are read in context: ``LeftShoulder`` is the collar when the
    rig also has ``LeftArm``, else the shoulder; ``LeftHand`` is the wrist unless there is a
    ``LeftWrist``; ``LeftFoot`` the ankle unless there is a ``LeftAnkle``. The spine is found by
    structure: ``spine3`` is where the neck and both arms branch off, ``spine1`` and ``spine2``
    the joints between it and the hips.

    Returns:
        24 entries in SMPL order: a BVH joint index, or None for a joint the rig lacks.

    Raises:
        BvhError: a required SMPL joint (:data:`REQUIRED_JOINTS`) is missing, or the matched
            joints do not nest as SMPL's do.
    """
    keys = [normalize_joint_name(n) for n in skeleton.names]
    sided = [_split_side(k) for k in keys]
    present = {(s[0], _LIMB_BASES[s[1]]) for s in sided if s is not None}
    depth = np.zeros(skeleton.num_joints, dtype=np.int64)
    for j, p in enumerate(skeleton.parents):
        depth[j] = depth[p] + 1 if p >= 0 else 0

    claims: dict[str, tuple[int, int, int]] = {}  # SMPL name -> (priority, depth, joint)

    def claim(smpl: str, joint: int, priority: int) -> None:
        rank = (priority, int(depth[joint]), joint)
        if smpl not in claims or rank < claims[smpl]:
            claims[smpl] = rank

    for j, (key, side) in enumerate(zip(keys, sided, strict=True)):
        if side is None:
            if key in _CENTRE_NAMES:
                claim(_CENTRE_NAMES[key], j, 0)
            continue
        role = _LIMB_BASES[side[1]]
        if role == "?shoulder":
            base = "collar" if (side[0], "shoulder") in present else "shoulder"
        elif role == "?hand":
            base = "hand" if (side[0], "wrist") in present else "wrist"
        elif role == "?foot":
            base = "foot" if (side[0], "ankle") in present else "ankle"
        else:
            base = role
        claim(f"{side[0]}_{base}", j, _PRIORITY.get(role, 0))

    found = {name: rank[2] for name, rank in claims.items()}
    if "pelvis" not in found:
        found["pelvis"] = int(np.flatnonzero(skeleton.parents < 0)[0])
    missing = [n for n in REQUIRED_JOINTS if n not in found]
    if missing:
        raise BvhError(f"the skeleton lacks SMPL joints: {', '.join(missing)}")

    # spine by structure: the lowest joint above which the head and both arm chains hang
    tops = [found["head"]] + [
        found.get(f"{side}_collar", found[f"{side}_shoulder"]) for side in ("left", "right")
    ]
    paths = [skeleton.path(found["pelvis"], j) for j in tops]
    if any(p is None for p in paths):
        raise BvhError("the head and the arms do not hang below the hips")
    chain = []
    for nodes in zip(*paths, strict=False):  # type: ignore[arg-type]
        if len(set(nodes)) != 1:
            break
        chain.append(nodes[0])
    if len(chain) < 2:
        raise BvhError("the skeleton has no spine between the hips and the chest")
    found["spine3"] = chain[-1]
    between = chain[1:-1]
    if between:
        found["spine1"] = between[0]
    if len(between) >= 2:
        found["spine2"] = between[len(between) // 2]
    if found.get("neck") == found["spine3"]:
        del found["neck"]

    mapping: list[int | None] = [found.get(n) for n in SMPL_JOINT_NAMES]
    for i, name in enumerate(SMPL_JOINT_NAMES):
        joint, parent = mapping[i], _mapped_ancestor(mapping, i)
        above = None if parent is None else mapping[parent]
        if joint is not None and above is not None and skeleton.path(above, joint) is None:
            raise BvhError(
                f"joint '{skeleton.names[joint]}' ({name}) is not below "
                f"'{skeleton.names[above]}' ({SMPL_JOINT_NAMES[parent]})"  # type: ignore[index]
            )
    return mapping


def _mapped_ancestor(mapping: Sequence[int | None], joint: int) -> int | None:
    """The nearest SMPL ancestor of ``joint`` that has a BVH counterpart."""
    parent = SMPL_PARENTS[joint]
    while parent >= 0 and mapping[parent] is None:
        parent = SMPL_PARENTS[parent]
    return parent if parent >= 0 else None


# --------------------------------------------------------------------------------------------
# Units and axes


def skeleton_height(skeleton: BvhSkeleton, up_axis: str = "y") -> float:
    """Vertical extent (file units) of the rest skeleton, End Sites included, along ``up_axis``
    (``"y"`` or ``"z"``)."""
    rest = rest_positions(skeleton)
    has_end = ~np.isnan(skeleton.end_sites[:, 0])
    points = np.concatenate([rest, rest[has_end] + skeleton.end_sites[has_end]])
    column = "xyz".index(up_axis)
    return float(np.ptp(points[:, column]))


def detect_up_axis(skeleton: BvhSkeleton, mapping: Sequence[int | None]) -> str:
    """``"y"`` or ``"z"``: the axis along which the rest skeleton's head sits above its hips."""
    rest = rest_positions(skeleton)
    pelvis, head = mapping[0], mapping[SMPL_JOINT_NAMES.index("head")]
    assert pelvis is not None and head is not None
    up = rest[head] - rest[pelvis]
    return "z" if abs(up[2]) > abs(up[1]) else "y"


def detect_units(height: float) -> str:
    """The unit of :data:`AUTO_UNITS` that makes a skeleton ``height`` (file units) tall
    closest to 1.7 m.

    Raises:
        BvhError: no unit gives a height within :data:`PLAUSIBLE_HEIGHT_M`.
    """
    best = min(AUTO_UNITS, key=lambda u: abs(math.log(max(height, 1e-12) * UNITS[u] / 1.7)))
    low, high = PLAUSIBLE_HEIGHT_M
    if not low <= height * UNITS[best] <= high:
        raise BvhError(
            f"cannot tell the units of a skeleton {height:g} units tall (not a person in "
            f"{', '.join(AUTO_UNITS)}): pass the units or a scale"
        )
    return best


def up_rotation(up_axis: str) -> np.ndarray:
    """``(3, 3)`` column-convention rotation from the file's frame to ours (Y-up)."""
    if up_axis == "y":
        return np.eye(3)
    if up_axis == "z":
        return ZUP_TO_YUP.copy()
    raise BvhError(f"unknown up axis '{up_axis}' (expected y or z)")


def world_motion(
    clip: BvhClip, scale: float, up: np.ndarray, frames: slice | np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Forward kinematics in our frame: Y-up, metres, and every joint's rest rotation identity.

    Args:
        clip: the parsed file.
        scale: metres per file unit.
        up: ``(3, 3)`` rotation from the file's frame to ours (:func:`up_rotation`).
        frames: the frames to evaluate (all by default).

    Returns:
        global rotations ``(T, J, 3, 3)``, positions ``(T, J, 3)`` (m) and rest positions
        ``(J, 3)`` (m).
    """
    rotations, positions = forward_kinematics(clip, frames)
    rotations = up @ rotations @ up.T
    positions = scale * positions @ up.T
    rest = scale * rest_positions(clip.skeleton) @ up.T
    return rotations, positions, rest


# --------------------------------------------------------------------------------------------
# Retargeting

#: Bones shorter than this (m) have no direction: CMU's zero OFFSETs.
_MIN_BONE = 1e-4


def _next_mapped(mapping: Sequence[int | None], smpl: str | None) -> int | None:
    """``smpl`` or, if the rig lacks it, the first joint down its primary chain that it has."""
    while smpl is not None:
        index = SMPL_JOINT_NAMES.index(smpl)
        if mapping[index] is not None:
            return index
        smpl = PRIMARY_CHILD.get(smpl)
    return None


def _bone_targets(mapping: Sequence[int | None], joint: int) -> list[int]:
    """SMPL joints that the bones of ``joint`` point to (primary first): its children, or for
    a child the rig lacks, the next one down that child's chain."""
    name = SMPL_JOINT_NAMES[joint]
    children = [SMPL_JOINT_NAMES[c] for c in range(NUM_JOINTS) if SMPL_PARENTS[c] == joint]
    primary = PRIMARY_CHILD.get(name)
    ordered = ([primary] if primary in children else []) + [c for c in children if c != primary]
    targets = [_next_mapped(mapping, c) for c in ordered]
    return [t for t in targets if t is not None]


@dataclass
class _Retarget:
    drivers: list[int | None]  # BVH joint whose global rotation each SMPL joint takes
    corrections: np.ndarray  # (24, 3, 3) rest corrections C_j (identity where unmapped)


def _plan(
    skeleton: BvhSkeleton,
    mapping: Sequence[int | None],
    rest: np.ndarray,
    smpl_rest: np.ndarray,
    scale: float,
    rest_relative: tuple[str, ...] = (),
) -> _Retarget:
    """Drivers and rest corrections of the SMPL joints.

    Args:
        skeleton: the BVH skeleton.
        mapping: :func:`map_joints`.
        rest: ``(J, 3)`` BVH rest positions in our frame (m).
        smpl_rest: ``(24, 3)`` SMPL rest joints (m).
        scale: metres per file unit.
        rest_relative: SMPL joints that keep their parent's correction instead of aiming their
            bone (:data:`REST_RELATIVE` with ``collars="rest"``).
    """
    drivers: list[int | None] = [None] * NUM_JOINTS
    corrections = np.repeat(np.eye(3)[None], NUM_JOINTS, axis=0)
    lengths = np.linalg.norm(skeleton.offsets, axis=1) * scale
    for j in range(NUM_JOINTS):  # SMPL order: parents first
        bvh = mapping[j]
        if bvh is None:
            continue
        targets = _bone_targets(mapping, j)
        drivers[j] = _driver(skeleton, bvh, mapping[targets[0]] if targets else None, lengths)
        bvh_dirs, smpl_dirs = [], []
        for target in targets:
            tgt: int | None = target
            while tgt is not None:  # a zero-length bone: aim at the next joint down instead
                d_bvh = rest[mapping[tgt]] - rest[bvh]  # type: ignore[index]
                if np.linalg.norm(d_bvh) > _MIN_BONE:
                    break
                tgt = _next_mapped(mapping, PRIMARY_CHILD.get(SMPL_JOINT_NAMES[tgt]))
            d_smpl = smpl_rest[tgt] - smpl_rest[j] if tgt is not None else np.zeros(3)
            if np.linalg.norm(d_smpl) <= _MIN_BONE:
                continue
            bvh_dirs.append(d_bvh / np.linalg.norm(d_bvh))
            smpl_dirs.append(d_smpl / np.linalg.norm(d_smpl))
        # start from the parent's correction, so that a rig turned as a whole (facing -Z, a
        # limb's rest twist) keeps that turn down the chain instead of a shortest arc's twist
        parent = _mapped_ancestor(mapping, j)
        base = corrections[parent] if parent is not None else np.eye(3)
        if bvh_dirs and SMPL_JOINT_NAMES[j] not in rest_relative:
            # the first (primary) bone exactly, the others fix the twist about it
            weights = np.ones(len(bvh_dirs))
            if len(bvh_dirs) > 1:
                weights[0] = np.inf
            fit, _ = Rotation.align_vectors(bvh_dirs, np.asarray(smpl_dirs) @ base.T, weights)
            corrections[j] = fit.as_matrix() @ base
        else:
            corrections[j] = base
    return _Retarget(drivers, corrections)


def _driver(skeleton: BvhSkeleton, joint: int, target: int | None, lengths: np.ndarray) -> int:
    """The BVH joint whose rotation moves the bone from ``joint`` to ``target``: the parent of
    the first joint with a non-zero OFFSET on the way (``lowerneck`` for ``Chest2`` → ``Neck``);
    ``joint`` itself if the bone has no length. For a leaf (no ``target``), the last of a chain
    of single zero-length children (``LeftWrist`` → ``lhand``)."""
    if target is None:
        while True:
            children = skeleton.children(joint)
            if len(children) != 1 or lengths[children[0]] > _MIN_BONE:
                return joint
            joint = children[0]
    path = skeleton.path(joint, target)
    assert path is not None  # map_joints checked the nesting
    moved = [b for b in path[1:] if lengths[b] > _MIN_BONE]
    return int(skeleton.parents[moved[0]]) if moved else joint


def retarget(
    clip: BvhClip,
    body: BodyModel,
    betas: np.ndarray | None = None,
    *,
    units: str = "auto",
    scale: float | None = None,
    up_axis: str = "auto",
    floor: str = "body",
    frames: tuple[int, int] | None = None,
    arm_clearance: float | None = ARM_CONTACT_CLEARANCE,
    collars: str = DEFAULT_COLLARS,
) -> tuple[SmplMotion, BvhRetarget]:
    """Retarget a parsed BVH clip to an SMPL motion on ``body`` at the clip's frame rate.

    Args:
        clip: the parsed file.
        body: the SMPL-layout body whose rest T-pose the rest corrections aim at.
        betas: shape coefficients (any length, cut or zero-padded to 10, within
            ``±MAX_ABS_BETA``); zero by default.
        units: a key of :data:`UNITS`, or ``"auto"`` (m, cm or mm by the skeleton's height).
        scale: metres per file unit; overrides ``units``.
        up_axis: ``"y"``, ``"z"`` or ``"auto"`` (the rest skeleton's hips→head axis).
        floor: ``"body"`` or ``"capture"`` (:data:`FLOOR_MODES`).
        frames: frames ``(A, B)`` of the file to keep (B exclusive); by default all, less frame
            0 where it is a reference pose (:func:`leads_with_reference`).
        arm_clearance: open the shoulders wherever an arm comes closer than this (m) to the
            torso (:func:`~usd_garment.motion.procedural.open_shoulders`, measured at most
            :data:`ARM_CHECK_FPS` times a second); 0 or None: bone directions as captured.
        collars: ``"aimed"`` or ``"rest"`` (:data:`COLLAR_MODES`).

    Returns:
        The motion (pose ``(T, 24, 3)`` axis-angle rad, trans ``(T, 3)`` m, Y-up) and a record of
        the mapping, units and floor shift.

    Raises:
        BvhError: a skeleton that does not map to SMPL, unknown units, axis or floor mode, a bad
            scale, frame range, betas or arm clearance.
    """
    sk = clip.skeleton
    if arm_clearance is not None and not (math.isfinite(arm_clearance) and arm_clearance >= 0):
        raise BvhError(f"the arm clearance must be a distance (m) >= 0, got {arm_clearance}")
    if collars not in COLLAR_MODES:
        raise BvhError(f"unknown collar mode '{collars}' (expected {', '.join(COLLAR_MODES)})")
    if floor not in FLOOR_MODES:
        raise BvhError(f"unknown floor mode '{floor}' (expected {', '.join(FLOOR_MODES)})")
    if up_axis not in UP_AXES:
        raise BvhError(f"unknown up axis '{up_axis}' (expected {', '.join(UP_AXES)})")
    reference = frames is None and leads_with_reference(clip)
    if reference:
        frames = (1, clip.num_frames)
    if frames is not None:
        a, b = frames
        if not 0 <= a < b <= clip.num_frames:
            raise BvhError(f"frames {a}:{b} outside the file's 0:{clip.num_frames}")
    mapping = map_joints(sk)
    axis = detect_up_axis(sk, mapping) if up_axis == "auto" else up_axis
    height = skeleton_height(sk, axis)
    if scale is not None:
        if not (math.isfinite(scale) and scale > 0):
            raise BvhError(f"the scale must be a positive number of metres per unit, got {scale}")
        unit_name, factor = "custom", float(scale)
    elif units == "auto":
        unit_name = detect_units(height)
        factor = UNITS[unit_name]
    elif units in UNITS:
        unit_name, factor = units, UNITS[units]
    else:
        raise BvhError(f"unknown units '{units}' (expected auto, {', '.join(UNITS)})")

    try:
        betas64 = as_betas(np.zeros(0) if betas is None else betas, max_abs=MAX_ABS_BETA)
    except ValueError as exc:
        raise BvhError(str(exc)) from None
    with torch.no_grad():
        _, smpl_rest_t = body.shaped(torch.as_tensor(betas64, dtype=torch.float32)[None])
    smpl_rest = smpl_rest_t[0].double().numpy()

    selection = slice(frames[0], frames[1]) if frames is not None else None
    rotations, positions, rest = world_motion(clip, factor, up_rotation(axis), selection)
    plan = _plan(sk, mapping, rest, smpl_rest, factor, REST_RELATIVE if collars == "rest" else ())

    t = rotations.shape[0]
    world = np.zeros((t, NUM_JOINTS, 3, 3))
    pose = np.zeros((t, NUM_JOINTS, 3))
    for j in range(NUM_JOINTS):
        parent = SMPL_PARENTS[j]
        driver = plan.drivers[j]
        if driver is not None:
            world[:, j] = rotations[:, driver] @ plan.corrections[j]
        else:
            world[:, j] = world[:, parent] if parent >= 0 else np.eye(3)
        local = world[:, j] if parent < 0 else np.swapaxes(world[:, parent], 1, 2) @ world[:, j]
        pose[:, j] = Rotation.from_matrix(local.reshape(-1, 3, 3)).as_rotvec().reshape(t, 3)
    opening = np.zeros((t, 2))
    if arm_clearance:
        stride = max(1, math.floor(clip.fps / ARM_CHECK_FPS + 1e-6))
        checked = np.unique(np.r_[np.arange(0, t, stride), t - 1])  # the last one too
        _, sparse = open_shoulders(body, betas64, pose[checked], clip.fps / stride, arm_clearance)
        frames_all = np.arange(t)
        opening = np.stack([np.interp(frames_all, checked, sparse[:, k]) for k in (0, 1)], 1)
        pose = turn_shoulders(pose, opening)
    pelvis = mapping[0]
    assert pelvis is not None
    trans = positions[:, pelvis] - rest_pelvis(body, betas64)

    motion = SmplMotion(
        betas=betas64.astype(np.float32),
        pose=pose.astype(np.float32),
        trans=trans.astype(np.float32),
        fps=clip.fps,
        model=body.name,
    )
    shift = 0.0
    if floor == "body":
        shift = -floor_height(motion, body)
        motion.trans[:, 1] += np.float32(shift)

    mapped = {m for m in mapping if m is not None}
    above = {a for m in mapped for a in sk.path(0, m) or []} - mapped
    info = BvhRetarget(
        joint_map=_named(sk, mapping),
        drivers=_named(sk, plan.drivers),
        unmapped=[n for n, m in zip(SMPL_JOINT_NAMES, mapping, strict=True) if m is None],
        folded=[sk.names[j] for j in sorted(above)],
        ignored=[sk.names[j] for j in range(sk.num_joints) if j not in above | mapped],
        scale=factor,
        units=unit_name,
        units_detected=scale is None and units == "auto",
        height_m=height * factor,
        up_axis=axis,
        floor=floor,
        floor_shift_m=shift,
        source_fps=clip.fps,
        rest_corrections=plan.corrections,
        arm_clearance_m=float(arm_clearance) if arm_clearance else None,
        shoulder_opening=opening,
        reference_left_out=reference,
    )
    return motion, info


def leads_with_reference(clip: BvhClip) -> bool:
    """Whether the clip's frame 0 is a reference pose rather than a frame of the motion: some
    joint's world rotation turns more than :data:`REFERENCE_JUMP` from frame 0 to frame 1, and
    more than :data:`REFERENCE_RATIO` times the largest turn from frame 1 to frame 2 (a clip of
    fewer than three frames has none)."""
    if clip.num_frames < 3:
        return False
    rotations, _ = forward_kinematics(clip, slice(0, 3))  # (3, J, 3, 3)
    turns = [
        np.linalg.norm(Rotation.from_matrix(np.swapaxes(a, 1, 2) @ b).as_rotvec(), axis=-1).max()
        for a, b in pairwise(rotations)
    ]  # the largest joint turn (rad) from frame 0 to 1, and from 1 to 2
    return bool(turns[0] > REFERENCE_JUMP and turns[0] > REFERENCE_RATIO * turns[1])


def _named(skeleton: BvhSkeleton, joints: Sequence[int | None]) -> dict[str, str]:
    """SMPL joint name → BVH joint name, for the SMPL joints with a BVH joint."""
    return {
        smpl: skeleton.names[j]
        for smpl, j in zip(SMPL_JOINT_NAMES, joints, strict=True)
        if j is not None
    }


def floor_height(
    motion: SmplMotion, body: BodyModel, percentile: float = FLOOR_PERCENTILE
) -> float:
    """Height (m) at which the posed body stands: the ``percentile`` of its per-frame lowest
    vertex over the motion (at most :data:`FLOOR_SAMPLES` frames, evenly spread), so that a few
    frames of a foot dipping through the capture's floor do not lift the whole clip."""
    count = min(motion.num_frames, FLOOR_SAMPLES)
    frames = np.unique(np.linspace(0, motion.num_frames - 1, count).round().astype(int))
    lowest = []
    with torch.no_grad():
        for chunk in np.array_split(frames, max(1, len(frames) // 100)):
            out = body(
                torch.as_tensor(motion.betas, dtype=torch.float32),
                torch.as_tensor(motion.pose[chunk], dtype=torch.float32),
                torch.as_tensor(motion.trans[chunk], dtype=torch.float32),
            )
            lowest.append(out.vertices[..., 1].amin(dim=1).double().numpy())
    return float(np.percentile(np.concatenate(lowest), percentile))


def load_bvh(
    path: str | Path,
    body: BodyModel,
    fps: float | None = None,
    betas: np.ndarray | None = None,
    *,
    units: str = "auto",
    scale: float | None = None,
    up_axis: str = "auto",
    floor: str = "body",
    frames: tuple[int, int] | None = None,
    arm_clearance: float | None = ARM_CONTACT_CLEARANCE,
    collars: str = DEFAULT_COLLARS,
) -> tuple[SmplMotion, BvhRetarget]:
    """Read a BVH capture (or an ASF/AMC one: :mod:`usd_garment.motion.asf_amc`) as an SMPL
    motion on ``body`` (Y-up, metres), optionally resampled.

    Args:
        path: the ``.bvh`` file (or ``.amc``, its ``.asf`` skeleton beside it: ``find_asf``).
        body: see :func:`retarget`.
        fps: resample to this frame rate (slerp / lerp); the file's rate by default.
        betas, units, scale, up_axis, floor, frames, arm_clearance, collars: see
            :func:`retarget`
            (``info.shoulder_opening`` follows the resampled frames).

    Raises:
        BvhError: see :func:`read_bvh` and :func:`retarget`.
        OSError: the file cannot be read.
    """
    clip = read_capture(path)
    try:
        motion, info = retarget(
            clip, body, betas, units=units, scale=scale, up_axis=up_axis, floor=floor,
            frames=frames, arm_clearance=arm_clearance, collars=collars,
        )  # fmt: skip
    except BvhError as exc:
        raise BvhError(f"{path}: {exc}") from None
    if fps is None:
        return motion, info
    resampled = resample_motion(motion, fps)
    if info.shoulder_opening is not None and resampled is not motion:
        source = np.arange(resampled.num_frames) / resampled.fps * motion.fps
        frames_in = np.arange(motion.num_frames)
        info.shoulder_opening = np.stack(
            [np.interp(source, frames_in, info.shoulder_opening[:, k]) for k in (0, 1)], axis=1
        )
    return resampled, info


def bone_angle_errors(
    bvh_positions: np.ndarray, smpl_joints: np.ndarray, mapping: Sequence[int | None]
) -> dict[str, np.ndarray]:
    """Angle (degrees) between each SMPL bone and the BVH segment between the same joints.

    Args:
        bvh_positions: ``(T, J, 3)`` BVH joint positions in our frame (:func:`world_motion`).
        smpl_joints: ``(T, 24, 3)`` posed SMPL joints (``BodyModel(...).joints``).
        mapping: :func:`map_joints`.

    Returns:
        ``"parent>child"`` (SMPL names, the nearest mapped parent) → ``(T,)`` angles, for the
        bones whose BVH segment is longer than 1 mm in the first frame.
    """
    errors: dict[str, np.ndarray] = {}
    for j in range(1, NUM_JOINTS):
        parent = _mapped_ancestor(mapping, j)
        if mapping[j] is None or parent is None:
            continue
        seg = bvh_positions[:, mapping[j]] - bvh_positions[:, mapping[parent]]  # type: ignore[index]
        if np.linalg.norm(seg[0]) < 1e-3:
            continue
        bone = smpl_joints[:, j] - smpl_joints[:, parent]
        cos = np.sum(seg * bone, axis=1) / (
            np.linalg.norm(seg, axis=1) * np.linalg.norm(bone, axis=1)
        )
        errors[f"{SMPL_JOINT_NAMES[parent]}>{SMPL_JOINT_NAMES[j]}"] = np.degrees(
            np.arccos(np.clip(cos, -1.0, 1.0))
        )
    return errors
