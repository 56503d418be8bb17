"""Training speed of ``usd-garment train all`` on each device: seconds per epoch of the pose
code, the garment VAE and the GRU regressor with the shipped T-shirt members' settings
(``examples/train/tshirt_member0.json``), and each device's ratio to the first one, measured in
one run.

Data: the synthetic canonical set of ``bench_decoder.py`` (the high T-shirt, 4,405 vertices,
smooth random displacements pushed out of the canonical body; poses at rest), sized like the
shipped T-shirt's training set by default (62 sequences of 100 frames: 6,000 training frames,
200 validation). An epoch costs what it costs on simulated data of that size; the fitted
figures mean nothing and are not printed.

Run: ``python benchmarks/bench_train.py [--devices cpu,cuda] [--sequences 62] [--frames 100]
[--epochs pose=10,vae=2,regressor=10] [--threads N] [--json FILE]``
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import torch
from bench_decoder import synthetic_set

from usd_garment.fields.body_fields import load_body_fields
from usd_garment.training.pipeline import STAGES, TrainSettings, train_stage
from usd_garment.training.vae import split_frames

CONFIG = Path(__file__).resolve().parents[1] / "examples" / "train" / "tshirt_member0.json"


def _epochs(text: str) -> dict[str, int]:
    pairs = (item.split("=") for item in text.split(","))
    epochs = {stage: int(count) for stage, count in pairs}
    if set(epochs) != set(STAGES) or min(epochs.values()) < 1:
        raise SystemExit(f"--epochs needs a positive count for each of {', '.join(STAGES)}")
    return epochs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--devices", default="cpu,cuda" if torch.cuda.is_available() else "cpu")
    parser.add_argument("--sequences", type=int, default=62)
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--epochs", type=_epochs, default=_epochs("pose=10,vae=2,regressor=10"))
    parser.add_argument("--threads", type=int, default=None, help="torch CPU threads")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    fields = load_body_fields()
    t0 = time.perf_counter()
    data = synthetic_set(fields, args.sequences, args.frames)
    train = len(split_frames(data, "train"))
    print(f"synthetic set: {args.sequences} sequences x {args.frames} frames "
          f"({train} train), made in {time.perf_counter() - t0:.1f} s; "
          f"torch {torch.__version__}, {torch.get_num_threads()} CPU threads"
          + (f", {torch.cuda.get_device_name()}" if torch.cuda.is_available() else ""))  # fmt: skip
    rows = []
    for device in args.devices.split(","):
        settings = TrainSettings.from_dict(json.loads(CONFIG.read_text(encoding="utf-8")))
        settings.set_device(device)
        settings.pose.epochs = args.epochs["pose"]
        settings.vae.epochs = args.epochs["vae"]
        settings.regressor.epochs = args.epochs["regressor"]
        with tempfile.TemporaryDirectory() as folder:
            for stage in STAGES:
                record = train_stage(stage, data, folder, settings, fields=fields)
                seconds = [row["seconds"] for row in record["history"]["epochs"]]
                rows.append({
                    "device": device,
                    "stage": stage,
                    "epochs": len(seconds),
                    "total_s": record["seconds"],
                    # the first epoch carries the warm-up (kernels, caches): left out where
                    # there are others
                    "epoch_s": sum(seconds[1:]) / (len(seconds) - 1)
                    if len(seconds) > 1 else seconds[0],
                })  # fmt: skip
    first = args.devices.split(",")[0]
    base = {r["stage"]: r["epoch_s"] for r in rows if r["device"] == first}
    print(f"{'stage':<10} {'device':<8} {'epochs':>6} {'total s':>9} {'s/epoch':>9} "
          f"{'vs ' + first:>8}")  # fmt: skip
    for r in rows:
        r["speedup"] = base[r["stage"]] / r["epoch_s"]
        print(f"{r['stage']:<10} {r['device']:<8} {r['epochs']:>6} {r['total_s']:>9.2f} "
              f"{r['epoch_s']:>9.3f} {r['speedup']:>7.1f}x")  # fmt: skip
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
