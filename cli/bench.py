"""``usd-garment bench``: every garment method at every level of detail on the same inputs in one
run; a JSON and CSV table, the speed–accuracy chart and the per-frame collision curves."""

from __future__ import annotations

import time
from pathlib import Path

import click
from tqdm import tqdm

from usd_garment.body.io import load_body_model
from usd_garment.cli.errors import user_errors
from usd_garment.cli.options import measure_workers_option, split_list
from usd_garment.eval.bench import BenchInput, BenchMethod, chart_table, run_bench, write_report
from usd_garment.eval.bench_plots import plot_chart, plot_collision_curves
from usd_garment.eval.body_distance import body_pool
from usd_garment.eval.machine import describe_machine, speed_readings
from usd_garment.eval.stress import LONG_FRAMES, write_stress_inputs
from usd_garment.garment.template import GARMENT_NAMES, LODS
from usd_garment.methods import available_methods
from usd_garment.methods.budget import BUDGET_FILE, budget_table, save_budget
from usd_garment.methods.learned import LEARNED_METHODS, LearnedMethod, shipped_model
from usd_garment.methods.learned_model import load_learned_model, model_identity
from usd_garment.methods.simulation import SimulationMethod
from usd_garment.training.dataset import dataset_layers

#: Methods benched when none is named (the learned one only where a model ships).
DEFAULT_METHODS = (
    "learned", "learned+canonical", "learned+preimage", "learned+postprocess", "lbs",
    "lbs+postprocess",
)  # fmt: skip


def _labelled_models(values: tuple[str, ...]) -> list[tuple[str, Path]]:
    models = []
    for value in values:
        label, sep, path = value.partition("=")
        if not sep or not label or not path:
            raise click.BadParameter(f"expected LABEL=DIR, got '{value}'", param_hint="--model")
        models.append((label, Path(path)))
    return models


def _methods(
    names: tuple[str, ...],
    models: list[tuple[str, Path]],
    model_methods: tuple[str, ...],
    lods: tuple[str, ...],
    garment: str,
    simulation_frames: int,
    simulation_lods: tuple[str, ...],
) -> list[BenchMethod]:
    """The benched methods: learned ones at the level of detail they were trained on and the
    coarser ones of ``lods`` (carried down), each of ``models`` with each of ``model_methods``
    (labelled LABEL, LABEL+canonical, LABEL+postprocess), the simulation on the first
    ``simulation_frames`` at ``simulation_lods``, the others at every one of ``lods``."""
    out = []
    runs: list[tuple[str, str, Path | None]] = []  # label, method, model directory
    for name in names or DEFAULT_METHODS:
        if name in LEARNED_METHODS:
            path = shipped_model(garment)
            if path is not None or names:
                runs.append((name, name, path))
        elif name == SimulationMethod.name:
            continue
        else:
            out.append(BenchMethod(name, name, lods=lods))
    runs += [
        (label + method.removeprefix(LearnedMethod.name), method, path)
        for label, path in models
        for method in model_methods or (LearnedMethod.name,)
    ]
    learned = []
    for label, method, path in runs:
        if path is None:
            raise click.UsageError(f"no trained model ships for the garment '{garment}'")
        trained = load_learned_model(path).lod
        dressed = (trained, *(lod for lod in lods if LODS[lod] < LODS[trained]))
        learned.append(BenchMethod(label, method, path, lods=dressed))
    out = learned + out
    if simulation_frames > 0 or SimulationMethod.name in names:
        frames = simulation_frames if simulation_frames > 0 else 30
        out.append(BenchMethod(SimulationMethod.name, SimulationMethod.name,
                               lods=simulation_lods, frames=frames))  # fmt: skip
    return out


def _plain(value: object) -> object:
    """A command-line value as JSON (paths as strings, tuples as lists)."""
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return str(value) if isinstance(value, Path) else value


@click.command("bench")
@click.argument("inputs", metavar="[INPUT]...", nargs=-1, type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Report folder: report.json, report.csv, chart.png, collisions.png, budget.json "
    "(the error table of dress --error-budget), layers/.",
)
@click.option(
    "--reference",
    "references",
    multiple=True,
    type=click.Path(path_type=Path),
    help="Simulated garment layer of each INPUT, in the same order (repeat): the error is "
    "measured against it.",
)
@click.option(
    "--manifest",
    type=click.Path(path_type=Path),
    default=None,
    help="Also bench the sequences of a 'dataset make' folder (see --split), each against its "
    "simulation.",
)
@click.option("--split", "split_names", default="test", show_default=True,
              help="With --manifest: comma-separated splits.")  # fmt: skip
@click.option(
    "--method",
    "names",
    multiple=True,
    type=click.Choice(available_methods()),
    help="Methods to bench (repeat); default: learned, learned+canonical, learned+preimage and "
    "learned+postprocess (where a model ships), lbs, lbs+postprocess.",
)
@click.option(
    "--model",
    "models",
    multiple=True,
    metavar="LABEL=DIR",
    help="Also bench a learned model directory under LABEL (repeat), e.g. an ablation.",
)
@click.option(
    "--model-method",
    "model_methods",
    multiple=True,
    type=click.Choice(LEARNED_METHODS),
    help="Learned methods each --model is benched with (repeat; default: learned); LABEL gains "
    "the method's suffix, e.g. LABEL+canonical.",
)
@click.option(
    "--lod",
    "lods",
    multiple=True,
    type=click.Choice(LODS),
    help="Levels of detail of the non-learned methods (repeat); default: all.",
)
@click.option(
    "--simulation-frames",
    type=click.IntRange(0),
    default=0,
    show_default=True,
    help="Also run the physics simulation on the first N frames of each input (slow).",
)
@click.option(
    "--simulation-lod",
    "simulation_lods",
    multiple=True,
    type=click.Choice(LODS),
    help="Levels of detail of the simulation (repeat); default: high.",
)
@click.option(
    "--stress",
    is_flag=True,
    help="Add the stress suite: β₁ = ±3, motion 2× and 4× faster, a long sequence, self-contact "
    "poses, root jumps, a declared splice of the joints (and each --capture).",
)
@click.option(
    "--stress-frames",
    type=click.IntRange(2),
    default=LONG_FRAMES,
    show_default=True,
    help="Frames of the stress suite's long sequence.",
)
@click.option(
    "--capture",
    "captures",
    multiple=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="With --stress: a BVH capture to add (repeat), imported at 30 fps.",
)
@click.option("--garment", type=click.Choice(GARMENT_NAMES), default="tshirt", show_default=True)
@measure_workers_option
def bench(
    inputs: tuple[Path, ...],
    output: Path,
    references: tuple[Path, ...],
    manifest: Path | None,
    split_names: str,
    names: tuple[str, ...],
    models: tuple[str, ...],
    model_methods: tuple[str, ...],
    lods: tuple[str, ...],
    simulation_frames: int,
    simulation_lods: tuple[str, ...],
    stress: bool,
    stress_frames: int,
    captures: tuple[Path, ...],
    garment: str,
    workers: int,
) -> None:
    """Dress every INPUT (animated body layers) with every method at every level of detail;
    chart speed against accuracy."""
    started = time.perf_counter()
    with user_errors():
        if references and len(references) != len(inputs):
            raise click.UsageError(
                f"give one --reference per INPUT ({len(references)} for {len(inputs)})"
            )
        cases = [
            BenchInput(path.stem, path, references[k] if references else None)
            for k, path in enumerate(inputs)
        ]
        if manifest is not None:
            layers = dataset_layers(manifest, split_list(split_names))
            cases += [
                BenchInput(name, body, sim)
                for name, body, sim in zip(
                    layers.names, layers.bodies, layers.garments, strict=True
                )
            ]
        if captures and not stress:
            raise click.UsageError("--capture is for --stress")
        if not cases and not stress:
            raise click.UsageError("give INPUT..., --manifest or --stress")
        for case in cases:
            for path in (case.body, case.reference):
                if path is not None and not path.is_file():
                    raise click.BadParameter(f"{path}: no such file")
        methods = _methods(names, _labelled_models(models), model_methods, lods or LODS,
                           garment, simulation_frames, simulation_lods or ("high",))  # fmt: skip
    output.mkdir(parents=True, exist_ok=True)
    if stress:
        with user_errors():
            cases += write_stress_inputs(
                output / "inputs", load_body_model(), long_frames=stress_frames, captures=captures
            )
    runs = sum(len(m.lods) for m in methods) * len(cases)
    with (
        tqdm(total=runs, desc="bench", unit="run", leave=False, disable=None) as bar,
        body_pool(workers) as pool,
    ):
        rows = run_bench(cases, methods, output, garment=garment, on_row=lambda _: bar.update(),
                         pool=pool)  # fmt: skip
    wall = time.perf_counter() - started
    source = {"wall_seconds": wall, "inputs": [c.name for c in cases]}
    write_report(rows, output, source)
    context = click.get_current_context()
    options = {k: _plain(v) for k, v in context.params.items()}
    measured = {**source, "command": context.command_path, "options": options,
                "machine": describe_machine(), "speed_readings": speed_readings()}  # fmt: skip
    shipped = [m.model for m in methods if m.label in LEARNED_METHODS and m.model is not None]
    if shipped:  # the table's learned entries are the shipped model's
        measured["model"] = model_identity(shipped[0])
    save_budget(output / BUDGET_FILE, budget_table(rows), measured)
    plot_chart(rows, output / "chart.png", f"{garment}: {len(cases)} input(s), {wall:.0f} s")
    plot_collision_curves(rows, output / "collisions.png")
    click.echo(chart_table(rows))
    for r in rows:
        if r.error:
            click.echo(f"failed: {r.label} ({r.lod}) on {r.input}: {r.error}")
    click.echo(f"{len(rows)} runs in {wall:.1f} s; wrote {output}")
