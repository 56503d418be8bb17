"""The SMPL motion that flows between USD, AMASS and the garment methods."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class SmplMotion:
    """An SMPL body animation in our canonical frame: Y-up, metres, seconds.

    Attributes:
        betas: ``(10,)`` shape coefficients.
        pose: ``(T, 24, 3)`` local axis-angle rotations (rad), SMPL joint order.
        trans: ``(T, 3)`` root translation (m), as SMPL's ``trans`` (added after skinning).
        fps: frames per second of the samples.
        start_time: USD time code of the first frame (kept for writing layers back).
        time_codes: ``(T,)`` USD time codes of the frames.
        gender: ``"neutral"``, ``"male"`` or ``"female"``.
        model: the body model name the betas belong to.
        cut_times: time codes where the animation is declared to start anew (an edit's splice;
            ``smpl:cuts`` of the layer, ``dress --cut``): nothing is smoothed or differentiated
            across them. Cuts where the root or the joints jump are also found from the motion
            itself (:func:`~usd_garment.motion.cuts.motion_cuts`).
    """

    betas: np.ndarray
    pose: np.ndarray
    trans: np.ndarray
    fps: float
    time_codes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gender: str = "neutral"
    model: str = "default"
    cut_times: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        t = self.pose.shape[0]
        if self.pose.shape != (t, 24, 3) or self.trans.shape != (t, 3):
            raise ValueError(
                f"pose must be (T, 24, 3) and trans (T, 3), got "
                f"{self.pose.shape} and {self.trans.shape}"
            )
        if self.betas.shape != (10,):
            raise ValueError(f"betas must be (10,), got {self.betas.shape}")
        if self.time_codes.shape[0] != t:
            self.time_codes = np.arange(t, dtype=np.float64)

    @property
    def num_frames(self) -> int:
        return int(self.pose.shape[0])
