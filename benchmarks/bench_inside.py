"""Collision figures of the garment baselines on given body layers, three ways, in one run:
``usd-garment eval`` (winding number against our posed body, split into forced and elsewhere),
an independent measure (the body mesh skinned by UsdSkel from the body layer itself, and libigl's
exact, non-approximated winding number), and the old measure (the sign of the nearest feature's
pseudo-normal, which misreads points where the body intersects itself).

Run: ``python benchmarks/bench_inside.py BODY.usda [BODY.usda ...] [--methods lbs,lbs+postprocess]
[--frames A:B]``; prints one row per body × method and the largest disagreement between eval
and the independent measure (percentage points of the inside share, per frame), with the
largest distance between the body that UsdSkel skins from the layer and the body we pose.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import igl
import numpy as np
from pxr import Usd, UsdGeom, UsdSkel

from usd_garment.body.io import load_body_model
from usd_garment.dress import dress
from usd_garment.eval.body_distance import WINDING_INSIDE, BodySurface, signed_distance
from usd_garment.eval.evaluate import evaluate_layer, posed_body_vertices
from usd_garment.usd.garment_read import read_garment_layer
from usd_garment.usd.read import read_smpl_motion


def usdskel_body(path: Path, time_codes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The first skinned mesh of the body layer, skinned by UsdSkel at ``time_codes``: world
    points ``(T, V, 3)`` (stage units) and triangles ``(F, 3)``."""
    stage = Usd.Stage.Open(str(path))
    cache = UsdSkel.Cache()
    for prim in stage.Traverse():
        if not prim.IsA(UsdSkel.Root):
            continue
        cache.Populate(UsdSkel.Root(prim), Usd.TraverseInstanceProxies())
        for binding in cache.ComputeSkelBindings(UsdSkel.Root(prim), Usd.PrimDefaultPredicate):
            skel_query = cache.GetSkelQuery(binding.GetSkeleton())
            for skinning in binding.GetSkinningTargets():
                mesh = UsdGeom.Mesh(skinning.GetPrim())
                if not mesh:
                    continue
                faces = np.array(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
                rest = mesh.GetPointsAttr().Get()
                out = []
                for code in time_codes:
                    xforms = skel_query.ComputeSkinningTransforms(float(code))
                    points = rest.__class__(rest)
                    skinning.ComputeSkinnedPoints(xforms, points, float(code))
                    world = skel_query.GetPrim().GetParent()
                    m = np.array(UsdGeom.Xformable(world).ComputeLocalToWorldTransform(float(code)))
                    p = np.asarray(points, dtype=np.float64)
                    out.append(p @ m[:3, :3] + m[3, :3])
                return np.stack(out), faces
    raise ValueError(f"{path}: no skinned mesh")


def measure(body_path: Path, garment_path: Path) -> dict[str, float]:
    """Inside shares (means and worst frames) of one garment layer, three ways."""
    metrics, codes = evaluate_layer(garment_path, body_path)
    points = read_garment_layer(garment_path)[0].astype(np.float64)
    skinned, faces = usdskel_body(body_path, codes)
    independent = np.stack(
        [
            igl.winding_number(skinned[t], faces, points[t]) > WINDING_INSIDE
            for t in range(len(codes))
        ]
    ).mean(axis=1)
    body = load_body_model(None)
    motion, _ = read_smpl_motion(body_path, body)
    ours = posed_body_vertices(body, motion)
    index = np.searchsorted(motion.time_codes, codes)
    query = signed_distance(points, ours[index], BodySurface(body.faces.numpy(), body.num_vertices))
    old = (((points - query.closest) * query.normal).sum(-1) < 0).mean(axis=1)
    apart = np.linalg.norm(skinned - ours[index].astype(np.float64), axis=-1).max()
    return {
        "eval": metrics.inside_share.mean(),
        "eval_max": metrics.inside_share.max(),
        "forced": metrics.inside_forced_share.mean(),
        "elsewhere": metrics.inside_elsewhere_share.mean(),
        "elsewhere_max": metrics.inside_elsewhere_share.max(),
        "independent": independent.mean(),
        "disagreement_pp": 100 * np.abs(independent - metrics.inside_share).max(),
        "old": old.mean(),
        "old_max": old.max(),
        "frames": len(codes),
        "body_apart_mm": 1000 * apart,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bodies", nargs="+", type=Path)
    parser.add_argument("--methods", default="lbs,lbs+postprocess")
    parser.add_argument("--garment", default="tshirt")
    parser.add_argument("--frames", default=None, help="A:B, a slice of frames (default: all)")
    args = parser.parse_args()
    frames = None
    if args.frames:
        a, b = args.frames.split(":")
        frames = (int(a), int(b))
    print(
        "figures are means over frames (worst frame in brackets); disagreement: largest "
        "per-frame |eval - independent| in percentage points"
    )
    worst = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for body_path in args.bodies:
            for method in args.methods.split(","):
                out = Path(tmp) / f"{body_path.stem}_{method}.usdc"
                start = time.perf_counter()
                dress(body_path, out, garment=args.garment, method=method, frames=frames)
                seconds = time.perf_counter() - start
                r = measure(body_path, out)
                worst = max(worst, r["disagreement_pp"])
                print(
                    f"{body_path.name:>22} {method:>16} ({r['frames']} frames, dress "
                    f"{r['frames'] / seconds:6.1f} frames/s): inside {100 * r['eval']:.3f}% "
                    f"[{100 * r['eval_max']:.2f}%] = forced {100 * r['forced']:.3f}% + "
                    f"elsewhere {100 * r['elsewhere']:.4f}% [{100 * r['elsewhere_max']:.3f}%]; "
                    f"independent {100 * r['independent']:.3f}%; old sign {100 * r['old']:.3f}% "
                    f"[{100 * r['old_max']:.2f}%]; disagreement {r['disagreement_pp']:.3f} pp; "
                    f"body layer (UsdSkel) vs ours at most {r['body_apart_mm']:.4f} mm"
                )
    print(f"largest disagreement of eval with the independent measure: {worst:.3f} pp")


if __name__ == "__main__":
    main()
