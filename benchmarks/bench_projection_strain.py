"""The projection's strain weight ω1 against what a model trained on its output can reach: one
simulated sequence of a dataset projected again with each weight (``usd-garment project
--strain-weight``), then its targets posed back and measured (``usd-garment dataset floor``).

Per weight it prints the projection's wall time, the reprojection error (mean, largest vertex),
the inside share of the posed-back targets (forced / elsewhere, winding number) beside the
simulation's, and how rough the canonical garment gets (the uniform Laplacian's p99.9 over all
vertices and frames, mm; the mean strain energy per frame). Lower ω1 fits the simulation closer
where posing folds the cloth, at the price of a rougher canonical garment.

    python benchmarks/bench_projection_strain.py --manifest scratch/dataset_tshirt_v3 \
        --sequence m08_s2 --strain-weight 1e-5 1e-6 1e-7 0
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from usd_garment.body.io import load_body_model
from usd_garment.canonical.floor import representation_floor
from usd_garment.canonical.project_layers import project_layers
from usd_garment.canonical.projection import ProjectionSettings
from usd_garment.canonical.strain import TriangleStrain
from usd_garment.fields.body_fields import load_body_fields
from usd_garment.generative.losses import UniformLaplacian


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--manifest", type=Path, required=True, help="A 'dataset make' folder.")
    parser.add_argument("--sequence", required=True, help="Sequence name, e.g. m08_s2.")
    parser.add_argument("--strain-weight", type=float, nargs="+", default=[1e-5, 1e-6])
    args = parser.parse_args()
    manifest = json.loads((args.manifest / "manifest.json").read_text())
    (entry,) = [e for e in manifest["sequences"] if e["name"] == args.sequence]
    sim = args.manifest / entry["files"]["garment"]
    body_layer = args.manifest / entry["files"]["body"]
    body, fields = load_body_model(), load_body_fields()
    print(f"{args.sequence} ({manifest['garment']}, {manifest['lod']}): {sim}")
    print("ω1 | seconds | reprojection mean / max mm | simulation forced / elsewhere % "
          "| posed back forced / elsewhere % | Laplacian p99.9 mm | strain per frame")  # fmt: skip
    with tempfile.TemporaryDirectory() as folder:
        for weight in args.strain_weight:
            out = Path(folder) / f"set_{weight:g}.npz"
            started = time.perf_counter()
            data = project_layers(
                [sim], [body_layer], out, garment=manifest["garment"], lod=manifest["lod"],
                settings=ProjectionSettings(strain_weight=weight),
            )  # fmt: skip
            seconds = time.perf_counter() - started
            (row,) = representation_floor(data, body, fields)
            x = torch.as_tensor(data.canonical)
            laplacian = UniformLaplacian(data.faces, x.shape[1])(x).norm(dim=-1)
            strain = TriangleStrain(torch.as_tensor(data.template), torch.as_tensor(data.faces))
            rough = float(np.quantile(laplacian.numpy(), 0.999)) * 1e3
            sim_s, back = row.simulation, row.reposed
            print(
                f"{weight:g} | {seconds:.1f} | {1e3 * data.error.mean():.2f} / "
                f"{1e3 * data.max_error.max():.1f} | {100 * sim_s['inside_forced_share']:.3f} / "
                f"{100 * sim_s['inside_elsewhere_share']:.3f} | "
                f"{100 * back['inside_forced_share']:.3f} / "
                f"{100 * back['inside_elsewhere_share']:.3f} | {rough:.1f} | "
                f"{float(strain.energy(x).mean()):.0f}"
            )


if __name__ == "__main__":
    main()
