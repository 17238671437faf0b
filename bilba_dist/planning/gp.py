"""Gaussian-process guidance for setpoint search (paper Algorithm 3, GPR).

Features are the SE(3) log of the gripper setpoint (Pinocchio); scores are normalised; the
kernel is ``C·RBF`` with hyperparameters by maximum marginal likelihood (scikit-learn)."""

import warnings
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel


@dataclass(frozen=True)
class GPParams:
    test_points: int = 1000
    noise: float = 0.02  # ± uniform, per log-space coordinate
    simulated: int = 31  # best predicted test points simulated per round
    rounds: int = 3
    patience: int = 1  # rounds in a row without a better score before the GP gives up
    restarts: int = 9
    max_train: int = 128  # fit on the best-scored this many: a fit is O(n³) per optimiser
    # step, and 300+ points made GP fitting 10 % of a peg plan (profiled)


def features(setpoints: list[pin.SE3]) -> np.ndarray:
    return np.array([pin.log6(X).vector for X in setpoints])


def propose(
    train: np.ndarray, scores: np.ndarray, params: GPParams, rng: np.random.Generator
) -> tuple[list[pin.SE3], np.ndarray]:
    """The ``simulated`` test setpoints with the best predicted score, and the predictions.
    Test points are training points plus uniform noise in the log space."""
    if len(train) > params.max_train:
        keep = np.sort(np.argsort(-scores, kind="stable")[: params.max_train])
        train, scores = train[keep], scores[keep]
    base = train[rng.integers(len(train), size=params.test_points)]
    test = base + rng.uniform(-params.noise, params.noise, size=base.shape)
    spread = scores.std()
    if spread < 1e-12:  # nothing to learn from: fall back to random test points
        predicted = rng.uniform(size=len(test))
    else:
        model = GaussianProcessRegressor(
            kernel=ConstantKernel(1.0) * RBF(1.0, (1e-5, 1e2)),
            n_restarts_optimizer=params.restarts,
            normalize_y=True,
            random_state=int(rng.integers(2**31)),
        )
        with warnings.catch_warnings():  # lbfgs often stops early on few points: harmless
            warnings.simplefilter("ignore", ConvergenceWarning)
            model.fit(train, scores)
        predicted = model.predict(test)
    best = np.argsort(-predicted, kind="stable")[: params.simulated]
    return [pin.exp6(test[i]) for i in best], predicted[best]
