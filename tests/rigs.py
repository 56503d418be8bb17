"""Author USD rigs that carry a known SMPL motion in the many ways real files do: joint names
in other styles, shuffled joint order, extra (finger) joints, non-identity joint orientations,
Z-up, centimetres, a SkelRoot transform and sparse samples at a higher time-code rate.

Without a SkelRoot transform every rig places the same posed body in the same place in the world,
so reading it must give back the motion it was made from; a SkelRoot transform moves that body
(world = canonical world × root_xform), as it would move a character in a layout.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from pxr import Gf, Usd, UsdGeom, UsdSkel, Vt
from scipy.spatial.transform import Rotation

from usd_garment.body.joints import SMPL_JOINT_NAMES, SMPL_PARENTS
from usd_garment.body.model import BodyModel
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.schema import apply_smpl_body
from usd_garment.usd.stage import canonical_to_world_matrix

#: SMPL name -> Meshcapade / SMPL-for-Maya style leaf name (``L_Hip``), before any prefix.
_SHORT = {
    n: (n[0].upper() + "_" + n.split("_", 1)[1].capitalize()) if "_" in n else n.capitalize()
    for n in SMPL_JOINT_NAMES
}


@dataclass
class RigStyle:
    """How to disguise the SMPL skeleton.

    Attributes:
        up_axis, meters_per_unit: stage metrics.
        step: time codes between authored samples (the stage's rate is ``fps * step``).
        root_xform: ``(4, 4)`` row-vector transform of the SkelRoot (stage units).
        orient_seed: random non-identity joint orientations when set.
        shuffle_seed: random (parents-first) joint order, and another for the animation.
        prefix: leaf name prefix, e.g. ``"m_avg_"``; with ``short_names`` ``L_Hip`` style.
        root_joint: put an extra ``root`` joint above the pelvis.
        fingers: extra joints below the wrists (SMPL-H style, no ``*_hand`` joints).
        betas: author ``SmplBodyAPI`` betas.
    """

    up_axis: str = "Y"
    meters_per_unit: float = 1.0
    step: int = 1
    root_xform: np.ndarray | None = None
    orient_seed: int | None = None
    shuffle_seed: int | None = None
    prefix: str = ""
    short_names: bool = False
    root_joint: bool = False
    fingers: bool = False
    betas: bool = True


def _joint_table(style: RigStyle) -> tuple[list[str], list[int], list[int | None]]:
    """Leaf names, parent indices and SMPL index of each rig joint (parents first)."""
    names: list[str] = []
    parents: list[int] = []
    smpl: list[int | None] = []
    offset = 0
    if style.root_joint:
        names, parents, smpl, offset = ["root"], [-1], [None], 1
    for i, n in enumerate(SMPL_JOINT_NAMES):
        if style.fingers and n.endswith("_hand"):
            continue
        names.append(style.prefix + (_SHORT[n] if style.short_names else n))
        p = SMPL_PARENTS[i]
        parents.append(smpl.index(p) if p >= 0 else (0 if offset else -1))
        smpl.append(i)
    if style.fingers:
        for side, wrist in (("left", 20), ("right", 21)):
            for f in ("index", "thumb"):
                for k in (1, 2):
                    parent = smpl.index(wrist) if k == 1 else len(names) - 1
                    names.append(f"{style.prefix}{side}_{f}{k}")
                    parents.append(parent)
                    smpl.append(None)
    return names, parents, smpl


def _topological_shuffle(parents: list[int], rng: np.random.Generator) -> list[int]:
    """A random order of the joints in which every parent precedes its children."""
    order: list[int] = []
    ready = [j for j, p in enumerate(parents) if p < 0]
    while ready:
        j = ready.pop(int(rng.integers(len(ready))))
        order.append(j)
        ready += [c for c, p in enumerate(parents) if p == j]
    return order


def write_rig(path: str | Path, motion: SmplMotion, body: BodyModel, style: RigStyle) -> None:
    """Author ``motion`` (canonical frame) on ``body`` as a skeleton-only USD rig in ``style``."""
    betas = torch.as_tensor(motion.betas, dtype=torch.float32)
    with torch.no_grad():
        out = body(betas, torch.as_tensor(motion.pose), torch.as_tensor(motion.trans))
    rot = out.transforms[..., :3, :3].double().numpy()  # (T, 24, 3, 3) column convention
    posed = out.joints.double().numpy()  # (T, 24, 3)
    rest = out.rest_joints[0].double().numpy()  # (24, 3)
    to_world = canonical_to_world_matrix(style.up_axis, style.meters_per_unit)
    axes = to_world[:3, :3] * style.meters_per_unit  # pure rotation, row convention

    names, parents, smpl = _joint_table(style)
    n = len(names)
    rng = np.random.default_rng(style.orient_seed)
    orient = (
        Rotation.random(n, random_state=rng).as_matrix()
        if style.orient_seed is not None
        else np.repeat(np.eye(3)[None], n, axis=0)
    )
    t = motion.num_frames
    bind = np.repeat(np.eye(4)[None], n, axis=0)
    posed_m = np.repeat(np.eye(4)[None, None], t, axis=0).repeat(n, axis=1)
    for j in range(n):
        anchor = j  # nearest SMPL joint at or above j; a root joint above the pelvis stays put
        while anchor >= 0 and smpl[anchor] is None:
            anchor = parents[anchor]
        if anchor < 0:
            r_rest, delta, p_posed = np.zeros(3), np.repeat(np.eye(3)[None], t, 0), np.zeros((t, 3))
        else:
            s = smpl[anchor]
            r_rest = rest[s] + (0.0 if anchor == j else 0.02 * (j % 3 + 1)) * np.eye(3)[0]
            delta = rot[:, s]
            p_posed = posed[:, s] + np.einsum("tab,b->ta", delta, r_rest - rest[s])
        bind[j, :3, :3] = orient[j]
        bind[j, 3, :3] = r_rest @ axes / style.meters_per_unit
        world_delta = np.einsum("ab,tcb,cd->tad", axes.T, delta, axes)  # row convention
        posed_m[:, j, :3, :3] = orient[j] @ world_delta
        posed_m[:, j, 3, :3] = p_posed @ axes / style.meters_per_unit

    order = list(range(n))
    anim_order = list(range(n))
    if style.shuffle_seed is not None:
        srng = np.random.default_rng(style.shuffle_seed)
        order = _topological_shuffle(parents, srng)
        anim_order = list(srng.permutation(n))
    paths = []
    for j in range(n):
        chain, k = [], j
        while k >= 0:
            chain.append(names[k])
            k = parents[k]
        paths.append("/".join(reversed(chain)))

    local = posed_m.copy()
    rest_local = bind.copy()
    for j in range(n):
        if parents[j] >= 0:
            local[:, j] = posed_m[:, j] @ np.linalg.inv(posed_m[:, parents[j]])
            rest_local[j] = bind[j] @ np.linalg.inv(bind[parents[j]])

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, style.up_axis)
    UsdGeom.SetStageMetersPerUnit(stage, style.meters_per_unit)
    stage.SetTimeCodesPerSecond(motion.fps * style.step)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode((t - 1) * style.step)
    UsdGeom.Xform.Define(stage, "/World")
    root = UsdSkel.Root.Define(stage, "/World/Char")
    if style.root_xform is not None:
        root.AddTransformOp().Set(_matrix(style.root_xform))
    skel = UsdSkel.Skeleton.Define(stage, "/World/Char/Skel")
    skel.CreateJointsAttr(Vt.TokenArray([paths[j] for j in order]))
    skel.CreateBindTransformsAttr(Vt.Matrix4dArray.FromNumpy(bind[order]))
    skel.CreateRestTransformsAttr(Vt.Matrix4dArray.FromNumpy(rest_local[order]))
    if style.betas:
        apply_smpl_body(skel.GetPrim(), motion.betas, "neutral", body.name)
    anim = UsdSkel.Animation.Define(stage, "/World/Char/Skel/Anim")
    anim.CreateJointsAttr(Vt.TokenArray([paths[j] for j in anim_order]))
    trans_attr, rot_attr = anim.CreateTranslationsAttr(), anim.CreateRotationsAttr()
    anim.CreateScalesAttr(Vt.Vec3hArray.FromNumpy(np.ones((n, 3), np.float16)))
    for f in range(t):
        m = local[f, anim_order]
        quats = Rotation.from_matrix(np.swapaxes(m[:, :3, :3], 1, 2)).as_quat()
        code = Usd.TimeCode(f * style.step)
        rot_attr.Set(Vt.QuatfArray.FromNumpy(quats.astype(np.float32)), code)
        trans_attr.Set(Vt.Vec3fArray.FromNumpy(m[:, 3, :3].astype(np.float32)), code)
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    stage.SetDefaultPrim(stage.GetPrimAtPath("/World"))
    stage.GetRootLayer().Export(str(path))


def _matrix(m: np.ndarray) -> Gf.Matrix4d:
    return Gf.Matrix4d(*[float(x) for x in m.reshape(-1)])
