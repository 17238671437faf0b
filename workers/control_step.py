"""One step of the Panda's joint-impedance law, compiled with Numba.

Between two PyBullet calls each numpy call costs 2–4× what a warm micro-benchmark says
(stepSimulation evicts the interpreter's caches), so the step's arithmetic — the gain
product, the spring-wrench clip, gravity and the torque limits — is one compiled call
(benchmarks/HISTORY.md, Rollouts).

Numba caches the compiled step beside this file, keyed by the file's time stamp and size, and
the cache names the module it was compiled from (`bilba_dist.workers.control_step` since the
folder installs inside the library): editing this file is what invalidates a stale cache."""

import math

import numpy as np
from numba import njit


@njit(cache=True)
def joint_torque(
    G: np.ndarray,
    feed: np.ndarray,
    i: int,
    x: np.ndarray,
    Jt: np.ndarray,
    limit: float,
    g: np.ndarray,
    tau_max: np.ndarray,
    tau: np.ndarray,
    calm: float,
) -> bool:
    """Whether every joint speed is under ``calm`` (the settle test); and write into ``tau``
    the torque ``clip(Jᵀ w + k_n N e − B_q q̇ + g, ±tau_max)`` at ramp step ``i`` for
    ``x = [q; q̇]``, ``e = q_ref[i] − q``, ``w = K J e`` norm-clipped at ``limit``.

    ``tau`` is 34 long: the torque in ``tau[:7]``; ``tau[7:13]`` and ``tau[13:20]`` keep the
    running peaks of ``|w|`` per axis and of ``|Jᵀ w|`` per joint (the spring's wrench and
    its joint torques: in contact, what the robot's external-force estimate reads and its
    collision thresholds are compared with), ``tau[20:27]`` and ``tau[27:34]`` the lowest
    and highest angle of each joint (a joint at its limit: the real arm's reflex). The
    caller starts them at 0, 0, +inf and -inf before a rollout.

    ``G x + feed[i]`` gives ``[w; τ − g]`` unclipped in one 13×14 product
    (`JointImpedance`); past the limit the wrench is scaled by ``s = limit/|w|``, which
    takes ``(1 − s) Jᵀ w`` off the torque. Ten arguments, not more: Numba types each one
    on every call, and the loop calls this at every physics step."""
    if tau.shape[0] != 34:  # compiled code writes past a shorter array unchecked
        raise ValueError("joint_torque: tau must hold 34 values")
    w = np.empty(6)
    w2 = 0.0
    for r in range(13):
        acc = 0.0
        for c in range(14):
            acc += G[r, c] * x[c]
        acc += feed[i, r]
        if r < 6:
            w[r] = acc
            w2 += acc * acc
        else:
            tau[r - 6] = acc
    scale = 1.0
    if w2 > limit * limit:  # rare: only far from the setpoint
        scale = limit / math.sqrt(w2)
    for j in range(7):  # Jᵀ w: the clip's share of the torque, and the joint's load
        acc = 0.0
        for r in range(6):
            acc += Jt[j, r] * w[r]
        if scale < 1.0:
            tau[j] -= (1.0 - scale) * acc
        tau[13 + j] = max(tau[13 + j], abs(acc) * scale)
    for r in range(6):
        tau[7 + r] = max(tau[7 + r], abs(w[r]) * scale)
    for j in range(7):
        tau[20 + j] = min(tau[20 + j], x[j])
        tau[27 + j] = max(tau[27 + j], x[j])
    still = True
    for j in range(7):
        tau[j] = min(max(tau[j] + g[j], -tau_max[j]), tau_max[j])
        still = still and -calm < x[7 + j] < calm
    return still
