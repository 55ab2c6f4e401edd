"""What the estimator assumes about its inputs, apart from the force model: the attitude error of
the autopilot's AHRS, and a force model perturbed within the paper's confidence intervals.

Both are seeded and plain (no simulator): the in-process runs use them to make their inputs look
like a real autopilot's. Units SI, angles in degrees where named.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vehicle.params import VehicleParams


@dataclass(frozen=True)
class AhrsErrorModel:
    """Attitude measurement error: rotation vector (body axes) as a Gauss-Markov process."""

    sigma_deg: float = 0.5
    tau_s: float = 20.0



def model_params(vehicle: VehicleParams, seed: int, perturb: bool) -> VehicleParams:
    """The parameters the estimator uses: exact, or drawn inside the Table 5 95 % intervals
    plus mass (+-5 %) and inertia (+-10 %) errors, seeded by ``seed``."""
    if not perturb:
        return vehicle
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x57D]))
    return vehicle.perturbed(rng)
