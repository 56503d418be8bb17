"""Jumps of the root alone taken out of a motion (``usd_garment/motion/jumps.py``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from usd_garment.body.model import BodyModel
from usd_garment.fields.body_fields import load_body_fields
from usd_garment.garment.model import GarmentModel
from usd_garment.motion.cuts import root_cuts
from usd_garment.motion.jumps import root_jumps, root_transforms, without_jumps
from usd_garment.motion.procedural import make_motion
from usd_garment.motion.sequence import SmplMotion


def _jumped(body: BodyModel) -> tuple[SmplMotion, SmplMotion]:
    """A walk, and the walk moved 0.5 m and turned 90° about the up axis from frame 20 on."""
    walk = make_motion("walk", 40, seed=2, body=body)
    turn = Rotation.from_rotvec([0.0, np.pi / 2, 0.0])
    pose, trans = walk.pose.copy(), walk.trans.copy()
    pose[20:, 0] = (turn * Rotation.from_rotvec(pose[20:, 0])).as_rotvec()
    trans[20:] = turn.apply(trans[20:]) + np.array([0.5, 0.0, 0.0])
    return walk, replace(walk, pose=pose, trans=trans)


def test_root_transforms_are_the_pelvis_skinning_transforms(body_model: BodyModel) -> None:
    """``root_transforms`` of a walk on a body shape are the pelvis's skinning transforms that
    posing uses (``GarmentModel.articulation``)."""
    walk = make_motion("walk", 12, seed=1, body=body_model)
    walk = replace(walk, betas=np.linspace(-1.0, 1.0, 10).astype(walk.betas.dtype))
    articulation = GarmentModel(body_model, load_body_fields()).articulation
    posed = articulation(
        torch.as_tensor(walk.betas).float(), torch.as_tensor(walk.pose).float(),
        torch.as_tensor(walk.trans).float(),
    ).transforms[:, 0]  # fmt: skip
    np.testing.assert_allclose(root_transforms(walk, body_model), posed.double(), atol=1e-5)


def test_root_jumps_are_the_cuts_that_are_no_restart(body_model: BodyModel) -> None:
    """``root_jumps`` of a walk moved 0.5 m and turned 90° from frame 20: one jump, whose map
    takes the root from frame 20 on back to within 1 mm of the walk's unmoved (0.18 mm: the
    walk's root does not take the same step twice, and the map takes the step midway between
    the steps beside the jump); ``without_jumps`` gives the walk back as closely; a restart at
    that frame, or no cut, leaves no jump."""
    walk, jumped = _jumped(body_model)
    assert root_cuts(jumped) == (20,)
    (jump,) = root_jumps(jumped, body_model, (20,), ())
    assert jump.frame == 20
    undo = np.reshape(jump.undo, (3, 4))
    back = undo[:, :3] @ root_transforms(jumped, body_model)[20:, :3]  # (20, 3, 4)
    back[..., 3] += undo[:, 3]
    assert np.abs(back - root_transforms(walk, body_model)[20:, :3]).max() < 1e-3
    seen = without_jumps(jumped, (jump,), body_model)
    assert np.array_equal(seen.trans[:20], walk.trans[:20])
    np.testing.assert_allclose(seen.trans, walk.trans, atol=1e-3)
    turned = Rotation.from_rotvec(seen.pose[:, 0]) * Rotation.from_rotvec(walk.pose[:, 0]).inv()
    assert float(turned.magnitude().max()) < 1e-3
    assert np.array_equal(seen.pose[:, 1:], walk.pose[:, 1:])
    assert root_jumps(jumped, body_model, (20,), (20,)) == ()
    assert root_jumps(jumped, body_model, (), ()) == ()
    assert without_jumps(jumped, (), body_model) is jumped
