"""The interface every garment method implements, and the registry the CLI picks methods from."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Protocol

import numpy as np

from usd_garment.body.model import BodyModel
from usd_garment.garment.template import GarmentTemplate
from usd_garment.motion.sequence import SmplMotion

#: Called with the number of frames finished so far.
Progress = Callable[[int], None]


class GarmentMethod(Protocol):
    """Poses a garment template on an animated body.

    Attributes:
        name: the registry name, written to the layer as ``garment:method``.
        version: version of the method or of its trained weights (``garment:modelVersion``).
        settings: the method's parameters, recorded as ``garment:solverSettings`` (JSON).

    A method may also have ``pushes_vertices`` (bool, False where absent; see
    :func:`pushes_vertices`) and ``predict_stream`` (see :func:`predict_chunks`).
    """

    name: str
    version: str
    settings: dict[str, float | int | str]

    def predict(
        self,
        motion: SmplMotion,
        body: BodyModel,
        template: GarmentTemplate,
        progress: Progress | None = None,
    ) -> np.ndarray:
        """Posed garment points ``(T, N, 3)`` float32, canonical frame (Y-up, metres)."""
        ...


_REGISTRY: dict[str, Callable[[], GarmentMethod]] = {}


def register_method(name: str, factory: Callable[[], GarmentMethod]) -> None:
    """Make ``factory`` available as ``get_method(name)``."""
    _REGISTRY[name] = factory


def available_methods() -> tuple[str, ...]:
    """Names of the registered methods, sorted."""
    return tuple(sorted(_REGISTRY))


def get_method(name: str) -> GarmentMethod:
    """A new instance of the method called ``name``.

    Raises:
        ValueError: no method has that name.
    """
    if name not in _REGISTRY:
        raise ValueError(f"unknown method '{name}' (available: {', '.join(available_methods())})")
    return _REGISTRY[name]()


def pushes_vertices(method: GarmentMethod) -> bool:
    """Whether ``method`` moves posed garment vertices out of the body one by one (the
    push-outs: ``+postprocess``, ``learned+preimage``): its garment carried down to a coarser
    mesh can then be inside the body again between the vertices it moved, so ``dress`` dresses
    each coarser level it writes (lod variants, a proxy) with the method itself."""
    return bool(getattr(method, "pushes_vertices", False))


def predict_chunks(
    method: GarmentMethod,
    motion: SmplMotion,
    body: BodyModel,
    template: GarmentTemplate,
    chunk: int,
    progress: Progress | None = None,
) -> Iterator[np.ndarray]:
    """The posed garment of ``method`` in consecutive chunks ``(t ≤ chunk, N, 3)`` float32
    (canonical frame, m), frames in order; ``progress`` gets the frames computed so far.

    Methods that pose frames chunk by chunk (``predict_stream(motion, body, template, chunk)``,
    e.g. skinning and the learned method) hold one chunk at a time and report after each; the
    others (the simulation) compute the whole sequence with ``predict`` first, reporting as
    they go.
    """
    stream = getattr(method, "predict_stream", None)
    if stream is None:
        points = method.predict(motion, body, template, progress)
        for s in range(0, len(points), chunk):
            yield points[s : s + chunk]
        return
    done = 0
    for part in stream(motion, body, template, chunk):
        done += len(part)
        if progress is not None:
            progress(done)
        yield part
