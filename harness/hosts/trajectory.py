"""What every host of the host matrix yields, scored the same way for every host.

ITAE and IAE from the true error ym - y of the plant's and the reference's outputs, Ec and TV(u)
from the u the plant was given (harness/scores.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scores import control_energy, iae, itae, total_variation_rate


@dataclass
class Trajectory:
    """What every host yields: the plant's and reference's outputs and the u applied, on one grid."""

    time: np.ndarray
    y: np.ndarray
    dy: np.ndarray
    ym: np.ndarray
    dym: np.ndarray
    u: np.ndarray  # applied over [t_k, t_k + h]

    def scores(self) -> dict:
        e, de = self.ym - self.y, self.dym - self.dy
        return {"ITAE": itae(self.time, e, de), "IAE": iae(self.time, e, de), "Ec": control_energy(self.time, self.u),
                "tv_u": total_variation_rate(self.time, self.u)}
