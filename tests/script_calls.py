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
# of a training's --out (with model.json for `train all`), the file of a projection's, a
# motion's, a simulation's or an import's -o.
STAND_IN = """\
import json, pathlib, sys
args = sys.argv[1:]
with open({log!r}, "a") as f:
    f.write(json.dumps(args) + "\\n")
if args[0] == "train":
    pathlib.Path(args[args.index("--out") + 1]).mkdir(parents=True, exist_ok=True)
if args[:2] == ["train", "all"]:
    (pathlib.Path(args[args.index("--out") + 1]) / "model.json").touch()
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
