"""Read an animated SMPL body from a USD stage: find the skeleton, map its joints to SMPL, and
recover SMPL local axis-angle poses and root translation in our canonical frame.

The canonical frame is the stage's world space turned Y-up and scaled to metres, so the
transforms of the SkelRoot, its ancestors and the Skeleton prim (even animated ones) are part
of the recovered motion, and gravity stays along −Y. Joint rotations come from the skinning
transforms (joint skel-space transform × inverse bind transform), so the rig's joint
orientations do not matter; the bind pose must be SMPL's rest pose (T-pose), in any placement
and any axis-aligned orientation, which is read off the bind joint positions.

What is read must be an animation UsdSkel can compose: a SkelAnimation whose rotations and
translations have values (time samples, or default values for a static pose; scales are
optional), each holding one value per joint of the animation at every time code read, and betas
within the body's shape space (``|β| ≤`` :data:`~usd_garment.body.betas.MAX_ABS_BETA`).
Anything else is a :class:`UsdInputError`, never a silent rest pose (UsdSkel itself only warns
and falls back to the rest transforms).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from pxr import Tf, Usd, UsdGeom, UsdSkel
from scipy.spatial.transform import Rotation

from usd_garment.body.betas import MAX_ABS_BETA, as_betas
from usd_garment.body.joints import NUM_BETAS, NUM_JOINTS, SMPL_JOINT_NAMES, SMPL_PARENTS
from usd_garment.body.model import BodyModel
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.errors import UsdInputError
from usd_garment.usd.joint_aliases import match_smpl_joints
from usd_garment.usd.schema import read_betas, read_cuts, read_smpl_body
from usd_garment.usd.stage import canonical_to_world_matrix, open_stage, stage_units

_J = {name: i for i, name in enumerate(SMPL_JOINT_NAMES)}


@dataclass
class StageInfo:
    """What a writer needs to author a layer that matches the input stage.

    Attributes:
        path: the input file.
        up_axis: ``"Y"`` or ``"Z"``.
        meters_per_unit: the stage's metres per unit.
        time_codes_per_second: the stage's time codes per second (the motion's fps).
        start_time_code, end_time_code: the stage's (or the animation's) time range.
        default_prim: path of the default prim, or None.
        skel_root: prim path of the SkelRoot (the Skeleton's path when it has none).
        skeleton: prim path of the Skeleton read.
        canonical_to_world: ``(4, 4)`` float64 row-vector matrix, ``p_world = p_canon @ M``,
            from our canonical frame (Y-up, metres) to stage world space. The SkelRoot's and
            its ancestors' transforms are already in the motion, so this is the stage's up-axis
            rotation and unit scale only.
    """

    path: Path
    up_axis: str
    meters_per_unit: float
    time_codes_per_second: float
    start_time_code: float
    end_time_code: float
    default_prim: str | None
    skel_root: str
    skeleton: str
    canonical_to_world: np.ndarray


def find_skeletons(stage: Usd.Stage) -> list[str]:
    """Prim paths of the Skeletons that have a bound SkelAnimation, in stage order."""
    cache = UsdSkel.Cache()
    found: list[str] = []
    for prim in stage.Traverse(Usd.TraverseInstanceProxies()):
        if prim.IsA(UsdSkel.Skeleton):
            query = cache.GetSkelQuery(UsdSkel.Skeleton(prim))
            if query and query.GetAnimQuery():
                found.append(str(prim.GetPath()))
    return found


def read_smpl_motion(
    path: str | Path,
    body: BodyModel,
    skeleton: str | None = None,
    frames: tuple[int, int] | None = None,
    betas: np.ndarray | None = None,
) -> tuple[SmplMotion, StageInfo]:
    """Read the SMPL motion of one animated skeleton of a USD file.

    Frames are the integer time codes from the stage's start to end time code (the animation's
    sample range when the stage has none), values interpolated as USD does between sparse
    samples. A static pose, a SkelAnimation whose rotations and translations have default
    values but no time samples, is read at every frame of the stage's range, or as one frame at
    time code 0 when the stage has no range.

    Args:
        path: a ``.usd``/``.usda``/``.usdc``/``.usdz`` file.
        body: the body model whose rest pelvis defines SMPL's ``trans``.
        skeleton: prim path of the Skeleton; needed only when the stage has several.
        frames: ``(a, b)`` reads frames ``a .. b-1`` of that range.
        betas: ``(≤16,)`` shape coefficients overriding the skeleton's ``smpl:betas``; like
            those, the first 10 must be finite and within ``±MAX_ABS_BETA``.

    Returns:
        The motion (pose ``(T, 24, 3)`` rad, trans ``(T, 3)`` m, canonical frame, float32;
        ``cut_times``: the skeleton's ``smpl:cuts``) and what a writer needs to know about the
        stage.

    Raises:
        UsdInputError: unreadable file, no (or no such) animated skeleton, missing SMPL joints,
            no animation (rotations or translations without any value), rotations, translations
            or scales holding a different count than the animation's joints, non-finite
            transforms, betas that are not finite or beyond ``MAX_ABS_BETA``, cuts that are not
            finite, an empty time range or bad ``frames``.
    """
    path = Path(path)
    stage = open_stage(path)
    skel = _pick_skeleton(stage, skeleton, path)
    where = f"{path}:{skel.GetPath()}"
    query = UsdSkel.Cache().GetSkelQuery(skel)
    if not query:
        raise UsdInputError(f"{where}: invalid Skeleton (check its joints and transforms)")
    anim = query.GetAnimQuery()
    if not anim:
        raise UsdInputError(f"{where}: the Skeleton has no bound SkelAnimation")
    joint_paths = [str(j) for j in query.GetJointOrder()]
    rig_index = match_smpl_joints(joint_paths, where)

    up_axis, meters_per_unit = stage_units(stage)
    to_world = canonical_to_world_matrix(up_axis, meters_per_unit)
    world_to_canon = np.linalg.inv(to_world)
    animation = UsdSkel.Animation(anim.GetPrim())
    if animation:
        _require_values(animation, where)
    start, end = _time_range(stage, anim, where, static_ok=bool(animation))
    codes = np.arange(math.ceil(start), math.floor(end) + 1, dtype=np.float64)
    if codes.size == 0:
        raise UsdInputError(f"{where}: no integer time code between {start} and {end}")
    if frames is not None:
        a, b = frames
        if not 0 <= a < b <= codes.size:
            raise UsdInputError(f"{where}: frames {a}..{b} outside the {codes.size} frames read")
        codes = codes[a:b]
    if animation:
        _check_counts(animation, codes, where)

    bind = _bind_transforms(skel, len(joint_paths), where)
    rest_axes = _rest_axes(bind[:, 3, :3], rig_index, where)
    skinning, skel_to_world = _sample_transforms(query, skel.GetPrim(), codes, where)

    # Row-vector chain: canonical rest → rig rest → posed skel space → world → canonical.
    rig = np.array(
        [i if i is not None else rig_index[SMPL_PARENTS[k]] for k, i in enumerate(rig_index)]
    )
    to_canon = skel_to_world[:, None, :3, :3] @ world_to_canon[:3, :3]  # (T, 1, 3, 3)
    chain = rest_axes @ skinning[:, rig, :3, :3] @ to_canon  # (T, 24, 3, 3)
    global_rot = np.swapaxes(_nearest_rotation(chain), -1, -2)  # column convention (T, 24, 3, 3)
    local = global_rot.copy()
    parents = np.array(SMPL_PARENTS[1:])
    local[:, 1:] = np.swapaxes(global_rot[:, parents], -1, -2) @ global_rot[:, 1:]
    for k, i in enumerate(rig_index):
        if i is None:
            local[:, k] = np.eye(3)
    pose = Rotation.from_matrix(local.reshape(-1, 3, 3)).as_rotvec().reshape(-1, NUM_JOINTS, 3)

    pelvis = rig_index[_J["pelvis"]]
    pelvis_rest = np.append(bind[pelvis, 3, :3], 1.0)
    pelvis_world = ((pelvis_rest @ skinning[:, pelvis])[:, None] @ skel_to_world)[:, 0]
    pelvis_canon = (pelvis_world @ world_to_canon)[:, :3]

    prim = skel.GetPrim()
    root = UsdSkel.Root.Find(prim)
    skel_root = root.GetPrim() if root else prim
    betas10 = _betas(betas, prim, skel_root, where)
    with torch.no_grad():
        _, rest_joints = body.shaped(torch.as_tensor(betas10, dtype=torch.float32)[None])
    trans = pelvis_canon - rest_joints[0, 0].double().numpy()

    meta = {**read_smpl_body(skel_root), **read_smpl_body(prim)}
    motion = SmplMotion(
        betas=betas10.astype(np.float32),
        pose=pose.astype(np.float32),
        trans=trans.astype(np.float32),
        fps=float(stage.GetTimeCodesPerSecond()),
        time_codes=codes,
        gender=meta.get("gender", "neutral"),
        model=meta.get("model", "default"),
        cut_times=_cut_times(prim, skel_root, where),
    )
    default_prim = stage.GetDefaultPrim()
    info = StageInfo(
        path=path,
        up_axis=up_axis,
        meters_per_unit=meters_per_unit,
        time_codes_per_second=float(stage.GetTimeCodesPerSecond()),
        start_time_code=float(start),
        end_time_code=float(end),
        default_prim=str(default_prim.GetPath()) if default_prim else None,
        skel_root=str(skel_root.GetPath()),
        skeleton=str(prim.GetPath()),
        canonical_to_world=to_world,
    )
    return motion, info


def _cut_times(prim: Usd.Prim, skel_root: Usd.Prim, where: str) -> tuple[float, ...]:
    """The skeleton's (or SkelRoot's) ``smpl:cuts``, sorted, each once; none when not authored.

    Raises:
        UsdInputError: a cut that is not a finite time code.
    """
    values = read_cuts(prim)
    if values is None:
        values = read_cuts(skel_root)
    if values is None:
        return ()
    if not np.isfinite(values).all():
        raise UsdInputError(f"{where}: smpl:cuts holds a time code that is not finite")
    return tuple(float(t) for t in np.unique(values))


def _pick_skeleton(stage: Usd.Stage, skeleton: str | None, path: Path) -> UsdSkel.Skeleton:
    if skeleton is not None:
        prim = stage.GetPrimAtPath(skeleton) if skeleton.startswith("/") else Usd.Prim()
        if not prim or not prim.IsA(UsdSkel.Skeleton):
            raise UsdInputError(f"{path}: no Skeleton at '{skeleton}'")
        return UsdSkel.Skeleton(prim)
    animated = find_skeletons(stage)
    if len(animated) == 1:
        return UsdSkel.Skeleton(stage.GetPrimAtPath(animated[0]))
    if len(animated) > 1:
        raise UsdInputError(
            f"{path}: several animated skeletons, pick one with --skeleton: {', '.join(animated)}"
        )
    plain = [
        str(p.GetPath())
        for p in stage.Traverse(Usd.TraverseInstanceProxies())
        if p.IsA(UsdSkel.Skeleton)
    ]
    if plain:
        raise UsdInputError(f"{path}: no SkelAnimation bound to the Skeleton {', '.join(plain)}")
    raise UsdInputError(f"{path}: no UsdSkel Skeleton in the stage")


def _require_values(animation: UsdSkel.Animation, where: str) -> None:
    """Raise unless the SkelAnimation animates joints: it lists joints, and its rotations and
    translations have values (time samples or a default). UsdSkel composes no joint transform
    from an animation without both and silently poses the rest transforms instead."""
    label = f"the SkelAnimation {animation.GetPath()}"
    if not animation.GetJointsAttr().Get():
        raise UsdInputError(f"{where}: no animation: {label} lists no joints")
    missing = [
        name
        for name, attr in (
            ("rotations", animation.GetRotationsAttr()),
            ("translations", animation.GetTranslationsAttr()),
        )
        if not attr.HasValue()
    ]
    if len(missing) == 2:
        raise UsdInputError(
            f"{where}: no animation: {label} has no time samples and no default values on its "
            "rotations and translations"
        )
    if missing:
        raise UsdInputError(
            f"{where}: no animation: {label} has no {missing[0]} (no time samples, no default "
            "value), UsdSkel would pose the rest transforms"
        )


def _check_counts(animation: UsdSkel.Animation, codes: np.ndarray, where: str) -> None:
    """Raise at the first time code of ``codes`` ``(T,)`` where the SkelAnimation's rotations,
    translations or (optional) scales do not hold one value per joint of the animation, or where
    rotations or translations are blocked."""
    label = f"the SkelAnimation {animation.GetPath()}"
    joints = len(animation.GetJointsAttr().Get())
    attrs = (
        ("rotations", animation.GetRotationsAttr(), True),
        ("translations", animation.GetTranslationsAttr(), True),
        ("scales", animation.GetScalesAttr(), False),
    )
    for code in codes:
        time = Usd.TimeCode(float(code))
        for name, attr, required in attrs:
            value = attr.Get(time)
            if value is None:
                if required:
                    raise UsdInputError(f"{where}: {label} has no {name} at time code {code:g}")
                continue
            if len(value) != joints:
                raise UsdInputError(
                    f"{where}: {label} has {len(value)} {name} for its {joints} joints at time "
                    f"code {code:g}"
                )


def _time_range(
    stage: Usd.Stage, anim: UsdSkel.AnimQuery, where: str, static_ok: bool = False
) -> tuple[float, float]:
    """The stage's start/end time codes, else the animation's first/last sample, else (0, 0)
    for a static pose when ``static_ok`` (a SkelAnimation already known to have values)."""
    if stage.HasAuthoredTimeCodeRange():
        start, end = float(stage.GetStartTimeCode()), float(stage.GetEndTimeCode())
    else:
        samples = list(anim.GetJointTransformTimeSamples())
        if not samples and not static_ok:
            raise UsdInputError(f"{where}: the SkelAnimation has no time samples")
        start, end = (float(samples[0]), float(samples[-1])) if samples else (0.0, 0.0)
    if end < start:
        raise UsdInputError(f"{where}: end time code {end} is before start time code {start}")
    return start, end


def _bind_transforms(skel: UsdSkel.Skeleton, num_joints: int, where: str) -> np.ndarray:
    """``(J, 4, 4)`` float64 bind transforms (skel space, row-vector convention)."""
    value = skel.GetBindTransformsAttr().Get()
    bind = np.array(value, dtype=np.float64) if value is not None else np.zeros((0, 4, 4))
    if bind.shape != (num_joints, 4, 4):
        raise UsdInputError(f"{where}: bindTransforms must hold one matrix per joint")
    if not np.isfinite(bind).all():
        raise UsdInputError(f"{where}: bindTransforms contain NaN or infinite values")
    return bind


def _rest_axes(rest_positions: np.ndarray, rig_index: list[int | None], where: str) -> np.ndarray:
    """``(3, 3)`` rotation (row-vector convention) from canonical axes to the rig's bind-pose
    axes, read off the bind joint positions ``(J, 3)`` and snapped to the nearest axis-aligned
    rotation: canonical +X is the body's left, +Y up, +Z forward."""

    def at(name: str) -> np.ndarray:
        return rest_positions[rig_index[_J[name]]]

    left = (at("left_hip") - at("right_hip")) + (at("left_shoulder") - at("right_shoulder"))
    up = at("neck") - at("pelvis")
    axes = np.zeros((3, 3))
    for row, vec in enumerate((left, up, np.cross(left, up))):
        k = int(np.argmax(np.abs(vec)))
        axes[row, k] = np.sign(vec[k])
    if not np.isclose(abs(np.linalg.det(axes)), 1.0) or np.linalg.det(axes) < 0:
        raise UsdInputError(f"{where}: cannot tell up and left from the bind pose (not a T-pose?)")
    return axes


def _sample_transforms(
    query: UsdSkel.SkeletonQuery, prim: Usd.Prim, codes: np.ndarray, where: str
) -> tuple[np.ndarray, np.ndarray]:
    """Skinning transforms ``(T, J, 4, 4)`` and skel-to-world transforms ``(T, 4, 4)``."""
    skinning = []
    to_world = []
    xform_cache = UsdGeom.XformCache()
    for code in codes:
        time = Usd.TimeCode(float(code))
        try:
            skinning.append(np.array(query.ComputeSkinningTransforms(time), dtype=np.float64))
        except Tf.ErrorException as exc:
            raise UsdInputError(f"{where}: cannot compute joint transforms at {code}") from exc
        xform_cache.SetTime(time)
        to_world.append(np.array(xform_cache.GetLocalToWorldTransform(prim), dtype=np.float64))
    skin = np.stack(skinning)
    world = np.stack(to_world)
    if skin.ndim != 4 or skin.shape[1:] != (len(query.GetJointOrder()), 4, 4):
        raise UsdInputError(f"{where}: the SkelAnimation does not give one transform per joint")
    if not (np.isfinite(skin).all() and np.isfinite(world).all()):
        bad = codes[~(np.isfinite(skin).all(axis=(1, 2, 3)) & np.isfinite(world).all(axis=(1, 2)))]
        raise UsdInputError(f"{where}: NaN or infinite joint transforms at time code {bad[0]:g}")
    return skin, world


def _nearest_rotation(m: np.ndarray) -> np.ndarray:
    """Nearest rotation ``(..., 3, 3)`` to each matrix (polar decomposition), scale removed."""
    u, _, vt = np.linalg.svd(m)
    r = u @ vt
    flip = np.linalg.det(r) < 0
    if flip.any():
        u[flip, :, -1] *= -1
        r = u @ vt
    return r


def _betas(
    override: np.ndarray | None, prim: Usd.Prim, skel_root: Usd.Prim, where: str
) -> np.ndarray:
    """``(10,)`` float64 betas: the override, the skeleton's (or SkelRoot's) ``smpl:betas``, or
    zeros with a warning. Longer vectors are cut to 10, shorter ones padded with zeros.

    Raises:
        UsdInputError: a kept value that is not finite or beyond ``±MAX_ABS_BETA``.
    """
    origin = "betas given"
    values = override
    if values is None:
        origin = "smpl:betas"
        values = read_betas(prim)
        if values is None:
            values = read_betas(skel_root)
    if values is None:
        warnings.warn(f"{where}: no smpl:betas on the Skeleton, using zeros", stacklevel=3)
        values = np.zeros(NUM_BETAS)
    try:
        return as_betas(values, max_abs=MAX_ABS_BETA)
    except ValueError as exc:
        raise UsdInputError(f"{where}: {origin}: {exc}") from None
