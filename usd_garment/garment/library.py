"""Garment template files: the committed templates of the default body, and templates computed
(once, then cached) for a user's body model.

A template file is an ``.npz`` with vertices ``(N, 3)`` float32, faces ``(F, 3)`` int32, uvs
``(N, 2)`` float32 and string/int metadata: name, lod, body, body_fingerprint, recipe_version.

Each template also has a *draped* version in the same format (``tshirt_high_draped.npz``): the
template settled under gravity on the rest body by the cloth simulator (``usd-garment garment
drape``), the shape the physics and everything downstream of it start from. The geometric
template keeps the garment's rest lengths.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from usd_garment.atomic import atomic_output
from usd_garment.body.fingerprint import rest_fingerprint
from usd_garment.body.io import load_body_model
from usd_garment.body.model import BodyModel
from usd_garment.garment.template import GARMENT_NAMES, LODS, RECIPE_VERSION, GarmentTemplate


@dataclass(frozen=True)
class Provenance:
    """Where a template file came from: the rest body it was fitted to and the recipe version."""

    body_fingerprint: str
    recipe_version: int


def template_dir() -> Path:
    """Folder of the committed templates of the default body."""
    return Path(str(resources.files("usd_garment") / "data" / "garments"))


def cache_dir() -> Path:
    """Folder of templates computed for users' bodies (``$XDG_CACHE_HOME`` or ``~/.cache``)."""
    root = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(root) / "usd-garment" / "garments"


def template_filename(name: str, lod: str, draped: bool = False) -> str:
    """File name of a template, e.g. ``tshirt_high.npz`` (``tshirt_high_draped.npz`` draped)."""
    return f"{name}_{lod}_draped.npz" if draped else f"{name}_{lod}.npz"


def save_template(path: str | Path, template: GarmentTemplate, provenance: Provenance) -> None:
    """Write a template file atomically (a temporary file renamed onto ``path``)."""
    with atomic_output(path) as tmp:
        np.savez_compressed(
            tmp,
            vertices=template.vertices.astype(np.float32),
            faces=template.faces.astype(np.int32),
            uvs=template.uvs.astype(np.float32),
            name=np.array(template.name),
            lod=np.array(template.lod),
            body=np.array(template.body),
            body_fingerprint=np.array(provenance.body_fingerprint),
            recipe_version=np.array(provenance.recipe_version),
        )


def read_template(path: str | Path) -> tuple[GarmentTemplate, Provenance]:
    """Read a template file.

    Raises:
        FileNotFoundError: no such file.
        ValueError: the file is not a template file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such garment template file")
    try:
        with np.load(path) as data:
            template = GarmentTemplate(
                name=str(data["name"]),
                lod=str(data["lod"]),
                vertices=data["vertices"].astype(np.float32),
                faces=data["faces"].astype(np.int32),
                uvs=data["uvs"].astype(np.float32),
                body=str(data["body"]),
            )
            provenance = Provenance(str(data["body_fingerprint"]), int(data["recipe_version"]))
    except (OSError, KeyError, ValueError) as exc:
        raise ValueError(f"{path}: not a garment template file ({exc})") from exc
    return template, provenance


def _check(name: str, lod: str) -> None:
    if name not in GARMENT_NAMES:
        raise ValueError(f"unknown garment '{name}' (known: {', '.join(GARMENT_NAMES)})")
    if lod not in LODS:
        raise ValueError(f"unknown level of detail '{lod}' (known: {', '.join(LODS)})")


def body_cache_dir(body: BodyModel) -> Path:
    """Cache folder of the templates of ``body``: keyed by its fingerprint and the recipe."""
    return cache_dir() / f"{rest_fingerprint(body)}-v{RECIPE_VERSION}"


def load_template(
    name: str,
    lod: str = "high",
    body_model_path: str | Path | None = None,
    draped: bool = False,
) -> GarmentTemplate:
    """The template of garment ``name`` at level of detail ``lod``.

    Without ``body_model_path`` it is the committed template of the default body; with one, it
    is computed for that body's rest shape on first use and cached under ``cache_dir()``, keyed by
    the body's fingerprint and the recipe version. ``draped`` gives the draped version, which
    ``usd-garment garment drape`` makes (committed for the default body, cached for others).

    Raises:
        ValueError: unknown name or level of detail, or an unreadable template file.
        FileNotFoundError: a draped template of a user's body that was not made yet.
        BodyModelError: the body model file cannot be loaded.
    """
    _check(name, lod)
    if body_model_path is None:
        return read_template(template_dir() / template_filename(name, lod, draped))[0]
    body = load_body_model(body_model_path)
    provenance = Provenance(rest_fingerprint(body), RECIPE_VERSION)
    folder = body_cache_dir(body)
    path = folder / template_filename(name, lod, draped)
    if path.is_file():
        return read_template(path)[0]
    if draped:
        raise FileNotFoundError(
            f"no draped {name} ({lod}) for this body yet: run 'usd-garment garment drape {name} "
            f"--lod {lod} --body-model {body_model_path}'"
        )
    # Here, not at the top: the recipe's scipy (ndimage, qhull) is for building templates only.
    from usd_garment.garment.templates import make_template

    template = make_template(body, name, lod)
    folder.mkdir(parents=True, exist_ok=True)
    save_template(path, template, provenance)
    return template


def find_draped(template: GarmentTemplate, body: BodyModel) -> GarmentTemplate | None:
    """The draped version of ``template`` made on ``body`` (committed or cached), or None when
    there is none with the same triangles fitted to the same rest body."""
    fingerprint = rest_fingerprint(body)
    name = template_filename(template.name, template.lod, draped=True)
    for path in (template_dir() / name, body_cache_dir(body) / name):
        if not path.is_file():
            continue
        draped, provenance = read_template(path)
        if provenance.body_fingerprint == fingerprint and np.array_equal(
            draped.faces, template.faces
        ):
            return draped
    return None
