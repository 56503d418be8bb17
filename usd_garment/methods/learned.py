"""The learned garment method of the paper: motion descriptor γ → GRU regressor → latent codes z →
VAE decoder → canonical garment X → garment model M_G(X, β, θ) → posed garment; and the same
followed by the baselines' push-out post-process ("learned+postprocess": no garment vertex left
inside the posed body where the pose does not force it, at a fraction of the speed).

The networks run at the model's 30 fps: the input motion is resampled to it, and the latent codes
are interpolated back to the input's frames before decoding and posing with the input's own
poses, so the output has the input's time codes. Everything is batched over frames except the
GRU's recurrence.
"""

from __future__ import annotations

import json
import time
from collections import deque
from collections.abc import Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import closing, contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from usd_garment.body.model import BodyModel
from usd_garment.canonical.preimage_push import PartBoxes, preimage_push
from usd_garment.canonical.push_out import push_out_canonical
from usd_garment.canonical.shape_gap import ShapeGap, shape_gap
from usd_garment.eval.body_distance import BodySurface, body_pool
from usd_garment.eval.push_out import PUSH_OUT_EPS, PUSH_OUT_PASSES, push_out
from usd_garment.fields.body_fields import (
    LINEARIZATION_LOOKUPS,
    LINEARIZATION_RADIUS,
    BodyFields,
    FieldTangent,
    load_body_fields,
)
from usd_garment.garment.lod import carry_to_lod
from usd_garment.garment.model import GarmentModel
from usd_garment.garment.template import LODS, GarmentTemplate
from usd_garment.methods.base import Progress, predict_chunks
from usd_garment.methods.learned_model import (
    LearnedModel,
    Member,
    ModelError,
    load_learned_model,
)
from usd_garment.methods.learned_posing import (
    PosingPool,
    Smoothing,
    available_cores,
    can_fork,
    pose_chunk,
)
from usd_garment.motion.cuts import motion_cuts, motion_restarts, smooth_runs
from usd_garment.motion.jumps import root_jumps, without_jumps
from usd_garment.motion.resample import cut_at, resampled_cuts
from usd_garment.motion.sequence import SmplMotion
from usd_garment.regressor.descriptor import MODEL_FPS, at_model_rate, motion_descriptor

#: Where the shipped default model of each garment lives.
SHIPPED_MODELS = Path(__file__).resolve().parent.parent / "data" / "models"
#: Frames decoded at once, sharing one first-order expansion of the body fields.
FRAMES_PER_CHUNK = 256
#: The stages :attr:`LearnedMethod.seconds` times.
STAGES = (
    "load", "regressor", "decoder", "carry", "canonical", "fields", "posing", "preimage",
    "workers", "push_out",
)  # fmt: skip


def shipped_model(garment: str, lod: str | None = None) -> Path | None:
    """The shipped default model directory of ``garment`` (when ``lod`` is given: one that
    dresses it, trained on ``lod`` or on a finer level it is carried down from), or None when
    there is none."""
    path = SHIPPED_MODELS / garment
    if not (path / "model.json").is_file():
        return None
    if lod is not None and not _dresses(json.loads((path / "model.json").read_text())["lod"], lod):
        return None
    return path


def _dresses(model_lod: str, lod: str) -> bool:
    """Whether a model trained on ``model_lod`` dresses the level of detail ``lod``: its own, or
    a coarser one that its garments are carried down to (``carry_to_lod``)."""
    return model_lod in LODS and lod in LODS and LODS[model_lod] >= LODS[lod]


def quality_method(quality: str | None) -> str:
    """The learned method ``dress`` uses for ``quality`` when none is asked for: the networks
    alone for a "draft" (``learned``), the garment pushed out of the parts posing carries it into
    when no quality is given (``learned+preimage``: a fortieth of the networks' collisions on
    held-out motion at three to four times their time a frame), the exact winding-number push-out
    for "final" (``learned+postprocess``, about ten times slower again; ``docs/judge.md``).

    Raises:
        ValueError: ``quality`` is none of :data:`QUALITY_METHODS`' keys.
    """
    if quality not in QUALITY_METHODS:
        raise ValueError(f"unknown quality {quality!r} ({', '.join(map(str, QUALITY_METHODS))})")
    return QUALITY_METHODS[quality]


def default_method(garment: str, lod: str, quality: str | None = None) -> str:
    """The method ``dress`` uses when none is asked for: the learned method of ``quality``
    (:func:`quality_method`) where a trained model of ``garment`` at ``lod`` ships, else the
    "lbs+postprocess" baseline."""
    if shipped_model(garment, lod) is None:
        return "lbs+postprocess"
    return quality_method(quality)


def learned_method(name: str, model: str | Path | None = None) -> LearnedMethod:
    """The learned method registered as ``name`` (one of :data:`LEARNED_METHODS`) with the
    model directory ``model`` (None: the shipped default).

    Raises:
        ValueError: ``name`` is not a learned method.
    """
    for kind in LEARNED_CLASSES:
        if kind.name == name:
            return kind(model)
    raise ValueError(f"'{name}' is not a learned method ({', '.join(LEARNED_METHODS)})")


@torch.no_grad()
def predict_latents(
    model: LearnedModel,
    motion: SmplMotion,
    cuts: Sequence[int] | None = None,
    restarts: Sequence[int] | None = None,
) -> torch.Tensor:
    """The regressors' latent codes ``(T, ΣL_m)`` for the frames of ``motion``, the members'
    side by side: each member's motion descriptor γ at the model's 30 fps (the motion resampled
    once, ``at_model_rate``; each run between its cuts on its own), its GRU (from rest at the
    start and again at each restart, its state carried across a jump of the root alone), the
    codes smoothed in time when the model says so (a Gaussian of ``model.latent_smoothing``
    seconds, reflected at the ends and at each restart), then interpolated back to the motion's
    frames (:func:`to_frames`, not across a restart). Across a jump of the root alone the codes,
    which see no heading or offset, go on: smoothed and interpolated across it. ``cuts`` and
    ``restarts``: the motion's :func:`motion_cuts` and :func:`motion_restarts`, where the
    caller has them (None: found here).

    The members' GRUs run in threads: a recurrence is a chain of small matrix products that
    keeps one core busy, so on two cores three members take about half the time."""
    betas = torch.as_tensor(motion.betas, dtype=torch.float32)
    restarts = motion_restarts(motion) if restarts is None else restarts
    cuts = motion_cuts(motion, restarts) if cuts is None else cuts
    resampled, at_30 = at_model_rate(motion, cuts)  # once for every member
    starts = resampled_cuts(restarts, motion.fps, MODEL_FPS, resampled.num_frames)
    gammas = [
        motion_descriptor(resampled.pose, resampled.trans, member.pose_codec, cuts=at_30)
        for member in model.members
    ]

    def codes_of(member: Member, gamma: torch.Tensor) -> torch.Tensor:
        return member.regressor.predict(gamma, betas, restarts=starts)

    with ThreadPoolExecutor(len(model.members)) as pool:
        codes = list(pool.map(codes_of, model.members, gammas))
    z = torch.cat(codes, dim=1)
    if model.latent_smoothing > 0 and len(z) > 1:
        sigma = model.latent_smoothing * MODEL_FPS
        smoothed = smooth_runs(z.cpu().numpy(), sigma, starts, mode="mirror")
        z = torch.from_numpy(smoothed).to(z.device)
    return to_frames(z, motion.fps, motion.num_frames, restarts)


def to_frames(
    values: torch.Tensor, fps: float, count: int, cuts: Sequence[int] = ()
) -> torch.Tensor:
    """``values`` ``(T', ...)`` sampled at :data:`MODEL_FPS` from time 0, linearly interpolated
    at ``count`` frames sampled at ``fps`` from time 0 (clamped at the last sample). ``cuts``:
    the frames (at ``fps``) where the motion starts anew; a frame between the two samples
    around a cut's sample (``cut_at``) takes the one on its own side of the cut, not a blend."""
    if values.shape[0] == 1:
        return values.expand(count, *values.shape[1:])
    u = torch.arange(count, dtype=torch.float64) * (MODEL_FPS / fps)
    u = u.clamp(max=values.shape[0] - 1)
    i0 = u.floor().long().clamp(max=values.shape[0] - 2)
    alpha = u - i0
    frames = torch.arange(count)
    for cut in sorted(cuts, reverse=True):  # of two cuts at one sample, the first decides
        across = i0 + 1 == cut_at(cut, fps, MODEL_FPS)
        alpha[across] = (frames[across] >= cut).to(alpha.dtype)
    alpha = alpha.to(values.dtype).reshape(-1, *([1] * (values.dim() - 1)))
    return (1.0 - alpha) * values[i0] + alpha * values[i0 + 1]


class LearnedMethod:
    """The trained networks of a model directory (default: the shipped model of the garment).

    Args:
        model: a model directory (see :mod:`learned_model`), or None for the shipped default
            of the template's garment.
        fields: the body's diffused fields for M_G; the default body's by default.
        exact_fields: look the fields up at every frame's canonical garment; by default they
            are taken to first order about the mean canonical garment of a chunk, or of
            each of the equal parts it is cut into where the garment moves far within it, kept
            for the next chunks while that is cheaper than linearizing again
            (:func:`_tangents`; exactly only for vertices more than 2 cm from the anchor):
            several times faster, within 0.2 mm on average of the exact M_G
            (:meth:`BodyFields.linearized`).
    """

    name = "learned"
    #: Push the decoded canonical garment ε out of the canonical body before posing
    #: (:func:`push_out_canonical`).
    canonical_push = False
    #: Push posed vertices out of the parts that posing carries them into, found through the
    #: body's skinning preimages (:func:`preimage_push`).
    preimage = False
    #: Push vertices inside or within ε of the posed body out (:func:`push_out`).
    push_out = False
    #: Processes that push the garment out (one CPU core each; 1: this process).
    push_out_workers = 1
    #: Forked processes that pose the chunks and push them out through the preimages, one CPU
    #: core each, while this one decodes the next chunks and writes the last (the preimage
    #: push only; at most one for every two chunks; 1: this process; ``learned_posing``).
    #: The garment of this process at one torch thread, to the bit.
    workers = 1

    def __init__(
        self,
        model: str | Path | None = None,
        fields: BodyFields | None = None,
        exact_fields: bool = False,
    ) -> None:
        self.model_path = Path(model) if model is not None else None
        self.exact_fields = exact_fields
        self._model: LearnedModel | None = None
        self._fields = fields
        #: Seconds spent by the last :meth:`predict_stream` in each stage (the model's and the
        #: fields' loading, the pose code and GRU, the decoder, the carry to a coarser mesh,
        #: the canonical push-out, the fields' linearization, the posing, the preimage push-out,
        #: the wait for the :attr:`workers` that pose and push in their place, and the
        #: push-out).
        self.seconds: dict[str, float] = {}

    @property
    def version(self) -> str:
        return self._model.version if self._model is not None else "unloaded"

    @property
    def pushes_vertices(self) -> bool:
        """Whether posed vertices are pushed out of the body (``base.pushes_vertices``)."""
        return self.preimage or self.push_out

    @property
    def smooths(self) -> bool:
        """Whether the model's posed smoothing applies: only where something keeps the smoothed
        vertices out of their own body parts (the canonical push's guard, ``Smoothing.apply``, or
        the posed push-out). The networks alone (``learned``) are not smoothed: with the T-shirt's
        version 9 they left 0.374 % inside elsewhere smoothed against 0.287 % not, on the test
        split of stop 59's chart (stop 77)."""
        return self.canonical_push or self.push_out

    def posed_smoothing(self, model: LearnedModel) -> float:
        """``model``'s posed smoothing (s) where this method :attr:`smooths`, else 0."""
        return model.posed_smoothing if self.smooths else 0.0

    @property
    def settings(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "model": str(self.model_path) if self.model_path else "shipped",
            "fields": "exact" if self.exact_fields else "linearized per chunk part",
            "canonical_push_out": self.canonical_push,
            "preimage_push_out": self.preimage,
        }
        if self.push_out:
            out.update(push_out_eps_m=PUSH_OUT_EPS, push_out_passes=PUSH_OUT_PASSES)
        if self._model is not None:
            out.update(
                garment=self._model.garment,
                lod=self._model.lod,
                members=len(self._model.members),
                version=self._model.version,
                body_fingerprint=self._model.body_fingerprint,
                posed_smoothing_s=self.posed_smoothing(self._model),
            )
        return out

    def load(self, garment: str, body: BodyModel) -> LearnedModel:
        """The model for ``garment`` on ``body`` (loaded once).

        Raises:
            ModelError: no model for that garment, an unreadable one, or one for another body.
        """
        if self._model is None:
            path = self.model_path or shipped_model(garment)
            if path is None:
                raise ModelError(
                    f"no trained model ships for the garment '{garment}' yet: pass --model DIR "
                    "or another --method"
                )
            self.model_path = path
            self._model = load_learned_model(path, body)
        else:
            self._model.check_body(body)
        if self._model.garment != garment:
            raise ModelError(
                f"{self.model_path}: a model of the garment '{self._model.garment}', "
                f"not '{garment}'"
            )
        return self._model

    def predict(
        self,
        motion: SmplMotion,
        body: BodyModel,
        template: GarmentTemplate,
        progress: Progress | None = None,
    ) -> np.ndarray:
        """Posed garment points ``(T, N, 3)`` float32, canonical frame (m).

        Raises:
            ModelError: no usable model, or one trained on another template.
        """
        chunks = predict_chunks(self, motion, body, template, FRAMES_PER_CHUNK, progress)
        return np.concatenate(list(chunks))

    def predict_stream(
        self,
        motion: SmplMotion,
        body: BodyModel,
        template: GarmentTemplate,
        chunk: int = FRAMES_PER_CHUNK,
    ) -> Iterator[np.ndarray]:
        """Posed garment points in consecutive chunks ``(t ≤ chunk, N, 3)`` float32 (m): the
        latent codes of the whole motion first (the GRU, ``(T, L)``: small), then each chunk
        decoded and posed (with the frames around it that the model's posed smoothing reaches,
        which smooths the chunk as it would the whole motion: ``Smoothing``; where the method
        :attr:`smooths`), then pushed out where the method does. A ``template`` coarser than
        the model's level of detail gets the model's garment carried down to it
        (``carry_to_lod``): with the preimage push, the decoded canonical garment, before
        anything else (the pushes, the fields and the posing then work on the vertices
        written); else the posed garment (a draft from the same networks).

        Raises:
            ModelError: no usable model, or one trained on another template (or a coarser
                level of detail than ``template``'s).
        """
        self.seconds = dict.fromkeys(STAGES, 0.0)
        clock = [time.perf_counter()]

        def lap(stage: str) -> None:
            now = time.perf_counter()
            self.seconds[stage] += now - clock[0]
            clock[0] = now

        model = self.load(template.name, body)
        carried = template.lod != model.lod and _dresses(model.lod, template.lod)
        lods = (template.name, model.lod, template.lod)
        # learned+preimage carries the decoded canonical garment down first, so that
        # its pushes act on the vertices written (a posed garment pushed at the model's level
        # and carried down can be inside again between its vertices) and every later stage
        # works on fewer vertices; the other methods carry the posed garment (stop 69: posing
        # the coarser mesh itself left 0.02-0.05 pp more inside elsewhere where nothing pushes
        # the posed garment).
        early = carried and self.preimage
        if len(template.vertices) != model.vertices and not carried:
            raise ModelError(
                f"{self.model_path}: trained on the {model.lod} {model.garment} "
                f"({model.vertices} vertices), not the {template.lod} one "
                f"({len(template.vertices)} vertices)"
            )
        if self._fields is None:
            self._fields = load_body_fields()
        garment_model = GarmentModel(body, self._fields)
        surface = BodySurface(body.faces.numpy(), body.num_vertices) if self.push_out else None
        betas = torch.as_tensor(motion.betas, dtype=torch.float32)
        boxes = PartBoxes.of(body, betas) if self.preimage else None
        gap = shape_gap(body, self._fields, betas) if self.preimage else None
        pose = torch.as_tensor(motion.pose, dtype=torch.float32)
        trans = torch.as_tensor(motion.trans, dtype=torch.float32)
        t_frames = motion.num_frames
        tangents: list[Tangent] = []  # the last one is kept across chunks (_tangents)
        lap("load")
        # The cuts where another motion starts, and the jumps of the root alone, which the
        # networks (the motion without them) and the smoothing (the posed garment) take out.
        restarts = motion_restarts(motion)
        cuts = motion_cuts(motion, restarts)
        jumps = root_jumps(motion, body, cuts, restarts)
        z = predict_latents(model, without_jumps(motion, jumps, body), restarts, restarts)
        smoothing = Smoothing.of(self.posed_smoothing(model), motion.fps, restarts, jumps)
        lap("regressor")
        posing = self._posing_pool(garment_model, betas, boxes, gap, -(-t_frames // chunk))
        pending: deque[Future[np.ndarray]] = deque()  # the chunks the workers have, in order

        def collect() -> np.ndarray:
            points = pending.popleft().result()
            lap("workers")
            return points

        with (
            body_pool(self.push_out_workers if self.push_out else 1) as pool,
            closing(posing) if posing is not None else nullcontext(),
            _threads_beside(posing.workers if posing is not None else 0),
        ):
            for s in range(0, t_frames, chunk):
                e = min(s + chunk, t_frames)
                # the chunk and the frames around it that its smoothing reaches
                a, b = max(0, s - smoothing.radius), min(t_frames, e + smoothing.radius)
                core, smooth = slice(s - a, e - a), smoothing.within(a, b)
                with torch.no_grad():
                    x = model.decode(z[a:b])
                    lap("decoder")
                    if early:
                        x = torch.from_numpy(carry_to_lod(x.numpy(), *lods))
                        lap("carry")
                    floor = None  # a lower bound on x's SDF (t, N), for the smoothing's guard
                    if self.canonical_push:
                        x, floor = push_out_canonical(x, self._fields.sdf)
                        lap("canonical")
                    if self.exact_fields:
                        tangents = [Tangent(slice(0, b - a), None, 0.0)]
                    else:
                        tangents = _tangents(self._fields, x, tangents[-1] if tangents else None)
                    parts = [(part.frames, part.tangent) for part in tangents]
                    lap("fields")
                    if posing is not None:  # posed and pushed there, in the order given
                        work = (x, floor, parts, pose[a:b], trans[a:b], core, smooth)
                        pending.append(posing.submit(*work))
                        while len(pending) > posing.workers:  # one chunk waits for a worker
                            yield collect()
                            clock[0] = time.perf_counter()
                        continue
                    art = garment_model.articulation(betas, pose[a:b], trans[a:b])
                    posed = pose_chunk(garment_model, x, parts, art, smooth.sigma > 0)
                    sdf = self._fields.sdf if self.canonical_push else None
                    vertices, unposed = smooth.apply(x, posed, core, sdf, floor)
                    del posed  # freed before the push (the blended transforms: ~55 MB a chunk)
                    lap("posing")
                    if boxes is not None:  # the whole chunk at once: fewer, larger steps
                        vertices = preimage_push(
                            vertices, unposed, art.transforms[core], self._fields, betas, boxes,
                            PUSH_OUT_EPS, gap,
                        )  # fmt: skip
                        lap("preimage")
                    points = vertices.numpy()
                if carried and not early:
                    points = carry_to_lod(points, *lods)
                    lap("carry")
                if surface is not None:
                    with torch.no_grad():
                        posed = body(betas, pose[s:e], trans[s:e]).vertices.numpy()
                    points = push_out(points, posed, surface, pool=pool)
                    lap("push_out")
                yield points
                clock[0] = time.perf_counter()  # the consumer's time (writing) is not ours
            while pending:
                yield collect()
                clock[0] = time.perf_counter()

    def _posing_pool(
        self,
        garment_model: GarmentModel,
        betas: torch.Tensor,
        boxes: PartBoxes | None,
        gap: ShapeGap | None,
        chunks: int,
    ) -> PosingPool | None:
        """Worker processes that pose and push the ``chunks`` chunks of a motion: at most
        :attr:`workers`, two chunks or more each (a worker's one thread is slower than this
        process's threads, and the first and the last chunk leave cores idle). None where this
        process does: a method without the preimage push, fewer than two workers, or a
        platform that cannot fork."""
        workers = min(self.workers, chunks // 2)
        if boxes is None or workers <= 1 or not can_fork():
            return None
        return PosingPool(workers, garment_model, betas, boxes, PUSH_OUT_EPS, gap)


@contextmanager
def _threads_beside(workers: int) -> Iterator[None]:
    """This process's torch threads limited to the CPU cores that ``workers`` busy worker
    processes leave (at least one) for the time of the context: more threads than cores
    spin against the workers (on two cores with two workers, two threads here took the
    decoder and the USD write three to five times as long as one)."""
    if workers == 0:
        yield
        return
    threads = torch.get_num_threads()
    torch.set_num_threads(max(1, min(threads, available_cores() - workers)))
    try:
        yield
    finally:
        torch.set_num_threads(threads)


@dataclass(frozen=True)
class Tangent:
    """The body fields to first order (None: exact) for the frames ``frames`` of a chunk, and
    the exact lookups per frame (points beyond its radius) it needed on the frames it was
    made for."""

    frames: slice
    tangent: FieldTangent | None
    far_per_frame: float


#: Numbers of equal parts a chunk may be cut into, each part linearized about its own mean.
PART_COUNTS = (1, 2, 4, 8, 16)
#: The cut is chosen from every this-many-th vertex's distances.
PART_SAMPLE = 8


def _tangents(fields: BodyFields, x: torch.Tensor, last: Tangent | None) -> list[Tangent]:
    """The fields to first order for the canonical garments ``x`` ``(t, N, 3)`` of a chunk, in
    consecutive parts. ``last`` (the previous chunk's last part) is kept for the whole chunk
    while the exact lookups it needs for ``x`` (its far points, beyond those it had per frame
    when made) cost less than linearizing again (:data:`LINEARIZATION_LOOKUPS` lookups of N
    points). Otherwise the chunk is cut into the number of equal parts (of
    :data:`PART_COUNTS`) that needs the fewest lookups, each part's linearization and the
    exact lookups of its points more than the radius from that part's mean, counted on every
    :data:`PART_SAMPLE`-th vertex: a garment that moves more than the radius within the chunk
    (the arms of a real capture at 120 frames/s) gets an anchor per part."""
    cost = LINEARIZATION_LOOKUPS * x.shape[1]
    if last is not None and last.tangent is not None:
        extra = last.tangent.far_count(x) - last.far_per_frame * len(x)
        if extra < cost:
            return [Tangent(slice(0, len(x)), last.tangent, last.far_per_frame)]
    out = []
    for frames in _parts(x, cost, LINEARIZATION_RADIUS):
        tangent = fields.linearized(x[frames].mean(dim=0))
        far = tangent.far_count(x[frames]) / (frames.stop - frames.start)
        out.append(Tangent(frames, tangent, far))
    return out


def _parts(x: torch.Tensor, cost: int, radius: float) -> list[slice]:
    """The frames of ``x`` ``(t, N, 3)`` cut into equal parts (see :func:`_tangents`)."""
    sample = x[:, ::PART_SAMPLE]
    scale = x.shape[1] / sample.shape[1]
    best: tuple[float, list[slice]] | None = None
    for count in PART_COUNTS:
        if count > len(x):
            break
        size = -(-len(x) // count)
        parts = [slice(a, min(a + size, len(x))) for a in range(0, len(x), size)]
        far = sum(
            int(((sample[p] - sample[p].mean(dim=0)).square().sum(-1) > radius**2).sum())
            for p in parts
        )
        lookups = len(parts) * cost + scale * far
        if best is None or lookups < best[0]:
            best = (lookups, parts)
    assert best is not None
    return best[1]


class LearnedPushOutMethod(LearnedMethod):
    """The learned garment, then vertices inside or within ε = 2 mm of the posed body pushed out
    (the baselines' post-process, winding-number inside test)."""

    name = "learned+postprocess"
    push_out = True


class LearnedCanonicalMethod(LearnedMethod):
    """The learned garment with its decoded canonical garment pushed ε = 2 mm out of the
    canonical body before posing (a grid lookup per vertex, about 0.7 ms per frame of the
    T-shirt): the collisions that the decoder leaves in canonical space, not those that posing
    makes."""

    name = "learned+canonical"
    canonical_push = True


class LearnedPreimageMethod(LearnedMethod):
    """The learned garment pushed out of the body without a search structure per frame: its
    decoded canonical garment ε out of the canonical body (``learned+canonical``), then each
    posed vertex ε out of the parts that posing carries it into, found through the body's
    skinning preimages (:func:`preimage_push`; on a shaped body each preimage's distance less
    the shape fields' shortfall there, :func:`shape_gap`). Not exact: a preimage the fixed
    point misses, or a vertex between two parts, can stay inside; the winding-number push-out
    (``learned+postprocess``) is."""

    name = "learned+preimage"
    canonical_push = True
    preimage = True


#: The learned method of each ``dress --quality`` (None: none given); :func:`quality_method`.
QUALITY_METHODS: dict[str | None, str] = {
    "draft": LearnedMethod.name,
    None: LearnedPreimageMethod.name,
    "final": LearnedPushOutMethod.name,
}

#: The learned methods (they take a model directory).
LEARNED_CLASSES: tuple[type[LearnedMethod], ...] = (
    LearnedMethod, LearnedCanonicalMethod, LearnedPreimageMethod, LearnedPushOutMethod,
)  # fmt: skip
#: Their registry names.
LEARNED_METHODS = tuple(kind.name for kind in LEARNED_CLASSES)
