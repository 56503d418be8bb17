"""Write posed garments as a new USD layer: one time-sampled ``UsdGeom.Mesh`` per garment beside
the body's SkelRoot, in the input stage's units, axes and timing, as one file or as value clips.

Layout. For a SkelRoot ``/Char/Body`` the garments go to ``/Char/Garments/<name>``: existing
ancestors (``/Char``) are ``over``s, new prims (``Garments``, the meshes) are ``def``s. For a
SkelRoot at the root of the stage (``/Body``) they go to ``/Garments/<name>``, a root prim of
their own, so nothing is ever authored inside the SkelRoot; the layer's defaultPrim is the root
prim that holds the garments.

Value clips. Past ``clip_threshold`` frames × vertices, ``out.usdc`` holds the static hierarchy
and the clip metadata, and the folder ``out.clips/`` holds ``topology.usdc`` (sublayered: meshes
with their topology, UVs and GarmentAPI), ``manifest.usda`` and ``clip_0000.usdc``… with the
time samples of points, normals and extent for a chunk of frames each. Asset paths are relative.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from pxr import Gf, Sdf, Usd, UsdGeom, Vt

from usd_garment.atomic import atomic_output
from usd_garment.usd.read import StageInfo
from usd_garment.usd.schema import apply_garment

#: Frames × vertices above which the time samples go to value clips.
CLIP_THRESHOLD = 8_000_000
#: Frames per value-clip file.
CLIP_FRAMES = 250
#: Frames whose normals are computed at once (bounds memory).
FRAMES_PER_CHUNK = 64
#: Output suffixes; ``.usd`` is written as binary crate, like ``.usdc``.
LAYER_SUFFIXES = (".usdc", ".usda", ".usd")
#: customData key on each mesh: the matrix taking canonical points to the mesh's local space.
CANONICAL_TO_LOCAL_KEY = "usdGarment:canonicalToLocal"
GARMENT_SCOPE = "Garments"
#: The variant set that holds levels of detail of one garment.
LOD_VARIANT_SET = "lod"
#: File names inside the value-clip folder.
TOPOLOGY_NAME, MANIFEST_NAME, CLIP_NAME = "topology.usdc", "manifest.usda", "clip_{:04d}.usdc"


@dataclass
class GarmentFrames:
    """One posed garment to write.

    Attributes:
        name: prim name of the mesh, e.g. ``"tshirt"``.
        garment_type: the garment kind (``garment:type``), e.g. ``"tshirt"``.
        faces: ``(F, 3)`` int triangles, counter-clockwise seen from outside.
        uvs: ``(N, 2)`` float texture coordinates, per vertex.
        points: ``(T, N, 3)`` posed points, canonical frame (Y-up, metres).
        method: the method that posed it (``garment:method``).
        model: model name (``garment:model``), e.g. the template or network name.
        model_version: version of the model (``garment:modelVersion``).
        body_model: the body model name it was fitted to (``garment:bodyModel``).
        solver_settings: free-form settings string recorded as ``garment:solverSettings``.
        purpose: the mesh's ``UsdGeom`` purpose ("render", "proxy"; empty: not authored). A
            "render" garment named ``X`` gets a ``proxyPrim`` relationship to a "proxy" garment
            named ``X_proxy`` written beside it.
        variant: a variant of the ``lod`` variant set (empty: none). Garments that share a
            name and differ in variant are one mesh prim whose variants hold each one's
            topology and samples; the first one listed is the default selection.
    """

    name: str
    garment_type: str
    faces: np.ndarray
    uvs: np.ndarray
    points: np.ndarray
    method: str
    model: str
    model_version: str
    body_model: str
    solver_settings: str = ""
    purpose: str = ""
    variant: str = ""


def garment_parent_path(info: StageInfo) -> Sdf.Path:
    """Path of the prim that holds the garments: a ``Garments`` sibling of the SkelRoot."""
    return Sdf.Path(info.skel_root).GetParentPath().AppendChild(GARMENT_SCOPE)


def _parent_to_world(info: StageInfo, parent: Sdf.Path) -> tuple[np.ndarray, set[str]]:
    """Local-to-world ``(4, 4)`` of the garment scope's parent in the input (at the start time)
    and the paths of the input prims that exist (those get ``over``s)."""
    stage = Usd.Stage.Open(str(info.path), Usd.Stage.LoadNone)
    existing = {str(p) for p in parent.GetPrefixes() if stage.GetPrimAtPath(p)}
    owner = stage.GetPrimAtPath(parent.GetParentPath())
    matrix = np.eye(4)
    if owner and not owner.IsPseudoRoot():
        cache = UsdGeom.XformCache(Usd.TimeCode(info.start_time_code))
        matrix = np.array(cache.GetLocalToWorldTransform(owner))
    return matrix, existing


def vertex_normals(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals ``(T, N, 3)`` float32 of meshes ``(T, N, 3)``.

    Computed vertex-major, ``(N, T, 3)``: gathers and sums over the first axis run about 2.5×
    faster on a CPU than over the middle one."""
    p = torch.from_numpy(np.asarray(points, dtype=np.float32)).transpose(0, 1).contiguous()
    corners = torch.from_numpy(np.ascontiguousarray(faces, dtype=np.int64))
    a, b, c = (p[corners[:, k]] for k in range(3))  # (F, T, 3) each
    face_n = torch.linalg.cross(b - a, c - a, dim=-1)  # twice the area, outward
    normals = torch.zeros_like(p)
    for k in range(3):
        normals.index_add_(0, corners[:, k], face_n)
    unit = torch.nn.functional.normalize(normals, dim=-1, eps=1e-12)
    return unit.transpose(0, 1).contiguous().numpy()


def _set(
    spec: Sdf.PrimSpec,
    name: str,
    type_name: Sdf.ValueTypeName,
    value: object,
    uniform: bool = False,
) -> Sdf.AttributeSpec:
    """An attribute spec on ``spec`` with ``value`` as its default (None: no default)."""
    variability = Sdf.VariabilityUniform if uniform else Sdf.VariabilityVarying
    attr = Sdf.AttributeSpec(spec, name, type_name, variability)
    if value is not None:
        attr.default = value
    return attr


def _define_hierarchy(
    layer: Sdf.Layer, mesh_path: Sdf.Path, existing: set[str], define: bool
) -> Sdf.PrimSpec:
    """Prim specs down to ``mesh_path``: ``over`` for input prims, ``def`` for new ones when
    ``define`` (else all ``over``). Returns the mesh's spec."""
    spec = layer.pseudoRoot
    for prefix in mesh_path.GetPrefixes():
        child = layer.GetPrimAtPath(prefix)
        if child is None:
            is_new = define and str(prefix) not in existing
            specifier = Sdf.SpecifierDef if is_new else Sdf.SpecifierOver
            type_name = ""
            if is_new:
                type_name = "Mesh" if prefix == mesh_path else "Xform"
            child = Sdf.PrimSpec(spec, prefix.name, specifier, type_name)
        spec = child
    return spec


def _mesh_spec(
    layer: Sdf.Layer, parent: Sdf.Path, garment: GarmentFrames, existing: set[str], define: bool
) -> Sdf.PrimSpec:
    """The spec that holds one garment's mesh data in ``layer``: the mesh prim's, or that of its
    ``lod`` variant (the set made, and its first variant selected, on first use)."""
    spec = _define_hierarchy(layer, parent.AppendChild(garment.name), existing, define)
    if not garment.variant:
        return spec
    if LOD_VARIANT_SET not in spec.variantSets:
        Sdf.VariantSetSpec(spec, LOD_VARIANT_SET)
        spec.variantSetNameList.prependedItems = [LOD_VARIANT_SET]
        spec.variantSelections[LOD_VARIANT_SET] = garment.variant
    variants = spec.variantSets[LOD_VARIANT_SET]
    if garment.variant not in variants.variants:
        Sdf.VariantSpec(variants, garment.variant)
    return variants.variants[garment.variant].primSpec


def _sample_path(parent: Sdf.Path, garment: GarmentFrames, in_clip: bool) -> Sdf.Path:
    """Where a garment's time samples go: its mesh (or ``lod`` variant) in the layer itself; in
    value-clip files, a prim of its own per variant (clip files are not composed, so a variant's
    samples need a path that the other variants' do not share)."""
    mesh = parent.AppendChild(garment.name)
    if not garment.variant:
        return mesh
    if in_clip:
        return parent.AppendChild(f"{garment.name}_{LOD_VARIANT_SET}_{garment.variant}")
    return mesh.AppendVariantSelection(LOD_VARIANT_SET, garment.variant)


def _author_static(
    spec: Sdf.PrimSpec, garment: GarmentFrames, faces: np.ndarray, canonical_to_local: np.ndarray
) -> None:
    """Topology, UVs, render settings and the canonical-frame record of one mesh (or variant)."""
    counts = np.full(len(faces), 3, dtype=np.int32)
    _set(spec, "faceVertexCounts", Sdf.ValueTypeNames.IntArray, Vt.IntArray.FromNumpy(counts))
    indices = np.ascontiguousarray(faces.reshape(-1), dtype=np.int32)
    _set(spec, "faceVertexIndices", Sdf.ValueTypeNames.IntArray, Vt.IntArray.FromNumpy(indices))
    _set(spec, "subdivisionScheme", Sdf.ValueTypeNames.Token, "none", uniform=True)
    _set(spec, "orientation", Sdf.ValueTypeNames.Token, "rightHanded", uniform=True)
    _set(spec, "doubleSided", Sdf.ValueTypeNames.Bool, True, uniform=True)
    uvs = Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(garment.uvs, dtype=np.float32))
    _set(spec, "primvars:st", Sdf.ValueTypeNames.TexCoord2fArray, uvs).SetInfo(
        "interpolation", UsdGeom.Tokens.vertex
    )
    if garment.purpose:
        _set(spec, "purpose", Sdf.ValueTypeNames.Token, garment.purpose, uniform=True)
    matrix = Gf.Matrix4d(*canonical_to_local.reshape(-1).tolist())
    spec.SetInfo("customData", {CANONICAL_TO_LOCAL_KEY: matrix})
    _set(spec, "normals", Sdf.ValueTypeNames.Normal3fArray, None).SetInfo(
        "interpolation", UsdGeom.Tokens.vertex
    )


def _one_per_mesh(garments: list[GarmentFrames]) -> list[GarmentFrames]:
    """The first garment of each mesh prim (the default variant where there are variants)."""
    first: dict[str, GarmentFrames] = {}
    for garment in garments:
        first.setdefault(garment.name, garment)
    return list(first.values())


def _link_proxies(layer: Sdf.Layer, parent: Sdf.Path, garments: list[GarmentFrames]) -> None:
    """``proxyPrim`` from each "render" garment ``X`` to the "proxy" garment ``X_proxy``."""
    proxies = {g.name for g in garments if g.purpose == "proxy"}
    for garment in _one_per_mesh(garments):
        if garment.purpose == "render" and f"{garment.name}_proxy" in proxies:
            spec = layer.GetPrimAtPath(parent.AppendChild(garment.name))
            rel = Sdf.RelationshipSpec(spec, "proxyPrim", custom=False)
            rel.targetPathList.explicitItems = [parent.AppendChild(f"{garment.name}_proxy")]


def _apply_garment_api(
    layer: Sdf.Layer, parent: Sdf.Path, garments: list[GarmentFrames], info: StageInfo
) -> None:
    """``GarmentAPI`` with its values on every mesh of ``layer``; ``garment:body`` targets the
    skeleton."""
    stage = Usd.Stage.Open(layer)
    for garment in _one_per_mesh(garments):
        apply_garment(
            stage.GetPrimAtPath(parent.AppendChild(garment.name)),
            garment_type=garment.garment_type,
            method=garment.method,
            model=garment.model,
            model_version=garment.model_version,
            body_model=garment.body_model,
            body=info.skeleton,
            solver_settings=garment.solver_settings,
        )


def _author_samples(
    layer: Sdf.Layer,
    mesh_path: Sdf.Path,
    points: np.ndarray,
    faces: np.ndarray,
    time_codes: np.ndarray,
) -> None:
    """Time samples of points, normals and extent; ``points`` ``(T, N, 3)`` in local space."""
    if layer.GetPrimAtPath(mesh_path) is None:
        Sdf.CreatePrimInLayer(layer, mesh_path)
    spec = layer.GetPrimAtPath(mesh_path)
    for name, type_name in (
        ("points", Sdf.ValueTypeNames.Point3fArray),
        ("normals", Sdf.ValueTypeNames.Normal3fArray),
        ("extent", Sdf.ValueTypeNames.Float3Array),
    ):
        if name not in spec.attributes:
            Sdf.AttributeSpec(spec, name, type_name)
    p_path, n_path = mesh_path.AppendProperty("points"), mesh_path.AppendProperty("normals")
    e_path = mesh_path.AppendProperty("extent")
    for s in range(0, len(time_codes), FRAMES_PER_CHUNK):
        chunk = np.ascontiguousarray(points[s : s + FRAMES_PER_CHUNK], dtype=np.float32)
        normals = vertex_normals(chunk, faces)
        tensor = torch.from_numpy(chunk)  # torch reduces over the middle axis much faster
        extent = torch.stack([tensor.amin(dim=1), tensor.amax(dim=1)], dim=1).numpy()  # (t, 2, 3)
        for i, t in enumerate(time_codes[s : s + FRAMES_PER_CHUNK].tolist()):
            layer.SetTimeSample(p_path, t, Vt.Vec3fArray.FromNumpy(chunk[i]))
            layer.SetTimeSample(n_path, t, Vt.Vec3fArray.FromNumpy(normals[i]))
            layer.SetTimeSample(e_path, t, Vt.Vec3fArray.FromNumpy(extent[i]))


def _new_layer(info: StageInfo, default_prim: str | None) -> Sdf.Layer:
    layer = Sdf.Layer.CreateAnonymous()
    layer.pseudoRoot.SetInfo("upAxis", info.up_axis)
    layer.pseudoRoot.SetInfo("metersPerUnit", info.meters_per_unit)
    layer.timeCodesPerSecond = info.time_codes_per_second
    layer.framesPerSecond = info.time_codes_per_second
    layer.startTimeCode = info.start_time_code
    layer.endTimeCode = info.end_time_code
    if default_prim:
        layer.defaultPrim = default_prim
    return layer


def _relative(target: Path, start: Path) -> str:
    rel = Path(os.path.relpath(target.resolve(), start.resolve())).as_posix()
    return rel if rel.startswith("../") else f"./{rel}"


@contextmanager
def _atomic_folder(path: Path) -> Iterator[Path]:
    """Like :func:`atomic_output` for a folder: a temporary folder renamed onto ``path``."""
    if not path.parent.is_dir():
        raise FileNotFoundError(f"{path.parent}: output folder does not exist")
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=path.parent))
    umask = os.umask(0)
    os.umask(umask)
    tmp.chmod(0o777 & ~umask)  # mkdtemp makes 0700
    try:
        yield tmp
        old = None
        if path.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.old.", dir=path.parent))
            os.replace(path, old / path.name)
        os.replace(tmp, path)
        if old is not None:
            shutil.rmtree(old)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)


def check_outputs(input_path: Path, output: Path, root_layer: Path | None = None) -> None:
    """Fail before any work on outputs that would overwrite the input, bad suffixes or missing
    folders.

    Raises:
        ValueError: a suffix that is not a USD layer's, or an output that is the input.
        FileNotFoundError: an output folder does not exist.
    """
    outputs = [output] + ([root_layer] if root_layer is not None else [])
    for out in outputs:
        if out.suffix.lower() not in LAYER_SUFFIXES:
            names = ", ".join(LAYER_SUFFIXES)
            raise ValueError(f"{out}: the output layer must end in one of {names}")
        if not out.parent.is_dir():
            raise FileNotFoundError(f"{out.parent}: output folder does not exist")
        if out.resolve() == input_path.resolve():
            raise ValueError(f"{out}: the output would overwrite the input")
    if root_layer is not None and root_layer.resolve() == output.resolve():
        raise ValueError(f"{root_layer}: the root layer and the garment layer are the same file")


def write_garment_layer(
    path: str | Path,
    info: StageInfo,
    garments: list[GarmentFrames],
    time_codes: np.ndarray,
    *,
    clip_threshold: int = CLIP_THRESHOLD,
    clip_frames: int = CLIP_FRAMES,
    root_layer: str | Path | None = None,
) -> list[Path]:
    """Write ``garments`` as a new layer at ``path`` (format by suffix); never touches the input.

    Args:
        path: output layer (``.usdc``/``.usd`` binary, ``.usda`` text).
        info: the input stage's description (units, axes, timing, SkelRoot, skeleton).
        garments: the garments, points ``(T, N, 3)`` in the canonical frame.
        time_codes: ``(T,)`` input time codes of the frames.
        clip_threshold: frames × vertices (summed over garments) above which value clips are
            written.
        clip_frames: frames per clip file.
        root_layer: also write this small layer that sublayers the garment layer and the input.

    Returns:
        The paths written: the layer, then the clip folder and the root layer if any.

    Raises:
        ValueError, FileNotFoundError: see :func:`check_outputs`.
    """
    with GarmentLayerWriter(
        path, info, garments, time_codes, clip_threshold=clip_threshold,
        clip_frames=clip_frames, root_layer=root_layer,
    ) as writer:  # fmt: skip
        writer.add([g.points for g in garments])
    return writer.outputs


class GarmentLayerWriter:
    """Writes a garment layer frames-chunk by frames-chunk (the streaming form of
    :func:`write_garment_layer`; same files). With value clips, each clip file is written as
    soon as its frames are in, so memory stays bounded by one clip whatever the length; without,
    the samples gather in one layer (at most ``clip_threshold`` frames × vertices).

    Use as a context manager: the files appear (renamed from temporary ones) when the block
    ends without error, after every frame was added; on error nothing is left behind.

    Args:
        path, info, time_codes, clip_threshold, clip_frames, root_layer: as for
            :func:`write_garment_layer`.
        garments: the garments' static description (their ``points`` are not read).

    Attributes:
        outputs: the paths written, once the block has ended.

    Raises:
        ValueError, FileNotFoundError: see :func:`check_outputs`.
    """

    def __init__(
        self,
        path: str | Path,
        info: StageInfo,
        garments: list[GarmentFrames],
        time_codes: np.ndarray,
        *,
        clip_threshold: int = CLIP_THRESHOLD,
        clip_frames: int = CLIP_FRAMES,
        root_layer: str | Path | None = None,
    ) -> None:
        self.path = Path(path)
        self.root = Path(root_layer) if root_layer is not None else None
        check_outputs(Path(info.path), self.path, self.root)
        self.info, self.garments, self.clip_frames = info, garments, clip_frames
        self.time_codes = np.asarray(time_codes, dtype=np.float64)
        self.parent = garment_parent_path(info)
        parent_to_world, self.existing = _parent_to_world(info, self.parent)
        self.canonical_to_local = np.asarray(info.canonical_to_world) @ np.linalg.inv(
            parent_to_world
        )
        identity = np.array_equal(self.canonical_to_local, np.eye(4))
        #: float32 canonical-to-local, None for the identity (points are written as they come).
        self._to_local = None if identity else self.canonical_to_local.astype(np.float32)
        mirrored = np.linalg.det(self.canonical_to_local[:3, :3]) < 0
        self.faces = [_oriented_faces(g, mirrored) for g in garments]
        self.default_prim = self.parent.GetPrefixes()[0].name
        vertices = sum(len(g.uvs) for g in garments)
        self.use_clips = len(self.time_codes) * vertices > clip_threshold
        self.clip_dir = self.path.with_name(f"{self.path.stem}.clips")
        self.main = _new_layer(info, self.default_prim)
        self.topology = _new_layer(info, self.default_prim) if self.use_clips else self.main
        with Sdf.ChangeBlock():
            for garment, faces in zip(garments, self.faces, strict=True):
                spec = _mesh_spec(self.topology, self.parent, garment, self.existing, define=True)
                _author_static(spec, garment, faces, self.canonical_to_local)
            _link_proxies(self.topology, self.parent, garments)
        _apply_garment_api(self.topology, self.parent, garments, info)
        self.outputs: list[Path] = []
        self._stack = ExitStack()
        self._pending = [np.zeros((0, len(g.uvs), 3), dtype=np.float32) for g in garments]
        self._start = 0  # frame of the first pending frame
        self._added = 0
        self._clips = 0
        self._tmp_clips: Path | None = None

    def __enter__(self) -> GarmentLayerWriter:
        if self.use_clips:
            self._tmp_clips = self._stack.enter_context(_atomic_folder(self.clip_dir))
        return self

    def add(self, points: list[np.ndarray]) -> None:
        """Append the next frames: one ``(t, N_g, 3)`` array per garment (canonical frame, m).

        Raises:
            ValueError: a count of garments, frames or vertices that does not fit.
        """
        if len(points) != len(self.garments):
            raise ValueError(f"expected points of {len(self.garments)} garments")
        count = {len(p) for p in points}
        if len(count) != 1 or self._added + count.pop() > len(self.time_codes):
            raise ValueError("every garment needs the same frames, no more than the time codes")
        m = self._to_local
        for g, pts in enumerate(points):
            local = np.asarray(pts, dtype=np.float32)
            if m is not None:
                local = local @ m[:3, :3] + m[3, :3]
            self._pending[g] = np.concatenate([self._pending[g], local])
        self._added += len(points[0])
        if not self.use_clips:
            self._flush(self.main, len(self._pending[0]))
            return
        while len(self._pending[0]) > self.clip_frames:  # a whole clip and its overlap frame
            self._write_clip(self.clip_frames + 1)

    def _flush(self, layer: Sdf.Layer, frames: int) -> None:
        """Author the first ``frames`` pending frames into ``layer``."""
        codes = self.time_codes[self._start : self._start + frames]
        with Sdf.ChangeBlock():
            for garment, faces, pending in zip(self.garments, self.faces, self._pending,
                                               strict=True):  # fmt: skip
                path = _sample_path(self.parent, garment, in_clip=self.use_clips)
                _author_samples(layer, path, pending[:frames], faces, codes)
        keep = frames - 1 if self.use_clips else frames  # clips overlap by one frame
        self._pending = [p[keep:] for p in self._pending]
        self._start += keep

    def _write_clip(self, frames: int) -> None:
        layer = _new_layer(self.info, self.default_prim)
        self._flush(layer, frames)
        assert self._tmp_clips is not None
        _export(layer, self._tmp_clips / CLIP_NAME.format(self._clips))
        self._clips += 1

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: object
    ) -> None:
        if kind is not None:  # remove the temporaries; the error goes on
            self._stack.__exit__(kind, exc, tb)
            return
        files = ExitStack()
        try:
            if self._added != len(self.time_codes):
                raise ValueError(
                    f"{self._added} frames written for {len(self.time_codes)} time codes"
                )
            self._finish(files)
        except BaseException as error:
            files.__exit__(type(error), error, error.__traceback__)
            self._stack.__exit__(type(error), error, error.__traceback__)
            raise
        self._stack.close()  # the clip folder first: the layer refers to it
        files.close()
        self.outputs = (
            [self.path]
            + ([self.clip_dir] if self.use_clips else [])
            + ([self.root] if self.root is not None else [])
        )

    def _finish(self, files: ExitStack) -> None:
        """The last clip, the clip metadata, topology and manifest; the layer and root layer
        exported to temporary files held by ``files``."""
        if self.use_clips:
            self._write_clip(len(self._pending[0]))
            starts = [k * self.clip_frames for k in range(self._clips)]
            with Sdf.ChangeBlock():
                _author_clips(self.main, self.parent, self.garments, self.existing,
                              self.time_codes, starts, self.clip_dir.name)  # fmt: skip
            assert self._tmp_clips is not None
            _export(self.topology, self._tmp_clips / TOPOLOGY_NAME)
            manifest = _manifest(self.info, self.default_prim, self.parent, self.garments)
            _export(manifest, self._tmp_clips / MANIFEST_NAME)
        if self.root is not None:
            tmp_root = files.enter_context(atomic_output(self.root))
            _export(_root_layer(self.info, self.default_prim, self.path, self.root), tmp_root)
        _export(self.main, files.enter_context(atomic_output(self.path)))


def _author_clips(
    main: Sdf.Layer,
    parent: Sdf.Path,
    garments: list[GarmentFrames],
    existing: set[str],
    time_codes: np.ndarray,
    starts: list[int],
    folder: str,
) -> None:
    """Sublayer the topology layer and author the value-clip metadata on every mesh of ``main``:
    clip k is active from frame ``starts[k]``; stage and clip times are the same."""
    main.subLayerPaths = [f"./{folder}/{TOPOLOGY_NAME}"]
    clips = {
        "assetPaths": Sdf.AssetPathArray(
            [f"./{folder}/{CLIP_NAME.format(k)}" for k in range(len(starts))]
        ),
        "active": Vt.Vec2dArray([(float(time_codes[s]), float(k)) for k, s in enumerate(starts)]),
        "times": Vt.Vec2dArray([(float(t), float(t)) for t in time_codes[[0, -1]]]),
        "manifestAssetPath": Sdf.AssetPath(f"./{folder}/{MANIFEST_NAME}"),
    }
    for garment in garments:
        spec = _mesh_spec(main, parent, garment, existing, define=True)
        source = _sample_path(parent, garment, in_clip=True)
        spec.SetInfo("clips", {"default": {**clips, "primPath": str(source)}})


def _oriented_faces(garment: GarmentFrames, mirrored: bool) -> np.ndarray:
    """``(F, 3)`` faces, winding reversed when the stage's frame is a mirror image."""
    faces = np.asarray(garment.faces, dtype=np.int64)
    return faces[:, ::-1] if mirrored else faces


def _export(layer: Sdf.Layer, path: Path) -> None:
    if not layer.Export(str(path)):
        raise OSError(f"{path}: could not write the layer")


def _manifest(
    info: StageInfo, default_prim: str, parent: Sdf.Path, garments: list[GarmentFrames]
) -> Sdf.Layer:
    """The clip manifest: which attributes of which meshes the clips animate."""
    layer = _new_layer(info, default_prim)
    for garment in garments:
        path = _sample_path(parent, garment, in_clip=True)
        spec = _define_hierarchy(layer, path, set(), define=False)
        Sdf.AttributeSpec(spec, "points", Sdf.ValueTypeNames.Point3fArray)
        Sdf.AttributeSpec(spec, "normals", Sdf.ValueTypeNames.Normal3fArray)
        Sdf.AttributeSpec(spec, "extent", Sdf.ValueTypeNames.Float3Array)
    return layer


def _root_layer(info: StageInfo, default_prim: str, garment_layer: Path, root: Path) -> Sdf.Layer:
    """A layer that sublayers the garment layer (stronger) and the input."""
    name = Sdf.Path(info.default_prim).name if info.default_prim else default_prim
    layer = _new_layer(info, name)
    layer.subLayerPaths = [
        _relative(garment_layer, root.parent),
        _relative(Path(info.path), root.parent),
    ]
    return layer
