"""Acclaim ASF/AMC motion captures (the CMU database's own format) read as BVH-style clips, so
that they retarget to SMPL exactly as BVH captures do (:mod:`usd_garment.motion.bvh`).

An ASF file holds the skeleton: for each bone its ``direction`` (a unit vector in the rest
frame), ``length``, ``axis`` (the orientation ``C`` of its local frame, Euler angles applied in
the given order about fixed axes) and ``dof`` (its rotation channels); ``:hierarchy`` says
which bones hang from which. An AMC file holds one block per frame, a line per bone with its
dof values (the root: translation then rotation, in the ASF's ``:root order``). A bone's
rotation relative to its parent is ``C · M · C⁻¹``, with ``M`` its dof rotations applied in
their listed order about fixed axes, and it turns the bone's own segment, which starts where
its parent's ends.

The clip has one joint per bone, at the bone's start (its OFFSET is the parent's ``length ·
direction``), rotated by the bone's rotation (written as Z-Y-X Euler channels, exact); a bone
without children gets an End Site at its end. A bone with several children passes on no length:
they start where it starts, as in the CMU database's BVH conversion (B. Hahne, cgspeed), where
the neck and both collars start at the chest's joint (``Spine1``, CMU's ``thorax``) and the
fingers and thumb at the wrist. In ASF all three start at the thorax's far end, one point: the
collars' bones from there point along the neck's, which leaves the chest's twist undetermined
when it is fitted to SMPL's (:func:`usd_garment.motion.bvh.retarget`); from the chest's joint
the retargeting follows each collar to its own first bone, as it does for the BVH conversion.
The rotations are the capture's either way, and SMPL's bones keep their own lengths. Lengths stay
in the file's units: with CMU's ``:units length 0.45`` (1/0.45 inch) ``units="auto"`` tells
them by the skeleton's height (``UNITS["cmu"]``). CMU's bone names are renamed to those of the
database's BVH conversion (:data:`CMU_BVH_NAMES`), so that an AMC capture maps onto SMPL as its
BVH conversion does. AMC files carry no frame rate: :data:`AMC_FPS` (CMU's 120 fps).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from usd_garment.motion.capture_clip import (
    BvhClip,
    BvhError,
    BvhSkeleton,
    has_suffix,
    parse_floats,
    read_text,
)

#: Frames per second of AMC files, which do not say (the CMU database's rate).
AMC_FPS = 120.0

#: CMU's ASF bone names → the joint names of the database's BVH conversion (B. Hahne, cgspeed),
#: whose joint sits where the bone starts.
CMU_BVH_NAMES: dict[str, str] = {
    "root": "Hips", "lowerback": "LowerBack", "upperback": "Spine", "thorax": "Spine1",
    "lowerneck": "Neck", "upperneck": "Neck1", "head": "Head",
    **{f"{s}{bone}": f"{prefix}{name}" for s, side in (("l", "Left"), ("r", "Right"))
       for bone, prefix, name in (
           ("hipjoint", s.upper(), "HipJoint"), ("femur", side, "UpLeg"), ("tibia", side, "Leg"),
           ("foot", side, "Foot"), ("toes", side, "ToeBase"), ("clavicle", side, "Shoulder"),
           ("humerus", side, "Arm"), ("radius", side, "ForeArm"), ("wrist", side, "Hand"),
           ("hand", side, "FingerBase"), ("fingers", side, "HandIndex1"),
           ("thumb", s.upper(), "Thumb"))},
}  # fmt: skip

#: The rotation channels of the clip's joints, in BVH's convention (intrinsic, degrees).
_EULER = "ZYX"
#: The degrees of freedom an ASF bone (or its root) may name.
_DOF_NAMES = ("rx", "ry", "rz", "tx", "ty", "tz")


@dataclass
class _Bone:
    """One ASF bone: ``direction`` ``(3,)`` unit vector and ``length`` (file units) of its
    segment in the rest frame, ``axis`` ``(3, 3)`` its local frame ``C``, ``dofs`` its
    channels (``("rx", "rz")``; the root's ``("tx", ..., "rz")``), ``position`` ``(3,)`` the
    root's rest position (file units; zero for the other bones)."""

    name: str
    direction: np.ndarray = field(default_factory=lambda: np.zeros(3))
    length: float = 0.0
    axis: np.ndarray = field(default_factory=lambda: np.eye(3))
    dofs: tuple[str, ...] = ()
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass
class AsfSkeleton:
    """A parsed ASF file: ``bones`` by name (the root first, named ``root``), each bone's
    ``children`` in the order ``:hierarchy`` lists them, and each bone's ``parent`` (all but the
    root's). Angles are in the bones' frames already (``axis``), whatever the file's unit."""

    bones: dict[str, _Bone]
    children: dict[str, list[str]]
    parent: dict[str, str]


def is_amc_path(path: str | Path) -> bool:
    """Whether ``path`` names an AMC file by its suffix: ``.amc``, ``.amc.xz`` or ``.amc.gz``."""
    return has_suffix(path, ".amc")


def find_asf(amc: str | Path) -> Path:
    """The ASF skeleton of the AMC file ``amc``: ``SUBJECT.asf`` beside ``SUBJECT_TRIAL.amc``
    (the CMU database's layout), else the only ``.asf`` file in its folder.

    Raises:
        BvhError: neither is there.
    """
    amc = Path(amc)
    named = amc.with_name(amc.name.split("_")[0].split(".")[0] + ".asf")
    if named.is_file():
        return named
    found = sorted(p for p in amc.parent.glob("*") if p.suffix.lower() == ".asf")
    if len(found) == 1:
        return found[0]
    raise BvhError(
        f"{amc}: no skeleton: expected {named.name} (or a single .asf file) in "
        f"{amc.parent if str(amc.parent) else '.'}"
    )


def read_amc(path: str | Path, asf: str | Path | None = None) -> BvhClip:
    """The AMC capture at ``path`` (xz- or gzip-compressed where its name ends in ``.xz`` or
    ``.gz``) on the ASF skeleton ``asf`` (found with :func:`find_asf` by default), as a clip at
    :data:`AMC_FPS`.

    Raises:
        BvhError: a broken ASF or AMC file, or an AMC file that does not fit the skeleton.
        OSError: a file cannot be read.
    """
    asf_path = find_asf(path) if asf is None else Path(asf)
    skeleton = parse_asf(read_text(asf_path, "ASF"), str(asf_path))
    values = parse_amc(read_text(path, "AMC"), skeleton, str(path))
    return asf_clip(skeleton, values)


def parse_asf(text: str, source: str = "<asf>") -> AsfSkeleton:
    """Parse ASF ``text``; ``source`` names it in error messages.

    Raises:
        BvhError: not an ASF file, or a bone or hierarchy that cannot be read.
    """
    sections = _sections(text)
    if ":bonedata" not in sections or ":hierarchy" not in sections:
        raise BvhError(f"{source}: not an ASF file (no :bonedata or :hierarchy)")
    units = dict(_pairs(sections.get(":units", [])))
    angle = units.get("angle", "deg").lower()
    if angle not in ("deg", "rad"):
        raise BvhError(f"{source}: unknown angle unit '{angle}'")
    degrees = angle == "deg"
    root = _Bone("root")
    root_axis = "XYZ"
    for row, words in sections.get(":root", []):
        key = words[0].lower()
        if key == "order":
            root.dofs = _dofs(words[1:], f"{source}:{row}")
        elif key == "axis" and len(words) == 2:
            root_axis = words[1]
        elif key == "position":
            root.position = _numbers(words[1:], 3, f"{source}:{row}")
        elif key == "orientation":
            angles = _numbers(words[1:], 3, f"{source}:{row}")
            root.axis = _frame(angles, root_axis, degrees, f"{source}:{row}")
    bones = {"root": root}
    for bone in _bone_blocks(sections[":bonedata"], degrees, source):
        if bone.name in bones:
            raise BvhError(f"{source}: the bone '{bone.name}' appears twice")
        bones[bone.name] = bone
    children: dict[str, list[str]] = {name: [] for name in bones}
    parent_of: dict[str, str] = {}
    for row, words in sections[":hierarchy"]:
        if words[0].lower() in ("begin", "end"):
            continue
        for name in words:
            if name not in bones:
                raise BvhError(f"{source}:{row}: the hierarchy names an unknown bone '{name}'")
        for child in words[1:]:
            if child in parent_of or child == "root":
                raise BvhError(f"{source}:{row}: the bone '{child}' has two parents")
            parent_of[child] = words[0]
            children[words[0]].append(child)
    orphans = [name for name in bones if name != "root" and name not in parent_of]
    if orphans:
        raise BvhError(f"{source}: bones outside the hierarchy: {', '.join(orphans)}")
    return AsfSkeleton(bones, children, parent_of)


def parse_amc(text: str, skeleton: AsfSkeleton, source: str = "<amc>") -> dict[str, np.ndarray]:
    """Each bone's dof values ``(T, D)`` per frame (root translation in file units, angles in
    degrees) from AMC ``text`` on ``skeleton``; bones without dofs are left out.

    Raises:
        BvhError: no frames, or a frame that lacks a bone, repeats one, names an unknown one or
            gives it the wrong number of values, or a value that is not a finite number.
    """
    degrees = True
    frames: list[dict[str, list[str]]] = []
    for row, line in enumerate(text.splitlines(), start=1):
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        if words[0].startswith(":"):
            if words[0].upper() == ":RADIANS":
                degrees = False
            continue
        where = f"{source}:{row}"
        if len(words) == 1 and words[0].isdigit():
            frames.append({})
            continue
        if not frames:
            raise BvhError(f"{where}: not an AMC file (a bone before the first frame number)")
        bone = skeleton.bones.get(words[0])
        if bone is None:
            raise BvhError(f"{where}: unknown bone '{words[0]}'")
        if words[0] in frames[-1]:
            raise BvhError(f"{where}: the bone '{words[0]}' twice in one frame")
        if len(words) - 1 != len(bone.dofs):
            raise BvhError(
                f"{where}: {len(words) - 1} values for '{words[0]}', which has "
                f"{len(bone.dofs)} degrees of freedom"
            )
        frames[-1][words[0]] = words[1:]
    if not frames:
        raise BvhError(f"{source}: the AMC file has no frames")
    values: dict[str, np.ndarray] = {}
    for name, bone in skeleton.bones.items():
        if not bone.dofs:
            continue
        missing = [i + 1 for i, frame in enumerate(frames) if name not in frame]
        if missing:
            raise BvhError(f"{source}: frame {missing[0]} lacks the bone '{name}'")
        values[name] = _numbers([w for frame in frames for w in frame[name]], None, source)
        values[name] = values[name].reshape(len(frames), len(bone.dofs))
        if not degrees:
            angular = [i for i, d in enumerate(bone.dofs) if d.startswith("r")]
            values[name][:, angular] = np.degrees(values[name][:, angular])
    return values


def asf_clip(skeleton: AsfSkeleton, values: dict[str, np.ndarray]) -> BvhClip:
    """The BVH-style clip (see the module's docstring) of ``skeleton`` moved by ``values``
    (:func:`parse_amc`), at :data:`AMC_FPS`."""
    order: list[str] = []
    stack = ["root"]
    while stack:  # depth first, children in the hierarchy's order
        name = stack.pop()
        order.append(name)
        stack.extend(reversed(skeleton.children[name]))
    index = {name: i for i, name in enumerate(order)}
    parents, offsets, ends, channels, columns = [], [], [], [], []
    for name in order:
        bone = skeleton.bones[name]
        parent = skeleton.parent.get(name)
        parents.append(-1 if parent is None else index[parent])
        if parent is None:
            offsets.append(bone.position)
        elif len(skeleton.children[parent]) > 1:  # a branch: its children start where it does
            offsets.append(np.zeros(3))
        else:
            above = skeleton.bones[parent]
            offsets.append(above.length * above.direction)
        ends.append(np.full(3, np.nan) if skeleton.children[name] else bone.length * bone.direction)
        dofs = values.get(name)
        names: list[str] = []
        if dofs is not None:
            moves = [i for i, d in enumerate(bone.dofs) if d.startswith("t")]
            names += [f"{bone.dofs[i][1].upper()}position" for i in moves]
            columns += [dofs[:, i] for i in moves]
            turns = [i for i, d in enumerate(bone.dofs) if d.startswith("r")]
            if turns:
                names += [f"{axis}rotation" for axis in _EULER]
                columns += list(_local_euler(bone, dofs[:, turns], [bone.dofs[i] for i in turns]).T)
        channels.append(tuple(names))
    clip_skeleton = BvhSkeleton(
        names=[CMU_BVH_NAMES.get(name, name) for name in order],
        parents=np.asarray(parents, dtype=np.int64),
        offsets=np.stack(offsets),
        channels=channels,
        end_sites=np.stack(ends),
    )
    if clip_skeleton.num_channels == 0:
        raise BvhError("the skeleton has no degrees of freedom")
    return BvhClip(clip_skeleton, np.stack(columns, axis=1), 1.0 / AMC_FPS)


def _local_euler(bone: _Bone, angles: np.ndarray, dofs: list[str]) -> np.ndarray:
    """``(T, 3)`` Z-Y-X Euler angles (intrinsic, degrees) of the bone's rotations ``C · M ·
    C⁻¹``, ``M`` its dof rotations ``angles`` ``(T, D)`` (degrees) about the fixed axes
    ``dofs`` in turn."""
    turn = Rotation.from_euler("".join(d[1] for d in dofs), angles, degrees=True).as_matrix()
    local = bone.axis @ turn @ bone.axis.T
    with warnings.catch_warnings():  # at ±90° about Y the first angle takes the whole turn
        warnings.simplefilter("ignore", UserWarning)
        return Rotation.from_matrix(local).as_euler(_EULER, degrees=True)


def _sections(text: str) -> dict[str, list[tuple[int, list[str]]]]:
    """The ASF's keyword sections (``":bonedata"`` ...) → their lines (line number, words),
    comments left out."""
    sections: dict[str, list[tuple[int, list[str]]]] = {}
    current: list[tuple[int, list[str]]] | None = None
    for row, line in enumerate(text.splitlines(), start=1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        if words[0].startswith(":"):
            current = sections.setdefault(words[0].lower(), [])
            if len(words) > 1:
                current.append((row, words[1:]))
        elif current is not None:
            current.append((row, words))
    return sections


def _pairs(lines: list[tuple[int, list[str]]]) -> list[tuple[str, str]]:
    """``key value`` lines as pairs (lower-case keys)."""
    return [(words[0].lower(), words[1]) for _, words in lines if len(words) >= 2]


def _bone_blocks(lines: list[tuple[int, list[str]]], degrees: bool, source: str) -> list[_Bone]:
    """The bones of the ``:bonedata`` section's ``begin`` … ``end`` blocks."""
    bones: list[_Bone] = []
    bone: _Bone | None = None
    for row, words in lines:
        key, where = words[0].lower(), f"{source}:{row}"
        if key == "begin":
            if bone is not None:
                raise BvhError(f"{where}: 'begin' inside a bone")
            bone = _Bone("")
        elif bone is None:
            raise BvhError(f"{where}: '{words[0]}' outside a bone's begin … end")
        elif key == "end":
            if not bone.name:
                raise BvhError(f"{where}: a bone without a name")
            norm = float(np.linalg.norm(bone.direction))
            if bone.length > 0 and norm == 0:
                raise BvhError(f"{where}: the bone '{bone.name}' has no direction")
            bone.direction = bone.direction / norm if norm > 0 else bone.direction
            bones.append(bone)
            bone = None
        elif key == "name" and len(words) == 2:
            bone.name = words[1]
        elif key == "direction":
            bone.direction = _numbers(words[1:], 3, where)
        elif key == "length":
            bone.length = float(_numbers(words[1:], 1, where)[0])
        elif key == "axis":
            bone.axis = _frame(_numbers(words[1:4], 3, where), "".join(words[4:5]), degrees, where)
        elif key == "dof":
            bone.dofs = _dofs(words[1:], where)
    if bone is not None:
        raise BvhError(f"{source}: a bone without its 'end'")
    return bones


def _dofs(words: list[str], where: str) -> tuple[str, ...]:
    """A bone's ``dof`` (or the root's ``order``) words, lower-case, each ``rx`` … ``tz`` once."""
    dofs = tuple(w.lower() for w in words)
    if not all(d in _DOF_NAMES for d in dofs) or len(set(dofs)) != len(dofs):
        raise BvhError(f"{where}: unknown or repeated degree of freedom in '{' '.join(words)}'")
    return dofs


def _frame(angles: np.ndarray, order: str, degrees: bool, where: str) -> np.ndarray:
    """``(3, 3)`` rotation of Euler ``angles`` ``(3,)`` applied about fixed axes in ``order``
    (``"XYZ"``: x first)."""
    if sorted(order.lower()) != ["x", "y", "z"]:
        raise BvhError(f"{where}: the axis order must name X, Y and Z once each, not '{order}'")
    rotation = Rotation.from_euler(order.lower(), angles, degrees=degrees)
    return rotation.as_matrix()


def _numbers(words: list[str], count: int | None, where: str) -> np.ndarray:
    """``words`` as finite float64 numbers (``count`` of them where given)."""
    if count is not None and len(words) != count:
        raise BvhError(f"{where}: expected {count} numbers")
    return parse_floats(words, where)
