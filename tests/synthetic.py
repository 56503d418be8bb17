"""A tiny synthetic body in the SMPL file layout, for tests that must not depend on a real file.

Each joint gets a small cluster of vertices around its T-pose location; the clusters are skinned
rigidly to their joint and the joint regressor is each cluster's mean, so joints are exact.
"""

from __future__ import annotations

import numpy as np

from usd_garment.body.joints import NUM_JOINTS, SMPL_PARENTS

#: Approximate SMPL T-pose joint locations (m, Y-up, facing +Z, body's left at +X).
TPOSE_JOINTS = np.array(
    [
        [0.0, -0.23, 0.0], [0.06, -0.32, 0.0], [-0.06, -0.32, 0.0], [0.0, -0.12, 0.0],
        [0.1, -0.7, 0.0], [-0.1, -0.7, 0.0], [0.0, 0.02, 0.0], [0.09, -1.1, -0.04],
        [-0.09, -1.1, -0.04], [0.0, 0.08, 0.0], [0.11, -1.16, 0.08], [-0.11, -1.16, 0.08],
        [0.0, 0.28, 0.0], [0.08, 0.2, 0.0], [-0.08, 0.2, 0.0], [0.0, 0.35, 0.04],
        [0.18, 0.22, 0.0], [-0.18, 0.22, 0.0], [0.44, 0.22, 0.0], [-0.44, 0.22, 0.0],
        [0.7, 0.22, 0.0], [-0.7, 0.22, 0.0], [0.78, 0.22, 0.0], [-0.78, 0.22, 0.0],
    ],
    dtype=np.float64,
)  # fmt: skip


def synthetic_smpl_arrays(per_joint: int = 8, seed: int = 0) -> dict[str, np.ndarray]:
    """Arrays of an SMPL-layout file: v_template ``(V, 3)``, shapedirs ``(V, 3, 10)``, posedirs
    ``(V, 3, 207)``, J_regressor ``(24, V)``, weights ``(V, 24)``, kintree_table ``(2, 24)``,
    f ``(F, 3)``, with V = 24 · per_joint."""
    rng = np.random.default_rng(seed)
    v = NUM_JOINTS * per_joint
    owner = np.repeat(np.arange(NUM_JOINTS), per_joint)
    v_template = TPOSE_JOINTS[owner] + rng.normal(scale=0.02, size=(v, 3))
    v_template -= v_template.reshape(NUM_JOINTS, per_joint, 3).mean(1)[owner] - TPOSE_JOINTS[owner]
    weights = np.zeros((v, NUM_JOINTS))
    weights[np.arange(v), owner] = 1.0
    j_regressor = weights.T / per_joint
    shapedirs = np.zeros((v, 3, 10))
    shapedirs[:, 1, 0] = 0.05 * v_template[:, 1]  # beta_1 scales height
    shapedirs[:, :, 1:] = rng.normal(scale=1e-3, size=(v, 3, 9))
    posedirs = rng.normal(scale=1e-3, size=(v, 3, 207))
    local = np.arange(per_joint - 2)
    faces = np.concatenate(
        [np.stack([j * per_joint + 0 * local, j * per_joint + local + 1,
                   j * per_joint + local + 2], 1) for j in range(NUM_JOINTS)]
    )  # fmt: skip
    kintree = np.stack([np.array(SMPL_PARENTS), np.arange(NUM_JOINTS)])
    return {
        "v_template": v_template,
        "shapedirs": shapedirs,
        "posedirs": posedirs,
        "J_regressor": j_regressor,
        "weights": weights,
        "kintree_table": kintree,
        "f": faces,
    }
