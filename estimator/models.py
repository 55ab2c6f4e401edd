"""What the estimator assumes about its inputs, apart from the force model: the attitude error of
the autopilot's AHRS, and a force model perturbed within the paper's confidence intervals.

Both are seeded and plain (no simulator): the in-process runs use them to make their inputs look
like a real autopilot's. Units SI, angles in degrees where named.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from vehicle.frames import quat_mul
from vehicle.params import VehicleParams


@dataclass(frozen=True)
class AhrsErrorModel:
    """Attitude measurement error: rotation vector (body axes) as a Gauss-Markov process."""

    sigma_deg: float = 0.5
    tau_s: float = 20.0

    def coefficients(self, dt_s: float) -> tuple[float, float]:
        """(a, c) of the first-order Gauss-Markov step over ``dt_s`` seconds: e <- a e + c n, n ~ N(0, 1)
        per axis; a = exp(-dt / tau), c = sqrt(1 - a^2) sigma (rad), so the stationary 1-sigma is sigma."""
        a = math.exp(-dt_s / self.tau_s)
        return a, math.sqrt(1.0 - a * a) * math.radians(self.sigma_deg)


@intrinsic
def _fma_intrinsic(typingctx: Any, a: Any, b: Any, c: Any) -> tuple[Any, Any]:
    """a * b + c rounded once (LLVM's fma; numba's intrinsic protocol: the signature and its code)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        d = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [d], ir.FunctionType(d, [d, d, d]))
        return builder.call(fn, args)

    return sig, codegen


#: a * b + c rounded once, callable from the kernels here.
_fma = cast(Callable[[float, float, float], float], _fma_intrinsic)


@njit(cache=True)
def _norm4(q: np.ndarray) -> float:
    """Euclidean norm of a 4-vector, its squares summed in order with fused multiply-adds: the rounding of
    ``np.linalg.norm`` (OpenBLAS's ddot) on the machines measured, so the attitudes stay what they were."""
    s = 0.0
    for i in range(4):
        s = _fma(q[i], q[i], s)
    return math.sqrt(s)


@njit(cache=True)
def ahrs_attitudes(q_true: np.ndarray, err: np.ndarray, normals: np.ndarray, a: float, c: float,
                   out: np.ndarray) -> None:  # fmt: skip
    """The AHRS's attitude for each of k samples: the true attitude ``q_true`` (k, 4; [w, x, y, z],
    body FRD -> NED) times the error rotation of the Gauss-Markov rotation vector ``err`` (3, body
    axes, rad; advanced in place by one step per sample: err <- a err + c normals[i], see
    :meth:`AhrsErrorModel.coefficients`), as a small-angle unit quaternion [1, e / 2] normalized;
    ``out`` (k, 4) the unit results."""
    dq = np.empty(4)
    for k in range(q_true.shape[0]):
        for i in range(3):
            err[i] = a * err[i] + c * normals[k, i]
        dq[0] = 1.0
        for i in range(3):
            dq[1 + i] = 0.5 * err[i]
        nd = _norm4(dq)
        for i in range(4):
            dq[i] = dq[i] / nd
        q = quat_mul(q_true[k], dq)
        nq = _norm4(q)
        for i in range(4):
            out[k, i] = q[i] / nq


def model_params(vehicle: VehicleParams, seed: int, perturb: bool) -> VehicleParams:
    """The parameters the estimator uses: exact, or drawn inside the Table 5 95 % intervals
    plus mass (+-5 %) and inertia (+-10 %) errors, seeded by ``seed``."""
    if not perturb:
        return vehicle
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x57D]))
    return vehicle.perturbed(rng)
