"""The stage processor: read an animated SMPL body from USD, pose a garment on it with a garment
method, and write the garment layer, timing each stage."""

from __future__ import annotations

import copy
import json
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from usd_garment.body.io import load_body_model
from usd_garment.body.model import BodyModel
from usd_garment.garment.library import load_template
from usd_garment.garment.lod import carry, transfer_weights
from usd_garment.garment.template import GARMENT_NAMES, LODS, GarmentTemplate
from usd_garment.methods import GarmentMethod, get_method
from usd_garment.methods.base import predict_chunks, pushes_vertices
from usd_garment.methods.learned import default_method
from usd_garment.motion.cuts import motion_cuts, motion_restarts
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.garment_layer import (
    CLIP_THRESHOLD,
    GarmentFrames,
    GarmentLayerWriter,
    check_outputs,
)
from usd_garment.usd.read import read_smpl_motion

#: Frames computed and written at once by :func:`dress`.
FRAMES_PER_CHUNK = 256


@dataclass
class DressResult:
    """What a dress run did.

    Attributes:
        frames: frames written.
        vertices: garment vertices.
        seconds: wall time (s) of ``read`` (stage, body model, template), ``compute`` (the
            method) and ``write`` (the layer files).
        outputs: the files and folders written.
        method: the method name.
        garment: the garment name.
        cuts: time codes of the frames where the motion starts anew or its root jumps
            (``motion_cuts``: found where the root or the joints jump, or declared by
            ``smpl:cuts`` and ``cuts``).
        root_jumps: those of ``cuts`` where the root alone jumps (a teleport, a snapped
            heading): one motion going on, moved, across which the learned garment goes on.
    """

    frames: int
    vertices: int
    seconds: dict[str, float] = field(default_factory=dict)
    outputs: list[Path] = field(default_factory=list)
    method: str = ""
    garment: str = ""
    cuts: list[float] = field(default_factory=list)
    root_jumps: list[float] = field(default_factory=list)

    def to_json(self) -> dict[str, object]:
        return {
            "frames": self.frames,
            "vertices": self.vertices,
            "method": self.method,
            "garment": self.garment,
            "seconds": self.seconds,
            "frames_per_second": self.frames / max(sum(self.seconds.values()), 1e-9),
            "outputs": [str(p) for p in self.outputs],
            "cuts": self.cuts,
            "root_jumps": self.root_jumps,
        }


def dress(
    input_path: str | Path,
    output: str | Path,
    *,
    garment: str = "tshirt",
    method: str | GarmentMethod | None = None,
    frames: tuple[int, int] | None = None,
    lod: str = "high",
    body_model: str | Path | None = None,
    skeleton: str | None = None,
    betas: np.ndarray | None = None,
    cuts: Sequence[float] = (),
    root_layer: str | Path | None = None,
    template: GarmentTemplate | None = None,
    clip_threshold: int = CLIP_THRESHOLD,
    frames_per_chunk: int = FRAMES_PER_CHUNK,
    proxy_lod: str | None = None,
    lod_variants: bool = False,
    on_read: Callable[[int], None] | None = None,
    progress: Callable[[int], None] | None = None,
) -> DressResult:
    """Dress the body of ``input_path`` and write the garment layer to ``output``.

    Args:
        input_path: USD file with an animated SMPL skeleton (never modified).
        output: the garment layer (``.usdc``/``.usd``/``.usda``).
        garment, lod: the template to load (ignored when ``template`` is given).
        method: a registered garment method name, or a method instance (e.g. a configured
            ``SimulationMethod``); None: the method ``usd-garment dress`` takes when none is
            asked for (``default_method``: the learned method with the garment's shipped model
            at its level of detail where one ships, else "lbs+postprocess").
        frames: ``(a, b)`` dresses frames ``a .. b-1`` only.
        body_model: SMPL-layout body file; None for the embedded default.
        skeleton: Skeleton prim path when the stage has several.
        betas: ``(≤16,)`` shape coefficients overriding the stage's ``smpl:betas``.
        cuts: time codes where the animation starts anew, besides the stage's ``smpl:cuts``
            (a splice too small to be found; cuts where the root or the joints jump are found).
        root_layer: also write a layer that sublayers the garment layer and the input.
        template: a ready template (tests, benchmarks); skips loading one.
        clip_threshold: frames × vertices above which the layer uses value clips.
        proxy_lod: also write a proxy-purpose mesh ``<garment>_proxy`` at this (lower) level
            of detail; the garment then has the render purpose and a ``proxyPrim`` to it.
        lod_variants: write the garment as a ``lod`` variant set: the computed level of detail
            (the default selection) and each coarser one.
        frames_per_chunk: frames computed and written at once; with value clips, memory stays
            bounded by a chunk and a clip whatever the length (methods that pose the whole
            sequence at once, the simulation, hold all of it).
        on_read: called once with the frame count after reading.
        progress: called with the number of frames computed so far.

    Raises:
        UsdInputError, BodyModelError, ValueError, FileNotFoundError: bad input or output.
    """
    input_path, output = Path(input_path), Path(output)
    root = Path(root_layer) if root_layer is not None else None
    check_outputs(input_path, output, root)
    if garment not in GARMENT_NAMES:
        raise ValueError(f"unknown garment '{garment}' (available: {', '.join(GARMENT_NAMES)})")
    if lod not in LODS:
        raise ValueError(f"unknown level of detail '{lod}' (available: {', '.join(LODS)})")
    if method is None:
        method = default_method(*((template.name, template.lod) if template else (garment, lod)))
    garment_method = get_method(method) if isinstance(method, str) else method
    seconds: dict[str, float] = {}

    start = time.perf_counter()
    body = load_body_model(body_model)
    motion, info = read_smpl_motion(input_path, body, skeleton, frames, betas)
    if not np.isfinite(np.asarray(cuts, dtype=np.float64)).all():
        raise ValueError("a cut must be a finite time code")
    motion.cut_times = tuple(sorted({*motion.cut_times, *map(float, cuts)}))
    if template is None:
        template = load_template(garment, lod=lod, body_model_path=body_model)
    variants = []  # coarser levels of detail than the computed one
    if lod_variants:
        below = [k for k in LODS if LODS[k] < LODS[template.lod]]  # finest first
        if not below:
            raise ValueError(f"a lod variant set needs a level of detail below '{template.lod}'")
        variants = [load_template(template.name, lod=k, body_model_path=body_model) for k in below]
    proxy = None
    if proxy_lod is not None:
        if proxy_lod not in LODS or LODS[proxy_lod] >= LODS[template.lod]:
            raise ValueError(f"the proxy must be a lower level of detail than '{template.lod}'")
        proxy = load_template(template.name, lod=proxy_lod, body_model_path=body_model)
    coarser = variants + ([proxy] if proxy is not None else [])
    # The coarser levels' points are carried from the computed garment, except where the
    # method pushes posed vertices out: carried, its garment can be inside again between the
    # vertices it moved, so the method dresses each level as `dress --lod` would. One source
    # per level: the proxy's may also be a variant's.
    itself = pushes_vertices(garment_method)
    sources = {
        other.lod: _dressed_by_copy(garment_method, motion, body, other, frames_per_chunk)
        if itself
        else transfer_weights(template, other)
        for other in coarser
    }
    seconds["read"] = time.perf_counter() - start
    if on_read is not None:
        on_read(motion.num_frames)

    chunks = predict_chunks(garment_method, motion, body, template, frames_per_chunk, progress)
    seconds["compute"] = seconds["write"] = 0.0
    writer: GarmentLayerWriter | None = None
    with ExitStack() as stack:
        while True:
            start = time.perf_counter()
            points = next(chunks, None)
            if points is not None:
                made = {lod: next(s) if isinstance(s, Iterator) else carry(points, s)
                        for lod, s in sources.items()}  # fmt: skip
                levels = [points, *(made[other.lod] for other in coarser)]
            seconds["compute"] += time.perf_counter() - start
            if points is None:
                break
            start = time.perf_counter()
            if writer is None:  # after the first chunk: a learned method knows its version
                garments = [_garment_frames(t, garment_method, body.name)
                            for t in [template, *coarser]]  # fmt: skip
                for g, t in zip(garments[: 1 + len(variants)], [template, *variants], strict=True):
                    g.name, g.variant = template.name, t.lod if variants else ""
                    g.purpose = "render" if proxy is not None else ""
                if proxy is not None:
                    garments[-1].name, garments[-1].purpose = f"{template.name}_proxy", "proxy"
                writer = stack.enter_context(
                    GarmentLayerWriter(
                        output, info, garments, motion.time_codes, clip_threshold=clip_threshold,
                        root_layer=root,
                    )
                )  # fmt: skip
            writer.add(levels)
            seconds["write"] += time.perf_counter() - start
        start = time.perf_counter()
    seconds["write"] += time.perf_counter() - start  # the files renamed into place
    assert writer is not None
    restarts = motion_restarts(motion)
    cuts = motion_cuts(motion, restarts)
    return DressResult(
        frames=motion.num_frames,
        vertices=len(template.vertices),
        seconds=seconds,
        outputs=writer.outputs,
        method=garment_method.name,
        garment=template.name,
        cuts=motion.time_codes[list(cuts)].tolist(),
        root_jumps=motion.time_codes[[k for k in cuts if k not in restarts]].tolist(),
    )


def _dressed_by_copy(
    method: GarmentMethod,
    motion: SmplMotion,
    body: BodyModel,
    template: GarmentTemplate,
    chunk: int,
) -> Iterator[np.ndarray]:
    """``predict_chunks`` of ``template`` by a shallow copy of ``method``, made when the first
    chunk is asked for: after the computed level's first chunk, so that the copy shares what
    the method loaded then (a learned model, the body fields) and times its stages apart."""
    yield from predict_chunks(copy.copy(method), motion, body, template, chunk)


def _garment_frames(template: GarmentTemplate, method: GarmentMethod, body: str) -> GarmentFrames:
    """The static description of the garment layer's mesh (no points: they are streamed)."""
    return GarmentFrames(
        name=template.name,
        garment_type=template.name,
        faces=template.faces,
        uvs=template.uvs,
        points=np.zeros((0, len(template.vertices), 3), dtype=np.float32),
        method=method.name,
        model=f"{template.name}-{template.lod}",
        model_version=method.version,
        body_model=body,
        solver_settings=json.dumps(method.settings, sort_keys=True),
    )
