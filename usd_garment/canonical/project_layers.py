"""Project simulated garment layers (USD) to canonical space and write the training set file:
the library side of ``usd-garment project``."""

from __future__ import annotations

import multiprocessing
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from usd_garment import __version__
from usd_garment.body.io import load_body_model
from usd_garment.canonical.dataset import (
    CanonicalSet,
    concat_canonical_sets,
    load_canonical_set,
    save_canonical_set,
)
from usd_garment.canonical.projection import Projection, ProjectionSettings, project_sequence
from usd_garment.fields.body_fields import load_body_fields
from usd_garment.garment.library import load_template
from usd_garment.garment.model import GarmentModel
from usd_garment.garment.template import GarmentTemplate
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.garment_read import read_garment_info, read_garment_layer
from usd_garment.usd.read import read_smpl_motion


@dataclass
class SequenceInput:
    """One simulated sequence, read and matched to its body motion.

    Attributes:
        source: the simulated garment layer.
        points: ``(T, N, 3)`` simulated garment (canonical frame, m).
        motion: the body motion at the same time codes.
        flagged: ``(T,)`` bool, the frames the simulation flagged (kept though they failed its
            checks).
    """

    source: Path
    points: np.ndarray
    motion: SmplMotion
    flagged: np.ndarray


def match_frames(points: np.ndarray, garment_times: np.ndarray, motion: SmplMotion) -> SmplMotion:
    """The frames of ``motion`` at the garment layer's time codes ``(T,)``.

    Raises:
        ValueError: a garment time code has no body frame.
    """
    lookup = {float(t): i for i, t in enumerate(motion.time_codes)}
    missing = [float(t) for t in garment_times if float(t) not in lookup]
    if missing:
        raise ValueError(
            f"the body has no frame at time code {missing[0]:g} of the garment layer "
            f"({len(missing)} of {len(garment_times)} frames missing)"
        )
    index = np.array([lookup[float(t)] for t in garment_times])
    return SmplMotion(
        betas=motion.betas,
        pose=motion.pose[index],
        trans=motion.trans[index],
        fps=motion.fps,
        time_codes=motion.time_codes[index],
        gender=motion.gender,
        model=motion.model,
    )


#: The garment model and projection inputs of a worker process (set by ``_init_worker``).
_WORKER: dict[str, Any] = {}


def _init_worker(model: GarmentModel, template: GarmentTemplate, start: np.ndarray) -> None:
    torch.set_num_threads(1)
    _WORKER.update(model=model, template=template, start=start)


def _project(
    model: GarmentModel,
    template: GarmentTemplate,
    start: np.ndarray,
    item: SequenceInput,
    settings: ProjectionSettings,
    progress: Callable[[int], None] | None = None,
) -> Projection:
    """Project one read sequence (see :func:`project_sequence`)."""
    m = item.motion
    return project_sequence(
        model, template.vertices, template.faces, item.points, m.betas, m.pose, m.trans,
        settings, progress, start,
    )  # fmt: skip


def _project_item(task: tuple[int, SequenceInput, ProjectionSettings]) -> tuple[int, Projection]:
    """Project one sequence in a worker process; ``(index, result)``."""
    index, item, settings = task
    return index, _project(_WORKER["model"], _WORKER["template"], _WORKER["start"], item, settings)


def project_layers(
    sim_layers: Sequence[str | Path],
    body_layers: Sequence[str | Path],
    output: str | Path,
    *,
    garment: str = "tshirt",
    lod: str = "high",
    body_model: str | Path | None = None,
    fields: str | Path | None = None,
    settings: ProjectionSettings | None = None,
    splits: Sequence[str] | None = None,
    workers: int = 1,
    update: bool = False,
    on_read: Callable[[int], None] | None = None,
    progress: Callable[[int], None] | None = None,
) -> tuple[CanonicalSet, bool]:
    """Project every simulated layer with the body motion of its body layer; write ``output``.

    Args:
        sim_layers: garment layers (time-sampled points), one per sequence.
        body_layers: the animated SMPL body of each sequence (same count), or one for all.
        output: the canonical training set file (``.npz``), written atomically at the end.
        garment, lod: the garment template the simulations were made from.
        body_model: SMPL-layout body file; the embedded default body by default.
        fields: the body's diffused fields file; the default body's by default.
        settings: projection parameters.
        splits: the split of each sequence ("train", "validation", "test"); all "train" by
            default.
        workers: processes projecting one sequence each at a time (spawned, one torch thread
            each); 1 projects in this process.
        update: when ``output`` exists, keep its sequences, project only the layers that are not
            among its sources and append them (same garment, lod, body and settings required);
            when every layer is already there, nothing is projected. Kept sequences projected
            before flagged frames were recorded get them from their layers when all of those
            still exist (else the set records none); the file is then written even with no
            new layer.
        on_read: called once with the total number of frames after all inputs are read.
        progress: called with the number of frames projected so far (after each chunk of
            frames with one worker, after each sequence with several).

    Returns:
        The set (``metadata["last_run"]``: what this run projected) and whether ``output`` was
        written (not by an update that found nothing to add or record).

    Raises:
        ValueError, FileNotFoundError, UsdInputError, BodyModelError: bad input.
    """
    started = time.perf_counter()
    settings = settings or ProjectionSettings()
    output = Path(output)
    splits = ["train"] * len(sim_layers) if splits is None else list(splits)
    if output.suffix != ".npz":
        raise ValueError(f"{output}: the output must be an .npz file")
    if not output.parent.is_dir():
        raise FileNotFoundError(f"{output.parent}: output folder does not exist")
    if len(body_layers) not in (1, len(sim_layers)):
        raise ValueError(
            f"give one body layer per simulated layer, or one for all "
            f"({len(sim_layers)} simulated, {len(body_layers)} body layers)"
        )
    if len(splits) != len(sim_layers):
        raise ValueError(
            f"give one split per simulated layer ({len(splits)} for {len(sim_layers)})"
        )
    if workers < 1:
        raise ValueError("workers must be >= 1")
    kept = None
    if update and output.is_file():
        kept = load_canonical_set(output)
        _check_same_projection(kept, output, garment, lod, settings)
        recorded = kept.flagged is not None
        if not recorded:
            kept.flagged = _flags_of_sources(kept)
        new = [k for k, sim in enumerate(sim_layers) if str(Path(sim)) not in kept.sources]
        if not new:
            kept.metadata["last_run"] = _run_record(0, 0, 0.0, started, 0)
            backfilled = not recorded and kept.flagged is not None
            if backfilled:
                save_canonical_set(output, kept)
            return kept, backfilled
        sim_layers = [sim_layers[k] for k in new]
        body_layers = body_layers if len(body_layers) == 1 else [body_layers[k] for k in new]
        splits = [splits[k] for k in new]
    body = load_body_model(body_model)
    if kept is not None and kept.metadata.get("body_model") != body.name:
        raise ValueError(f"{output}: made for body '{kept.metadata.get('body_model')}'")
    body_fields = load_body_fields(fields)
    if body_fields.body_name != body.name:
        raise ValueError(
            f"the fields were fitted to body '{body_fields.body_name}', not '{body.name}'"
        )
    template = load_template(garment, lod, body_model)
    try:
        start = load_template(garment, lod, body_model, draped=True).vertices
    except FileNotFoundError:  # no draped template for this body yet: start from the template
        start = template.vertices
    inputs = []
    for k, sim in enumerate(sim_layers):
        points, faces, info = read_garment_layer(sim)
        if points.shape[1] != len(template.vertices) or not np.array_equal(faces, template.faces):
            raise ValueError(
                f"{sim}: the garment mesh ({points.shape[1]} vertices) is not the {garment} "
                f"'{lod}' template ({len(template.vertices)} vertices)"
            )
        motion, _ = read_smpl_motion(body_layers[k % len(body_layers)], body)
        inputs.append(
            SequenceInput(
                Path(sim), points, match_frames(points, info.time_codes, motion), info.flagged
            )
        )
    total = sum(len(i.points) for i in inputs)
    if on_read is not None:
        on_read(total)
    model = GarmentModel(body, body_fields)
    results: list[Projection | None] = [None] * len(inputs)
    tasks = [(k, item, settings) for k, item in enumerate(inputs)]
    done = 0
    if workers == 1 or len(tasks) == 1:
        for k, item, _ in tasks:
            step = None if progress is None else (lambda n, d=done: progress(d + n))
            results[k] = _project(model, template, start, item, settings, step)
            done += len(item.points)
    else:
        context = multiprocessing.get_context("spawn")
        pool_size = min(workers, len(tasks))
        with context.Pool(pool_size, _init_worker, (model, template, start)) as pool:
            for k, result in pool.imap_unordered(_project_item, tasks):
                results[k] = result
                done += len(inputs[k].points)
                if progress is not None:
                    progress(done)
    finished = [r for r in results if r is not None]
    data = CanonicalSet(
        canonical=np.concatenate([r.canonical for r in finished]),
        frame_offsets=np.cumsum([0] + [len(i.points) for i in inputs]),
        betas=np.stack([i.motion.betas for i in inputs]),
        pose=np.concatenate([i.motion.pose for i in inputs]),
        trans=np.concatenate([i.motion.trans for i in inputs]),
        fps=np.array([i.motion.fps for i in inputs]),
        error=np.concatenate([r.error for r in finished]),
        max_error=np.concatenate([r.max_error for r in finished]),
        template=template.vertices,
        faces=template.faces,
        sources=[str(i.source) for i in inputs],
        splits=splits,
        flagged=np.concatenate([i.flagged for i in inputs]),
        metadata={
            "garment": garment,
            "lod": lod,
            "body_model": body.name,
            "fields_body": body_fields.body_name,
            "projection": settings.to_json(),
            "workers": workers,
            "seconds": sum(r.seconds for r in finished),
            "wall_seconds": time.perf_counter() - started,
            "usd_garment_version": __version__,
        },
    )
    data.metadata["last_run"] = _run_record(
        len(inputs), total, data.metadata["seconds"], started, min(workers, len(tasks))
    )
    if kept is not None:
        for key in ("seconds", "wall_seconds"):
            data.metadata[key] += float(kept.metadata.get(key, 0.0))
        data = concat_canonical_sets(kept, data)
    save_canonical_set(output, data)
    return data, True


def _run_record(
    sequences: int, frames: int, seconds: float, started: float, workers: int
) -> dict[str, float | int]:
    """What one call projected: ``sequences`` and ``frames`` (0 when it found nothing new),
    ``seconds`` of projection summed over its workers, its wall time since ``started``
    (``time.perf_counter``) and the ``workers`` it ran (one process per sequence at most). The
    set's ``seconds`` and ``wall_seconds`` sum every call that added to it."""
    return {
        "sequences": sequences,
        "frames": frames,
        "seconds": seconds,
        "wall_seconds": time.perf_counter() - started,
        "workers": workers,
    }


def _flags_of_sources(data: CanonicalSet) -> np.ndarray | None:
    """``(T,)`` bool: the flagged frames of ``data``'s sequences read from their garment layers
    (their records, not their points); None when a layer is gone.

    Raises:
        ValueError: a layer has another number of frames than its sequence.
    """
    parts = []
    for s, source in enumerate(data.sources):
        if not Path(source).is_file():
            return None
        info = read_garment_info(source)
        frames = data.sequence(s)
        if len(info.flagged) != frames.stop - frames.start:
            raise ValueError(
                f"{source}: {len(info.flagged)} frames, its sequence in the set "
                f"{frames.stop - frames.start}"
            )
        parts.append(info.flagged)
    return np.concatenate(parts) if parts else np.zeros(0, dtype=bool)


def _check_same_projection(
    kept: CanonicalSet, output: Path, garment: str, lod: str, settings: ProjectionSettings
) -> None:
    """Refuse to append to a set made for another garment or with other projection settings.

    Raises:
        ValueError: ``kept`` (read from ``output``) differs in garment, lod or settings.
    """
    made = (kept.metadata.get("garment"), kept.metadata.get("lod"), kept.metadata.get("projection"))
    if made != (garment, lod, settings.to_json()):
        raise ValueError(
            f"{output}: made for {made[0]} '{made[1]}' with projection settings {made[2]}, not "
            f"{garment} '{lod}' with {settings.to_json()}; write a new file instead"
        )
