"""The decoder trade-off of the garment VAE: for several decoder architectures, parameters, size
(float32 / float16, decoder plus its per-vertex statistics, what the stage processor ships),
CPU time per frame of batched decoding (batch 256) and of one frame, and, trained briefly
(``--epochs``), validation reconstruction error and the share of vertices inside the canonical
body for reconstructions and for decodings of random latents (the paper's Fig. 4 figure).

Data: a canonical training set (``--canonical PATH``, its train / validation splits) or, without
one, a synthetic set on the T-shirt template: smooth random displacement fields (RBF bumps of
1.5 cm, smooth in time) pushed out of the real canonical body SDF to 2.5 mm. The synthetic set
is a stand-in: its figures say how the decoders compare, not how well they fit simulations.

Run: ``python benchmarks/bench_decoder.py [--canonical PATH] [--epochs N] [--configs a,b]
[--train-large] [--ablation] [--threads 1] [--json FILE]``
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import numpy as np
import torch

from usd_garment.canonical.dataset import CanonicalSet, load_canonical_set
from usd_garment.fields.body_fields import BodyFields, load_body_fields
from usd_garment.garment.library import load_template
from usd_garment.generative.vae import (
    OFFICIAL_DECODER,
    DecoderConfig,
    GarmentVAE,
    decoder_bytes,
    num_parameters,
)
from usd_garment.training.vae import VaeTrainConfig, split_frames, train_vae

#: The decoders compared, by name.
CONFIGS: dict[str, DecoderConfig] = {
    "official-mlp-4x2000": OFFICIAL_DECODER,
    "mlp-256x2": DecoderConfig(kind="mlp", hidden=(256, 256)),
    "mlp-128x2": DecoderConfig(kind="mlp", hidden=(128, 128)),
    "basis-32": DecoderConfig(kind="basis", hidden=(256, 256), basis_size=32),
    "basis-64": DecoderConfig(kind="basis", hidden=(256, 256), basis_size=64),
    "basis-128": DecoderConfig(kind="basis", hidden=(256, 256), basis_size=128),
}
#: Decoders above this many parameters are timed but trained only with ``--train-large``.
TRAIN_LIMIT = 10_000_000
BATCH = 256
MB = 1e6


def synthetic_set(
    fields: BodyFields, sequences: int = 10, frames: int = 60, seed: int = 0
) -> CanonicalSet:
    """Synthetic canonical T-shirts (high, 4,405 vertices): the template plus 16 smooth RBF
    displacement bumps (σ 10 cm, up to ~1.5 cm, sinusoidal in time), then pushed out along the
    SDF gradient to at least 2.5 mm outside the canonical body. Two sequences are validation."""
    template = load_template("tshirt", "high")
    v = template.vertices.astype(np.float32)
    rng = np.random.default_rng(seed)
    centres = v[rng.choice(len(v), 16, replace=False)]
    kernel = np.exp(-((v[:, None] - centres[None]) ** 2).sum(-1) / (2 * 0.1**2))
    kernel /= kernel.sum(1, keepdims=True)  # (N, 16)
    t = np.arange(frames)[:, None, None]
    parts = []
    for _ in range(sequences):
        freq = rng.uniform(0.03, 0.25, size=(1, 16, 3))
        phase = rng.uniform(0, 2 * np.pi, size=(1, 16, 3))
        coeffs = 0.015 * np.sin(freq * t + phase)  # (T, 16, 3)
        parts.append(v[None] + np.einsum("nk,tkc->tnc", kernel, coeffs))
    x = torch.as_tensor(np.concatenate(parts).astype(np.float32))
    for _ in range(6):  # push out of the body
        for chunk in x.split(64):
            p = chunk.clone().requires_grad_(True)
            d = fields.sdf(p)
            (g,) = torch.autograd.grad(d.sum(), p)
            step = (2.5e-3 - d.detach()).clamp_min(0.0)[..., None]
            chunk += step * torch.nn.functional.normalize(g, dim=-1)
    total = len(x)
    return CanonicalSet(
        canonical=x.numpy(),
        frame_offsets=np.arange(0, total + 1, frames),
        betas=np.zeros((sequences, 10), np.float32),
        pose=np.zeros((total, 24, 3), np.float32),
        trans=np.zeros((total, 3), np.float32),
        fps=np.full(sequences, 30.0, np.float32),
        error=np.zeros(total, np.float32),
        max_error=np.zeros(total, np.float32),
        template=v,
        faces=template.faces,
        sources=[f"synthetic{s}" for s in range(sequences)],
        splits=["validation" if s < 2 else "train" for s in range(sequences)],
        metadata={"garment": "tshirt", "lod": "high", "synthetic": True},
    )


def _best_ms(fn: Callable[[], object], repeats: int = 3) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return 1e3 * best


@torch.no_grad()
def time_decoder(model: GarmentVAE) -> tuple[float, float]:
    """CPU ms per frame decoding a batch of 256, and ms for one frame alone."""
    model.eval()
    gen = torch.Generator().manual_seed(0)
    z = torch.randn(BATCH, model.latent_size, generator=gen)
    model.decode(z[:8])  # warm up
    batched = _best_ms(lambda: model.decode(z)) / BATCH
    single = _best_ms(lambda: [model.decode(z[i : i + 1]) for i in range(16)]) / 16
    return batched, single


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--canonical", help="canonical training set (.npz); default: synthetic")
    parser.add_argument("--epochs", type=int, default=0, help="train each decoder this long")
    parser.add_argument("--configs", default=",".join(CONFIGS), help="comma-separated names")
    parser.add_argument("--train-large", action="store_true", help="train decoders > 10 M too")
    parser.add_argument(
        "--ablation", action="store_true",
        help="also train each decoder without the self-supervised term and without collisions",
    )  # fmt: skip
    parser.add_argument("--batch-size", type=int, default=64)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    parser.add_argument("--json", help="write the rows to this file")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    fields = load_body_fields()
    if args.canonical:
        data = load_canonical_set(args.canonical)
        source = args.canonical
    else:
        t0 = time.perf_counter()
        data = synthetic_set(fields)
        source = f"synthetic ({time.perf_counter() - t0:.1f} s to make)"
    n = data.canonical.shape[1]
    splits = {s: len(split_frames(data, s)) for s in ("train", "validation")}
    print(f"data: {source}; {n} vertices; frames train {splits['train']}, "
          f"validation {splits['validation']}; {args.threads} torch thread(s)")  # fmt: skip

    names = [name.strip() for name in args.configs.split(",") if name.strip()]
    rows = []
    header = (
        f"{'decoder':<22}{'params':>12}{'MB f32':>9}{'MB f16':>9}{'ms/frame b256':>15}"
        f"{'ms 1 frame':>12}{'enc params':>12}  {'variant':<16}{'epochs':>7}{'rec L1 mm':>11}"
        f"{'rec in %':>10}{'rand in %':>11}{'rand <1mm %':>13}{'s/epoch':>9}"
    )
    print(header)
    for name in names:
        decoder = CONFIGS[name]
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(args.seed)
            model = GarmentVAE(n, encoder_hidden=(256, 256), decoder=decoder)
        params = num_parameters(model.decoder)
        batched, single = time_decoder(model)
        base = {
            "decoder": name, "config": decoder.to_dict(), "params": params,
            "mb_f32": decoder_bytes(model, 4) / MB, "mb_f16": decoder_bytes(model, 2) / MB,
            "ms_per_frame_batch256": batched, "ms_single_frame": single,
            "encoder_params": num_parameters(model.encoder),
        }  # fmt: skip
        del model
        variants = [("full", {})]
        if args.ablation:
            variants += [("no-self-sup", {"self_supervised": False}),
                         ("no-collision", {"collision": False})]  # fmt: skip
        trainable = args.epochs > 0 and (params <= TRAIN_LIMIT or args.train_large)
        for variant, changes in variants if trainable else [("-", {})]:
            row = dict(base, variant=variant)
            if trainable:
                config = VaeTrainConfig(
                    epochs=args.epochs, batch_size=args.batch_size, decoder=decoder,
                    seed=args.seed, **changes,
                )  # fmt: skip
                _, history = train_vae(data, config, fields=fields)
                last = history["epochs"][-1]
                row |= {
                    "epochs": args.epochs,
                    "rec_l1_mm": last["val_rec_l1_mm"],
                    "rec_inside_pct": last["val_rec_inside_pct"],
                    "rand_inside_pct": last["val_rand_inside_pct"],
                    "rand_near_pct": last["val_rand_near_pct"],
                    "seconds_per_epoch": float(np.mean([r["seconds"] for r in history["epochs"]])),
                    "history": history["epochs"],
                }
            rows.append(row)

            def cell(key: str, width: int, fmt: str, row: dict = row) -> str:
                value = row.get(key)
                return f"{'-':>{width}}" if value is None else f"{value:>{width}{fmt}}"

            print(
                f"{name:<22}{params:>12,}{base['mb_f32']:>9.2f}{base['mb_f16']:>9.2f}"
                f"{batched:>15.3f}{single:>12.3f}{base['encoder_params']:>12,}  {variant:<16}"
                + cell("epochs", 7, "d") + cell("rec_l1_mm", 11, ".3f")
                + cell("rec_inside_pct", 10, ".3f") + cell("rand_inside_pct", 11, ".3f")
                + cell("rand_near_pct", 13, ".3f") + cell("seconds_per_epoch", 9, ".1f"),
                flush=True,
            )  # fmt: skip
    if args.json:
        with open(args.json, "w") as handle:
            json.dump({"data": source, "threads": args.threads, "rows": rows}, handle, indent=1)


if __name__ == "__main__":
    main()
