"""Author an animated SMPL body as a USD layer: SkelRoot, Skeleton (24 SMPL joints, identity
joint orientations), SkelAnimation, ``SmplBodyAPI`` betas and the skinned body mesh.

Layout: ``/Character`` (Xform, the default prim) / ``Body`` (SkelRoot) / ``Skeleton``,
``Animation`` and ``Mesh``; Y-up, metres, ``timeCodesPerSecond`` = the motion's fps. Garment
layers put their meshes beside the SkelRoot, under ``/Character/Garments``.

The mesh is the shaped rest body (at the motion's betas) with every non-zero skinning weight of
the body model and an identity ``geomBindTransform``, so UsdSkel's skinning of it is the body
model's LBS (``BodyModel(betas, pose, trans).vertices``) up to float32 rounding (< 1 µm on the
embedded body): the body a user sees is the body garments are fitted against. Pose blendshapes
(SMPL's ``posedirs``; the embedded body has none) are not written: a body with them is skinned
by USD without its pose correctives.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt
from scipy.spatial.transform import Rotation

from usd_garment.atomic import atomic_output
from usd_garment.body.betas import MAX_ABS_BETA, as_betas
from usd_garment.body.joints import NUM_JOINTS, SMPL_PARENTS, smpl_joint_paths
from usd_garment.body.model import BodyModel
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.schema import apply_smpl_body

CHARACTER_PATH = "/Character"
SKEL_ROOT_PATH = f"{CHARACTER_PATH}/Body"
SKELETON_PATH = f"{SKEL_ROOT_PATH}/Skeleton"
ANIMATION_PATH = f"{SKEL_ROOT_PATH}/Animation"
MESH_PATH = f"{SKEL_ROOT_PATH}/Mesh"

#: The largest number of skinning influences per vertex that ``top_weights`` keeps by default.
#: Kept for callers that want a compact rig; :func:`write_body_layer` writes every influence.
MAX_INFLUENCES = 4


def top_weights(weights: np.ndarray, k: int = MAX_INFLUENCES) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` largest skinning weights of each vertex, renormalised.

    Args:
        weights: ``(V, J)`` skinning weights.

    Returns:
        joint indices ``(V, k)`` int32 and weights ``(V, k)`` float32 summing to 1, largest first.
    """
    order = np.argsort(-weights, axis=1)[:, :k]
    top = np.take_along_axis(weights, order, axis=1).clip(min=0.0)
    total = top.sum(axis=1, keepdims=True)
    top = np.where(total > 0, top / np.where(total > 0, total, 1.0), 1.0 / k)
    return order.astype(np.int32), top.astype(np.float32)


def all_weights(weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every non-zero skinning weight of each vertex, as UsdSkel's fixed-size influences.

    The element size is the largest count of non-zero weights of any vertex; vertices with fewer
    are padded with joint 0 / weight 0, which UsdSkel skins to nothing. Weights are written as
    given (not renormalised), so USD's skinning is the body model's LBS.

    Args:
        weights: ``(V, J)`` skinning weights (≥ 0; each row sums to 1 in a body model).

    Returns:
        joint indices ``(V, K)`` int32 and weights ``(V, K)`` float32, largest first, with
        ``K`` = max over vertices of the non-zero weights (at least 1).
    """
    weights = np.asarray(weights)
    k = max(1, int((weights != 0).sum(axis=1).max(initial=0)))
    order = np.argsort(-weights, axis=1, kind="stable")[:, :k]
    kept = np.take_along_axis(weights, order, axis=1)
    order = np.where(kept != 0, order, 0)
    return order.astype(np.int32), kept.astype(np.float32)


def write_body_layer(
    path: str | Path,
    motion: SmplMotion,
    body: BodyModel,
    with_mesh: bool = True,
) -> None:
    """Write ``motion`` on ``body`` as a USD file (``.usda``/``.usdc``/``.usd``), atomically.

    Args:
        path: output file; its folder must exist.
        motion: the SMPL motion (canonical frame: Y-up, metres), samples at
            ``motion.time_codes``.
        body: the body model the betas belong to; gives rest joints, mesh and weights.
        with_mesh: also write the skinned body mesh (skip it for a skeleton-only layer).

    Raises:
        ValueError: betas that are not finite or beyond ``±MAX_ABS_BETA`` (the reader refuses
            them, so no layer is written that could not be read back).
        OSError: the file could not be written.
    """
    try:
        as_betas(motion.betas, max_abs=MAX_ABS_BETA)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    with torch.no_grad():
        rest_vertices, rest_joints = body.shaped(torch.as_tensor(motion.betas)[None].float())
    rest_joints_np = rest_joints[0].double().numpy()
    layer = Sdf.Layer.CreateAnonymous(".usda")
    stage = Usd.Stage.Open(layer)
    _author_stage(stage, motion)
    _author_skeleton(stage, motion, rest_joints_np)
    if with_mesh:
        _author_mesh(stage, body, rest_vertices[0].numpy())
    with atomic_output(path) as tmp:
        if not layer.Export(str(tmp)):
            raise OSError(f"{path}: USD could not write the file")


def _author_stage(stage: Usd.Stage, motion: SmplMotion) -> None:
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(motion.fps)
    stage.SetFramesPerSecond(motion.fps)
    stage.SetStartTimeCode(float(motion.time_codes[0]))
    stage.SetEndTimeCode(float(motion.time_codes[-1]))
    character = UsdGeom.Xform.Define(stage, CHARACTER_PATH)
    stage.SetDefaultPrim(character.GetPrim())
    UsdSkel.Root.Define(stage, SKEL_ROOT_PATH)


def _author_skeleton(stage: Usd.Stage, motion: SmplMotion, rest_joints: np.ndarray) -> None:
    """Skeleton with identity-oriented rest/bind transforms at ``rest_joints`` ``(24, 3)`` (m)
    and a SkelAnimation with per-frame local rotations and translations."""
    joints = Vt.TokenArray(smpl_joint_paths())
    parents = np.array(SMPL_PARENTS)
    offsets = rest_joints.copy()
    offsets[1:] -= rest_joints[parents[1:]]

    skeleton = UsdSkel.Skeleton.Define(stage, SKELETON_PATH)
    skeleton.CreateJointsAttr(joints)
    skeleton.CreateJointNamesAttr(Vt.TokenArray([p.rsplit("/", 1)[-1] for p in joints]))
    skeleton.CreateBindTransformsAttr(_translations_to_matrices(rest_joints))
    skeleton.CreateRestTransformsAttr(_translations_to_matrices(offsets))
    apply_smpl_body(
        skeleton.GetPrim(), motion.betas, motion.gender, motion.model, cuts=motion.cut_times
    )

    anim = UsdSkel.Animation.Define(stage, ANIMATION_PATH)
    anim.CreateJointsAttr(joints)
    scales = np.ones((NUM_JOINTS, 3), dtype=np.float16)
    anim.CreateScalesAttr(Vt.Vec3hArray.FromNumpy(scales))
    quats = Rotation.from_rotvec(motion.pose.reshape(-1, 3).astype(np.float64)).as_quat()
    quats = quats.reshape(-1, NUM_JOINTS, 4).astype(np.float32)  # (x, y, z, w) as Vt stores
    translations = np.repeat(offsets[None], motion.num_frames, axis=0)
    translations[:, 0] = rest_joints[0] + motion.trans
    rot_path = anim.CreateRotationsAttr().GetPath()
    trans_path = anim.CreateTranslationsAttr().GetPath()
    layer = stage.GetRootLayer()
    with Sdf.ChangeBlock():
        for t, code in enumerate(motion.time_codes):
            rot = Vt.QuatfArray.FromNumpy(np.ascontiguousarray(quats[t]))
            layer.SetTimeSample(rot_path, float(code), rot)
            tr = Vt.Vec3fArray.FromNumpy(translations[t].astype(np.float32))
            layer.SetTimeSample(trans_path, float(code), tr)
    binding = UsdSkel.BindingAPI.Apply(skeleton.GetPrim())
    binding.CreateAnimationSourceRel().SetTargets([anim.GetPath()])


def _author_mesh(stage: Usd.Stage, body: BodyModel, rest_vertices: np.ndarray) -> None:
    """The body mesh at its shaped rest pose ``(V, 3)`` (m), skinned with every non-zero weight
    of the body model (see :func:`all_weights`)."""
    mesh = UsdGeom.Mesh.Define(stage, MESH_PATH)
    faces = body.faces.numpy().astype(np.int32)
    points = np.ascontiguousarray(rest_vertices, dtype=np.float32)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(faces.reshape(-1)))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([points.min(0), points.max(0)])))
    indices, weights = all_weights(body.weights.numpy())
    size = indices.shape[1]
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateJointIndicesPrimvar(False, size).Set(Vt.IntArray.FromNumpy(indices.reshape(-1)))
    binding.CreateJointWeightsPrimvar(False, size).Set(Vt.FloatArray.FromNumpy(weights.reshape(-1)))
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
    binding.CreateSkeletonRel().SetTargets([Sdf.Path(SKELETON_PATH)])


def _translations_to_matrices(translations: np.ndarray) -> Vt.Matrix4dArray:
    """Identity-rotation row-vector matrices ``(N, 4, 4)`` with the given translations (N, 3)."""
    m = np.repeat(np.eye(4)[None], len(translations), axis=0)
    m[:, 3, :3] = translations
    return Vt.Matrix4dArray.FromNumpy(m)
