"""Register the package's codeless USD schemas and apply / read them on prims.

``SmplBodyAPI`` (on a Skeleton): ``smpl:betas``, ``smpl:gender``, ``smpl:model``,
``smpl:modelVersion``, ``smpl:cuts``. ``GarmentAPI`` (on a garment Mesh): ``garment:type``,
``garment:method``, ``garment:model``, ``garment:modelVersion``, ``garment:bodyModel``,
``garment:solverSettings`` and the relationship ``garment:body``. Files that use them still open
where the plugin is not registered: the applied schema names and the attributes are ordinary
scene description.
"""

from __future__ import annotations

from importlib import resources

import numpy as np
from pxr import Plug, Sdf, Usd, Vt

SMPL_BODY_API = "SmplBodyAPI"
GARMENT_API = "GarmentAPI"

_registered = False


def register_schemas() -> None:
    """Register ``schemas/plugInfo.json`` with USD's plugin registry (idempotent)."""
    global _registered
    if _registered:
        return
    folder = resources.files("usd_garment.schemas")
    Plug.Registry().RegisterPlugins(str(folder / "plugInfo.json"))
    _registered = True


def apply_smpl_body(
    prim: Usd.Prim,
    betas: np.ndarray,
    gender: str = "neutral",
    model: str = "",
    model_version: str = "",
    cuts: tuple[float, ...] = (),
) -> None:
    """Apply ``SmplBodyAPI`` to ``prim`` (a Skeleton) and author its attributes.

    Args:
        betas: ``(K,)`` shape coefficients.
        cuts: time codes where the animation starts anew (``smpl:cuts``; none: not authored).
    """
    prim.AddAppliedSchema(SMPL_BODY_API)
    values = Vt.FloatArray.FromNumpy(np.ascontiguousarray(betas, dtype=np.float32))
    _uniform(prim, "smpl:betas", Sdf.ValueTypeNames.FloatArray).Set(values)
    _uniform(prim, "smpl:gender", Sdf.ValueTypeNames.Token).Set(gender)
    _uniform(prim, "smpl:model", Sdf.ValueTypeNames.String).Set(model)
    if model_version:
        _uniform(prim, "smpl:modelVersion", Sdf.ValueTypeNames.String).Set(model_version)
    if cuts:
        values = Vt.DoubleArray.FromNumpy(np.asarray(cuts, dtype=np.float64))
        _uniform(prim, "smpl:cuts", Sdf.ValueTypeNames.DoubleArray).Set(values)


def read_betas(prim: Usd.Prim) -> np.ndarray | None:
    """``(K,)`` float64 ``smpl:betas`` of ``prim``, or None when none are authored."""
    return _authored_array(prim, "smpl:betas")


def read_cuts(prim: Usd.Prim) -> np.ndarray | None:
    """``(C,)`` float64 ``smpl:cuts`` of ``prim`` (time codes), or None when none are authored."""
    return _authored_array(prim, "smpl:cuts")


def _authored_array(prim: Usd.Prim, name: str) -> np.ndarray | None:
    """The authored array attribute ``name`` of ``prim`` as a flat float64 array, or None."""
    attr = prim.GetAttribute(name)
    if not attr or not attr.HasAuthoredValue():
        return None
    return np.asarray(attr.Get(), dtype=np.float64).reshape(-1)


def read_smpl_body(prim: Usd.Prim) -> dict[str, str]:
    """The authored ``smpl:gender``, ``smpl:model`` and ``smpl:modelVersion`` of ``prim``."""
    out: dict[str, str] = {}
    for key in ("gender", "model", "modelVersion"):
        attr = prim.GetAttribute(f"smpl:{key}")
        if attr and attr.HasAuthoredValue():
            out[key] = str(attr.Get())
    return out


def apply_garment(
    prim: Usd.Prim,
    garment_type: str,
    method: str,
    model: str = "",
    model_version: str = "",
    body_model: str = "",
    body: Sdf.Path | str | None = None,
    solver_settings: str = "",
) -> None:
    """Apply ``GarmentAPI`` to ``prim`` (a garment Mesh) and author its attributes."""
    prim.AddAppliedSchema(GARMENT_API)
    _uniform(prim, "garment:type", Sdf.ValueTypeNames.Token).Set(garment_type)
    _uniform(prim, "garment:method", Sdf.ValueTypeNames.Token).Set(method)
    strings = {
        "garment:model": model,
        "garment:modelVersion": model_version,
        "garment:bodyModel": body_model,
        "garment:solverSettings": solver_settings,
    }
    for name, value in strings.items():
        if value:
            _uniform(prim, name, Sdf.ValueTypeNames.String).Set(value)
    if body is not None:
        prim.CreateRelationship("garment:body", custom=False).SetTargets([Sdf.Path(str(body))])


def read_garment(prim: Usd.Prim) -> dict[str, str]:
    """The authored ``garment:*`` attributes of ``prim`` (names without the namespace) and the
    first ``garment:body`` target as ``body``."""
    out: dict[str, str] = {}
    for attr in prim.GetAuthoredAttributes():
        name = attr.GetName()
        if name.startswith("garment:"):
            out[name.split(":", 1)[1]] = str(attr.Get())
    rel = prim.GetRelationship("garment:body")
    if rel and rel.GetTargets():
        out["body"] = str(rel.GetTargets()[0])
    return out


def _uniform(prim: Usd.Prim, name: str, type_name: Sdf.ValueTypeName) -> Usd.Attribute:
    return prim.CreateAttribute(name, type_name, custom=False, variability=Sdf.VariabilityUniform)
