"""One step of the Panda's joint-impedance law, compiled with Numba.

Between two PyBullet calls each numpy call costs 2–4× what a warm micro-benchmark says
(stepSimulation evicts the interpreter's caches), so the step's arithmetic — the gain
product, the spring-wrench clip, gravity and the torque limits — is one compiled call
(README, Benchmarks: rollouts)."""

import math

import numpy as np
from numba import njit


@njit(cache=True)
def joint_torque(
    G: np.ndarray,
    feed: np.ndarray,
    ramp: np.ndarray,
    i: int,
    x: np.ndarray,
    KJ: np.ndarray,
    Jt: np.ndarray,
    K_null: np.ndarray,
    B_q: np.ndarray,
    limit: float,
    g: np.ndarray,
    tau_max: np.ndarray,
    tau: np.ndarray,
    calm: float,
) -> bool:
    """Whether every joint speed is under ``calm`` (the settle test); and write into ``tau``
    the torque ``clip(Jᵀ w + k_n N e − B_q q̇ + g, ±tau_max)`` at ramp
    step ``i`` for ``x = [q; q̇]``, ``e = ramp[i] − q``, ``w = K J e`` (norm-clipped at
    ``limit``). Unclipped, ``G x + feed[i]`` gives ``[w; τ − g]`` in one 13×14 product
    (`JointImpedance`); past the limit the wrench is scaled before mapping back."""
    w2 = 0.0
    for r in range(13):
        acc = 0.0
        for c in range(14):
            acc += G[r, c] * x[c]
        acc += feed[i, r]
        if r < 6:
            w2 += acc * acc
        else:
            tau[r - 6] = acc
    if w2 > limit * limit:  # rare: only far from the setpoint
        e = ramp[i] - x[:7]
        w = KJ @ e
        w *= limit / math.sqrt(w @ w)
        tau[:] = Jt @ w + K_null @ e - B_q @ x[7:]
    still = True
    for j in range(7):
        tau[j] = min(max(tau[j] + g[j], -tau_max[j]), tau_max[j])
        still = still and -calm < x[7 + j] < calm
    return still
