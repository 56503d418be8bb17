"""The wheel's package list and package data cover every subpackage and shipped data file.

An editable install imports unlisted subpackages anyway, so only this test catches them."""

from __future__ import annotations

import fnmatch
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _setuptools() -> dict:
    with (ROOT / "pyproject.toml").open("rb") as fh:
        return tomllib.load(fh)["tool"]["setuptools"]


def test_every_subpackage_is_listed() -> None:
    listed = set(_setuptools()["packages"])
    found = {
        "usd_garment." + ".".join(p.parent.relative_to(ROOT / "usd_garment").parts)
        for p in (ROOT / "usd_garment").rglob("__init__.py")
        if p.parent != ROOT / "usd_garment"
    }
    assert found - listed == set(), "add these to [tool.setuptools] packages"


def test_every_data_file_is_package_data() -> None:
    patterns = _setuptools()["package-data"]["usd_garment"]
    data = [p.relative_to(ROOT / "usd_garment").as_posix()
            for p in (ROOT / "usd_garment" / "data").rglob("*") if p.is_file()]  # fmt: skip
    assert data
    missing = [
        f
        for f in data
        if not any(fnmatch.fnmatch(f, p) and f.count("/") == p.count("/") for p in patterns)
    ]
    assert missing == [], "add these to [tool.setuptools.package-data]"


def test_each_shipped_model_fits_in_12_mb() -> None:
    """Issue 11: a shipped default model takes at most 12 MB in the repository (weights,
    model.json, figures, its members' curves and logs)."""
    models = [p for p in (ROOT / "usd_garment" / "data" / "models").iterdir() if p.is_dir()]
    assert {p.name for p in models} >= {"tshirt", "dress"}
    sizes = {p.name: sum(f.stat().st_size for f in p.rglob("*") if f.is_file()) for p in models}
    assert all(size <= 12_000_000 for size in sizes.values()), sizes
