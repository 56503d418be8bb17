"""The ``usd-garment`` commands that a script of ``examples/train`` runs, read without running
them: the script is run against a stand-in ``usd-garment`` that logs its arguments."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).parent.parent

# Logs its arguments, one JSON list a line; makes what later lines of a script read: the folder
# of a training's --out (with model.json for `train all`, and for `train combine` one that lists
# a member for each run folder joined), the file of a projection's, a
# motion's, a simulation's or an import's -o.
STAND_IN = """\
import json, pathlib, sys
args = sys.argv[1:]
with open({log!r}, "a") as f:
    f.write(json.dumps(args) + "\\n")
if args[0] == "train" and "--out" in args:
    pathlib.Path(args[args.index("--out") + 1]).mkdir(parents=True, exist_ok=True)
if args[:2] == ["train", "all"]:
    (pathlib.Path(args[args.index("--out") + 1]) / "model.json").touch()
if args[:2] == ["train", "combine"]:  # a member for each run folder joined
    joined = [a for a in args[2:args.index("--out")] if not a.startswith("-")]
    model = pathlib.Path(args[args.index("--out") + 1]) / "model.json"
    model.write_text(json.dumps({{"members": [{{}} for _ in joined]}}))
if args[0] in ("project", "motion", "simulate", "import-bvh"):
    pathlib.Path(args[args.index("-o") + 1]).touch()
"""


def script_calls(
    script: str, *args: str, tmp_path: Path, env: dict[str, str] | None = None
) -> list[list[str]]:
    """Run ``bash examples/train/SCRIPT ARGS...`` in ``tmp_path / "work"``, which links to the
    repository's ``examples`` folder (so that the script's relative ``scratch/`` paths land in
    ``tmp_path``), against the stand-in, with ``env`` added to the environment; return the
    arguments of each ``usd-garment`` call, in order."""
    log = tmp_path / "calls.jsonl"
    stand_in = tmp_path / "bin" / "usd-garment"
    stand_in.parent.mkdir()
    stand_in.write_text(f"#!{sys.executable}\n" + STAND_IN.format(log=str(log)))
    stand_in.chmod(0o755)
    env = {**os.environ, **(env or {}),
           "PATH": f"{stand_in.parent}{os.pathsep}{os.environ['PATH']}"}  # fmt: skip
    work = tmp_path / "work"
    work.mkdir()
    (work / "examples").symlink_to(ROOT / "examples", target_is_directory=True)
    command = ["bash", f"examples/train/{script}", *args]
    subprocess.run(command, env=env, check=True, cwd=work)
    return [json.loads(line) for line in log.read_text().splitlines()]


def calls_on_base(
    script: str, out: str, tmp_path: Path, names: tuple[str, ...] = ("v4c", "v4cs")
) -> list[list[str]]:
    """:func:`script_calls` of ``SCRIPT tshirt OUT BASE``, BASE a folder of ``tmp_path`` holding
    the T-shirt's canonical sets ``names`` (``canonical_tshirt_NAME.npz``, each file's text its
    name: see :func:`copied_from_base`)."""
    base = tmp_path / "base"
    base.mkdir()
    for name in names:
        (base / f"canonical_tshirt_{name}.npz").write_text(name)
    return script_calls(script, "tshirt", out, str(base), tmp_path=tmp_path)


def copied_from_base(tmp_path: Path, out: str, names: tuple[str, ...] = ("v4c", "v4cs")) -> bool:
    """Whether the files ``OUT/canonical_tshirt_NAME.npz`` that a script of
    :func:`calls_on_base` left are BASE's, copied before the projections (the stand-in leaves a
    projected file as it is)."""
    folder = tmp_path / "work" / out
    return all((folder / f"canonical_tshirt_{n}.npz").read_text() == n for n in names)
