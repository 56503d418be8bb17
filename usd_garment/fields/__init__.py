"""Diffused body fields (skinning weights, shape and pose blendshapes around the body) and the
canonical body SDF: fitted from a body model, baked into grids for fast evaluation."""

from usd_garment.fields.body_fields import (
    BodyFields,
    default_fields_path,
    load_body_fields,
    save_body_fields,
)

__all__ = [
    "BodyFields",
    "default_fields_path",
    "fit_body_fields",
    "load_body_fields",
    "save_body_fields",
]


def __getattr__(name: str):  # lazy: fitting needs the [train] extra
    if name == "fit_body_fields":
        from usd_garment.fields.fit import fit_body_fields

        return fit_body_fields
    raise AttributeError(name)
