"""The stage processor: read an animated SMPL body from USD, pose a garment on it with a garment
method, and write the garment layer, timing each stage."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from usd_garment.body.io import load_body_model
from usd_garment.garment.library import load_template
from usd_garment.garment.template import GARMENT_NAMES, LODS, GarmentTemplate
from usd_garment.methods import GarmentMethod, get_method
from usd_garment.usd.garment_layer import (
    CLIP_THRESHOLD,
    GarmentFrames,
    check_outputs,
    write_garment_layer,
)
from usd_garment.usd.read import read_smpl_motion


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
    """

    frames: int
    vertices: int
    seconds: dict[str, float] = field(default_factory=dict)
    outputs: list[Path] = field(default_factory=list)
    method: str = ""
    garment: str = ""

    def to_json(self) -> dict[str, object]:
        return {
            "frames": self.frames,
            "vertices": self.vertices,
            "method": self.method,
            "garment": self.garment,
            "seconds": self.seconds,
            "frames_per_second": self.frames / max(sum(self.seconds.values()), 1e-9),
            "outputs": [str(p) for p in self.outputs],
        }


def dress(
    input_path: str | Path,
    output: str | Path,
    *,
    garment: str = "tshirt",
    method: str | GarmentMethod = "lbs",
    frames: tuple[int, int] | None = None,
    lod: str = "high",
    body_model: str | Path | None = None,
    skeleton: str | None = None,
    betas: np.ndarray | None = None,
    root_layer: str | Path | None = None,
    template: GarmentTemplate | None = None,
    clip_threshold: int = CLIP_THRESHOLD,
    on_read: Callable[[int], None] | None = None,
    progress: Callable[[int], None] | None = None,
) -> DressResult:
    """Dress the body of ``input_path`` and write the garment layer to ``output``.

    Args:
        input_path: USD file with an animated SMPL skeleton (never modified).
        output: the garment layer (``.usdc``/``.usd``/``.usda``).
        garment, lod: the template to load (ignored when ``template`` is given).
        method: a registered garment method name, or a method instance (e.g. a configured
            ``SimulationMethod``).
        frames: ``(a, b)`` dresses frames ``a .. b-1`` only.
        body_model: SMPL-layout body file; None for the embedded default.
        skeleton: Skeleton prim path when the stage has several.
        betas: ``(≤16,)`` shape coefficients overriding the stage's ``smpl:betas``.
        root_layer: also write a layer that sublayers the garment layer and the input.
        template: a ready template (tests, benchmarks); skips loading one.
        clip_threshold: frames × vertices above which the layer uses value clips.
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
    garment_method = get_method(method) if isinstance(method, str) else method
    seconds: dict[str, float] = {}

    start = time.perf_counter()
    body = load_body_model(body_model)
    motion, info = read_smpl_motion(input_path, body, skeleton, frames, betas)
    if template is None:
        template = load_template(garment, lod=lod, body_model_path=body_model)
    seconds["read"] = time.perf_counter() - start
    if on_read is not None:
        on_read(motion.num_frames)

    start = time.perf_counter()
    points = garment_method.predict(motion, body, template, progress)
    seconds["compute"] = time.perf_counter() - start

    start = time.perf_counter()
    frames_out = GarmentFrames(
        name=template.name,
        garment_type=template.name,
        faces=template.faces,
        uvs=template.uvs,
        points=points,
        method=garment_method.name,
        model=f"{template.name}-{template.lod}",
        model_version=garment_method.version,
        body_model=body.name,
        solver_settings=json.dumps(garment_method.settings, sort_keys=True),
    )
    outputs = write_garment_layer(
        output,
        info,
        [frames_out],
        motion.time_codes,
        clip_threshold=clip_threshold,
        root_layer=root,
    )
    seconds["write"] = time.perf_counter() - start
    return DressResult(
        frames=motion.num_frames,
        vertices=int(points.shape[1]),
        seconds=seconds,
        outputs=outputs,
        method=garment_method.name,
        garment=template.name,
    )
