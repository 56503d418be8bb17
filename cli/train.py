"""``usd-garment train``: train the learned method's networks from a canonical training set
(``usd-garment project``) into a model directory, with progress bars, a plain-text log and
plots; ``train compare`` draws the paper's Fig. 4 from several runs."""

from __future__ import annotations

import json
import shlex
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click
import numpy as np
from tqdm import tqdm

from usd_garment.cli.errors import user_errors
from usd_garment.cli.motion import corpus_options, read_corpus
from usd_garment.methods.weight_storage import STORAGES

if TYPE_CHECKING:
    from usd_garment.body.model import BodyModel
    from usd_garment.canonical.dataset import CanonicalSet
    from usd_garment.fields.body_fields import BodyFields
    from usd_garment.training.posed_planes import PosedPlanes

F = TypeVar("F", bound=Callable[..., Any])


def _train_options(command: F) -> F:
    """Options shared by the stages."""
    for option in reversed((
        click.option("--data", type=click.Path(dir_okay=False, path_type=Path), required=True,
                     help="Canonical training set (.npz, from 'usd-garment project')."),
        click.option("--out", type=click.Path(file_okay=False, path_type=Path), required=True,
                     help="Model directory (run folder) to train into; created."),
        click.option("--device", default="cpu", show_default=True,
                     help="Torch device, e.g. cpu or cuda."),
        click.option("--resume", is_flag=True,
                     help="Continue from the run folder's checkpoints."),
        click.option("--config", "config_path", type=click.Path(dir_okay=False, path_type=Path),
                     default=None, help="JSON of settings per stage (keys pose, vae, regressor, "
                     "ablation, version); default: the run folder's config.json, else defaults."),
        click.option("--ablation", type=click.Choice(("none", "no-collision",
                     "no-self-supervision")), default=None,
                     help="The paper's VAE ablations (default: none, the full model)."),
        click.option("--epochs", "epochs", multiple=True, metavar="STAGE=N",
                     help="Epochs of a stage, e.g. --epochs vae=200 (repeatable)."),
        click.option("--seed", type=click.IntRange(min=0), default=None,
                     help="Every stage's seed (initial weights, noise, crops), over the "
                     "settings'; give it to each command of another training of a member's "
                     "recipe, as the settings it records are every stage's."),
        click.option("--init-from", "init_from", type=click.Path(file_okay=False,
                     path_type=Path), default=None, help="Run folder whose trained regressor "
                     "starts the regressor's training (a fine-tuning), over the settings' "
                     "init_from."),
        click.option("--planes", "planes_path", type=click.Path(dir_okay=False, path_type=Path),
                     default=None, help="Posed collision planes of --data for a regressor with "
                     "lambda_posed > 0 (.npz): read when made for this set, else computed and "
                     "written there (for a set that grew by 'project --update' from the one "
                     "they were made for, only its new sequences); default: computed, not "
                     "kept."),
    )):  # fmt: skip
        command = option(command)
    return command


@click.group()
def train() -> None:
    """Train the learned garment method: pose codec, garment VAE, regressor."""


def _settings(
    out: Path,
    config_path: Path | None,
    ablation: str | None,
    epochs: tuple[str, ...],
    device: str,
    seed: int | None = None,
    init_from: Path | None = None,
) -> Any:
    """The settings of a run: the settings file's (or the run folder's), then the options over
    them (``seed``: every stage's)."""
    from usd_garment.training.pipeline import STAGES, TrainSettings

    source = config_path or (out / "config.json")
    values = json.loads(source.read_text(encoding="utf-8")) if source.is_file() else {}
    if config_path is not None and not config_path.is_file():
        raise FileNotFoundError(f"{config_path}: no such settings file")
    if ablation is not None:
        values["ablation"] = ablation
    for text in epochs:
        stage, _, count = text.partition("=")
        if stage not in STAGES or not count.isdigit():
            raise click.BadParameter(f"expected STAGE=N with STAGE in {STAGES}, got {text!r}")
        values.setdefault(stage, {})["epochs"] = int(count)
    if seed is not None:
        for stage in STAGES:
            values.setdefault(stage, {})["seed"] = seed
    if init_from is not None:
        values.setdefault("regressor", {})["init_from"] = str(init_from)
    settings = TrainSettings.from_dict(values)
    settings.set_device(device)
    return settings


def _command_line(
    stages: tuple[str, ...],
    data: Path,
    out: Path,
    device: str,
    config_path: Path | None,
    ablation: str | None,
    epochs: tuple[str, ...],
    planes_path: Path | None,
    seed: int | None = None,
    init_from: Path | None = None,
) -> str:
    """The ``usd-garment train`` command that trains the same model (recorded in it)."""
    words = ["train", "all" if len(stages) > 1 else stages[0], "--data", str(data)]
    words += ["--out", str(out), "--device", device]
    if config_path is not None:
        words += ["--config", str(config_path)]
    if ablation is not None:
        words += ["--ablation", ablation]
    for text in epochs:
        words += ["--epochs", text]
    if seed is not None:
        words += ["--seed", str(seed)]
    if init_from is not None:
        words += ["--init-from", str(init_from)]
    if planes_path is not None:
        words += ["--planes", str(planes_path)]
    return "usd-garment " + shlex.join(words)


def _after_earlier(model_json: Path, command: str, trained: bool) -> str:
    """The command to record for a run that trained some stages of a run folder whose other
    stages earlier commands trained (e.g. the regressor again in a copy of a folder): those
    commands, then this one (``trained``: it trained an epoch), or those alone (a resume that
    found its stages finished). This one alone when the folder has no model yet."""
    try:
        earlier = str(json.loads(model_json.read_text(encoding="utf-8"))["command"])
    except (FileNotFoundError, KeyError, TypeError, json.JSONDecodeError):
        return command
    return f"{earlier}; then {command}" if trained else earlier


def _run(
    stages: tuple[str, ...],
    data: Path,
    out: Path,
    device: str,
    resume: bool,
    config_path: Path | None,
    ablation: str | None,
    epochs: tuple[str, ...],
    planes_path: Path | None = None,
    seed: int | None = None,
    init_from: Path | None = None,
) -> None:
    with user_errors():
        from usd_garment.body.io import load_body_model
        from usd_garment.canonical.dataset import load_canonical_set
        from usd_garment.fields.body_fields import load_body_fields
        from usd_garment.methods.learned_model import CONFIG_NAME, CURVES_NAME, LOG_NAME
        from usd_garment.training.pipeline import (
            STAGES,
            assemble_model,
            load_stage,
            train_stage,
        )
        from usd_garment.training.plots import plot_curves

        settings = _settings(out, config_path, ablation, epochs, device, seed, init_from)
        canonical = load_canonical_set(data)
        body = load_body_model(None)
        fields = load_body_fields()
        out.mkdir(parents=True, exist_ok=True)
        (out / "config.json").write_text(
            json.dumps(settings.to_dict(), indent=1) + "\n", encoding="utf-8"
        )
        trained = 0  # epochs this run trained (a resume may find its stages finished)
        for stage in stages:
            planes = None
            if stage == "regressor" and settings.regressor.lambda_posed > 0:
                planes = _posed_planes(canonical, body, fields, planes_path)
            bar = tqdm(desc=stage, unit="epoch", disable=None)

            def progress(name: str, epoch: int, total: int, row: dict[str, Any]) -> None:
                bar.total = total  # noqa: B023 (one bar per stage, used within it)
                bar.update(epoch - bar.n)  # noqa: B023
                shown = {k: v for k, v in row.items() if k.startswith("val_")}
                bar.set_postfix({k[4:]: f"{v:.4g}" for k, v in list(shown.items())[:3]})  # noqa: B023

            try:
                record = train_stage(
                    stage, canonical, out, settings, fields=fields, planes=planes,
                    resume=resume, progress=progress,
                )  # fmt: skip
            finally:
                bar.close()
            trained += len(record["history"]["epochs"]) - record["resumed_epochs"]
            click.echo(f"{stage}: {len(record['history']['epochs'])} epochs in "
                       f"{record['seconds']:.1f} s")  # fmt: skip
        records = {}
        for stage in STAGES:
            try:
                records[stage] = load_stage(out, stage)[1]
            except FileNotFoundError:
                continue
        plot_curves(records, out / CURVES_NAME)
        click.echo(f"wrote {out / CURVES_NAME}, log {out / LOG_NAME}")
        if len(records) == len(STAGES):
            command = _command_line(stages, data, out, device, config_path, ablation, epochs,
                                    planes_path, seed, init_from)  # fmt: skip
            if len(stages) < len(STAGES):
                command = _after_earlier(out / CONFIG_NAME, command, trained > 0)
            assemble_model(out, canonical, body, settings, {"command": command})
            click.echo(f"wrote the model {out}")


def _posed_planes(
    canonical: CanonicalSet, body: BodyModel, fields: BodyFields, path: Path | None
) -> PosedPlanes:
    """The posed collision planes of the training and validation frames: read from ``path``
    when it holds this set's, else computed with a progress bar (one query of the posed body
    per frame: minutes for a few thousand frames; those of the set's first sequences kept where
    ``path`` holds the planes of the set it grew from) and written to ``path`` when given.

    Raises:
        ValueError: ``path`` holds the planes of another set (or radius).
    """
    from usd_garment.eval.body_distance import body_pool
    from usd_garment.training.posed_planes import (
        PLANE_RADIUS,
        posed_planes,
        reusable_posed_planes,
        save_posed_planes,
    )

    known: PosedPlanes | None = None
    if path is not None and path.is_file():
        known, sequences = reusable_posed_planes(path, canonical, PLANE_RADIUS)
        if sequences == canonical.num_sequences:
            click.echo(f"posed planes from {path}")
            return known
        click.echo(f"posed planes of the first {sequences} sequences from {path}")
    with tqdm(desc="posed planes", unit="sequence", disable=None) as bar, body_pool(2) as pool:

        def progress(done: int, total: int) -> None:
            bar.total = total
            bar.update(done - bar.n)

        planes = posed_planes(canonical, body, fields, pool=pool, progress=progress, known=known)
    if path is not None:
        save_posed_planes(path, planes, canonical, PLANE_RADIUS)
        click.echo(f"wrote the posed planes {path}")
    return planes


def _stage_command(name: str, stages: tuple[str, ...], help_text: str) -> None:
    @train.command(name, help=help_text)
    @_train_options
    def command(data: Path, out: Path, device: str, resume: bool, config_path: Path | None,
                ablation: str | None, epochs: tuple[str, ...], seed: int | None,
                init_from: Path | None, planes_path: Path | None) -> None:  # fmt: skip
        _run(stages, data, out, device, resume, config_path, ablation, epochs, planes_path,
             seed, init_from)  # fmt: skip


_stage_command("pose", ("pose",), "Train the 10-d pose code (an autoencoder of the pose).")
_stage_command("vae", ("vae",), "Train the garment VAE with the collision losses.")
_stage_command("regressor", ("regressor",), "Train the GRU regressor (needs pose and vae).")
_stage_command("all", ("pose", "vae", "regressor"), "Train every stage, then write the model.")


@train.command("compare", short_help="Collisions per epoch of several VAE runs (Fig. 4).")
@click.argument("runs", nargs=-1, required=True, type=click.Path(file_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="PNG to write.")  # fmt: skip
def compare(runs: tuple[Path, ...], output: Path) -> None:
    """The paper's Fig. 4 from the VAE histories of RUNS (e.g. with and without the
    self-supervised term): collisions on held-out data per epoch."""
    with user_errors():
        from usd_garment.training.pipeline import load_stage
        from usd_garment.training.plots import plot_collisions

        histories = {}
        for run in runs:
            record = load_stage(run, "vae")[1]
            config = record["config"]
            label = ("full model" if config.get("collision") and config.get("self_supervised")
                     else "w/o self-supervised term" if config.get("collision")
                     else "w/o collision loss")  # fmt: skip
            histories[f"{label} ({run.name})"] = record["history"]["epochs"]
        plot_collisions(histories, output)
    click.echo(f"wrote {output}")


def _smoothing_option(name: str, what: str) -> Callable[[F], F]:
    """A ``train combine`` option: the standard deviation (s) of a Gaussian that smooths
    ``what``."""
    return click.option(
        name,
        type=click.FloatRange(min=0.0),
        default=0.0,
        show_default=True,
        metavar="SECONDS",
        help=f"Standard deviation of a Gaussian that smooths {what} (0: none).",
    )


def _weights_option(f: F) -> F:
    """A ``train combine`` / ``train member`` option: how the written model stores its
    weights."""
    return click.option(
        "--weights",
        type=click.Choice(STORAGES),
        default=STORAGES[0],
        show_default=True,
        help="How the learned weights are stored: float16, or int8 with a scale per row (about "
        "half the file again: room for more members in a shipped model's 12 MB).",
    )(f)


@train.command("combine", short_help="Average several trained models into one (an ensemble).")
@click.argument("models", nargs=-1, required=True, type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Model directory to write; created, and not one of MODELS.",
)
@click.option(
    "--version",
    "version",
    default=None,
    help="The combined model's version (default: the first model's, with '-ensemble').",
)
@_smoothing_option("--latent-smoothing", "the latent codes in time before decoding")
@_smoothing_option("--posed-smoothing", "the posed garment in time before any push-out")
@_weights_option
def combine(
    models: tuple[Path, ...],
    out: Path,
    version: str | None,
    latent_smoothing: float,
    posed_smoothing: float,
    weights: str,
) -> None:
    """One model whose garment is the mean of the canonical garments of MODELS (trained on the
    same garment and body, e.g. with other seeds): each model's networks run, their decodings
    are averaged and posed once. Each member keeps its own training command and figures; its
    training curves and log are copied beside the model (curves_member{i}.png,
    train_member{i}.log). With --latent-smoothing the codes are smoothed in time first (the
    shipped dress: 0.1 s, docs/learning.md); with --posed-smoothing the posed garment is, before
    it is pushed out of the body (the shipped T-shirt: 1/60 s; not the networks alone, where
    nothing would push it out)."""
    with user_errors():
        from usd_garment.methods.learned_model import (
            combine_models,
            copy_member_records,
            save_learned_model,
        )

        if any(out.resolve() == path.resolve() for path in models):
            raise click.BadParameter(f"{out} is one of the models combined", param_hint="--out")
        model = combine_models(list(models), version, latent_smoothing, posed_smoothing)
        model.info["command"] = "usd-garment " + shlex.join(
            ["train", "combine", *map(str, models), "--out", str(out), "--version", model.version,
             "--latent-smoothing", str(latent_smoothing), "--posed-smoothing", str(posed_smoothing),
             "--weights", weights]
        )  # fmt: skip
        save_learned_model(out, model, weights)
        records = copy_member_records(list(models), out)
    click.echo(f"wrote the model {out}: {len(model.members)} members, {records} curves and logs")


@train.command("member", short_help="Write one member of an ensemble as a model of its own.")
@click.argument("model", type=click.Path(file_okay=False, path_type=Path))
@click.option("--index", type=int, required=True, help="The member's number (0-based).")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Model directory to write; created, and not MODEL.",
)
@_weights_option
def member(model: Path, index: int, out: Path, weights: str) -> None:
    """Member INDEX of the ensemble MODEL as a one-member model, to dress or bench it alone
    (e.g. `bench --model m0=DIR`): its networks and training record, version
    '{version}-member{index}'; its training curves and log are copied as curves.png and
    train.log."""
    with user_errors():
        from usd_garment.methods.learned_model import (
            copy_member_record,
            load_learned_model,
            member_model,
            save_learned_model,
        )

        if out.resolve() == model.resolve():
            raise click.BadParameter(f"{out} is the model itself", param_hint="--out")
        one = member_model(load_learned_model(model), index)
        one.info["command"] = "usd-garment " + shlex.join(
            ["train", "member", str(model), "--index", str(index), "--out", str(out),
             "--weights", weights]
        )  # fmt: skip
        save_learned_model(out, one, weights)
        records = copy_member_record(model, index, out)
    click.echo(f"wrote the model {out}: member {index} of {model}, {records} curves and logs")


@train.command("pose-error", short_help="How well a trained pose code holds the poses of motions.")
@click.argument("model", type=click.Path(file_okay=False, path_type=Path))
@click.argument("sources", nargs=-1, required=True, type=click.Path(dir_okay=False, path_type=Path))
@corpus_options
def pose_error(
    model: Path,
    sources: tuple[Path, ...],
    fps: float,
    arm_clearance: float,
    collars: str,
    body_model: Path | None,
) -> None:
    """The pose code of MODEL (a run folder's pose stage, else each member of a model
    directory) on the poses of SOURCES (BVH captures, AMASS .npz, USD body layers, read as
    'motion poses' reads them): the mean geodesic angle between each joint's rotation (1..23)
    and its reconstruction, in degrees, per motion and over all their poses. The networks read
    the pose through this code, so a pose it holds badly is one they cannot tell apart
    (docs/learning.md, "Real captures against the pose code")."""
    with user_errors():
        from usd_garment.training.pipeline import trained_pose_codecs
        from usd_garment.training.pose import corpus_errors

        codecs = trained_pose_codecs(model)
        corpus = read_corpus(sources, fps, arm_clearance, collars, body_model)
        errors = np.array([corpus_errors(codec, corpus) for codec in codecs])  # (C, S)
    counts = np.asarray(corpus.counts)
    names = [f"{name} ({count} poses)" for name, count in zip(corpus.sources, counts, strict=True)]
    names.append(f"all ({counts.sum()} poses)")
    rows = np.concatenate([errors, errors @ counts[:, None] / counts.sum()], axis=1).T  # (S+1, C)
    width = max(map(len, names))
    members = " ".join(f"{f'code {i}':>8}" for i in range(len(codecs)))
    click.echo(f"{model}: mean error per joint (deg) of {len(codecs)} pose code(s), "
               f"{codecs[0].code_size}-d")  # fmt: skip
    click.echo(f"{'':<{width}} {members}")
    for name, row in zip(names, rows, strict=True):
        click.echo(f"{name:<{width}} " + " ".join(f"{value:8.2f}" for value in row))
