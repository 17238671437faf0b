"""The Franka drivers a plan can be exported to, and what each does with a stiffness.

A plan's motion holds ``K`` at the ``panda_hand`` origin, in world (robot base) axes, rotation
first ``[rx, ry, rz, x, y, z]`` [N·m/rad, N/m], and the setpoint ``G_d`` of ``panda_hand``.
Every driver commands the end-effector frame ``EE`` instead (Desk's TCP: the Franka Hand's
default puts it 0.1034 m along the hand's z), translation first, and each accepts its own
form of stiffness (docs/drivers.md):

============  ===============================================  ==========================
driver        stiffness it takes                               damping
============  ===============================================  ==========================
franky        any symmetric PSD 6×6, base axes at EE            passed explicitly
panda-py      a 6×6, base axes at EE                            2ζ√K element-wise: right
                                                                only for a diagonal K
libfranka     6 diagonal values in a stiffness frame            critical, per axis
              (``set_K``), [10, 3000] N/m, [1, 300] N·m/rad
franka-ros    one translational (≤ 400 N/m) and one rotational  2√k
              (≤ 30 N·m/rad) scalar (the example controller)
============  ===============================================  ==========================

`fit` turns a plan's K into the nearest stiffness the driver accepts and says, in numbers,
what it changed; `to_ee`/`to_hand` carry K between the two frames by the adjoint of the
offset (the spring's energy is the same for the same displacement of the body).
"""

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import pinocchio as pin

from bilba_dist.robot.panda import JOINT_LIMITS
from bilba_dist.rollout import damping

DriverName = Literal["franky", "panda-py", "libfranka", "franka-ros"]
DRIVER_NAMES: tuple[DriverName, ...] = ("franky", "panda-py", "libfranka", "franka-ros")

#: Desk's default TCP for the Franka Hand: EE is this far along ``panda_hand``'s z [m].
DEFAULT_EE_OFFSET_M = 0.1034
#: ``panda_hand`` in the flange frame: turned -45° about z, same origin (the URDF's
#: ``panda_hand_joint``); the payload's centre of mass is given to drivers in the flange frame.
R_FLANGE_HAND = pin.utils.rotate("z", -np.pi / 4)

#: Rotation-first (plan) ↔ translation-first (drivers) for a 6-vector or, as P K P, a 6×6.
SWAP = np.block([[np.zeros((3, 3)), np.eye(3)], [np.eye(3), np.zeros((3, 3))]])


@dataclass(frozen=True)
class Driver:
    name: DriverName
    package: str  # what to pip install
    robot: str  # the robot generation its pip wheel's libfranka serves
    form: Literal["full", "diagonal-base", "diagonal-frame", "scalar"]
    translational: tuple[float, float]  # accepted range [N/m]
    rotational: tuple[float, float]  # [N·m/rad]
    damping: str
    wrench_clip: bool  # can the driver bound the spring's wrench as the planner did
    arms: tuple["ArmName", ...]  # the arms its usual build drives (joint limits to check)
    #: The exported script eases the setpoint ramp's speed in and out over this long [s]:
    #: a driver that sends the pose through libfranka's Cartesian pose generator, which does
    #: no rate limiting and stops the arm on a jump in velocity (plans/export.py)
    ramp_blend_s: float = 0.0


ArmName = Literal["Panda", "Franka Research 3"]

INF = float("inf")
#: A projection or clamp changing K by less than this (relative) is not reported: a plan
#: made for the driver, refitted on export, moves by ~1e-15.
NOTICE = 1e-6
DRIVERS: dict[str, Driver] = {
    "franky": Driver(
        "franky",
        "franky-control",
        "Franka Research 3 (libfranka 0.10+); build franky from source for a Panda",
        "full",
        (0.0, INF),
        (0.0, INF),
        "passed explicitly as 2·sqrtm(K)",
        True,
        ("Franka Research 3",),
    ),
    "panda-py": Driver(
        "panda-py",
        "panda-python",
        "Panda (the pip wheel bundles libfranka 0.9); builds for newer libfranka are on the "
        "project's GitHub releases",
        "diagonal-base",
        (0.0, INF),
        (0.0, INF),
        "computed by the driver (damping ratio 1, element-wise square root)",
        False,
        ("Panda",),
    ),
    "libfranka": Driver(
        "libfranka",
        "pylibfranka",
        "Franka Research 3 (libfranka 0.10+)",
        "diagonal-frame",
        (10.0, 3000.0),
        (1.0, 300.0),
        "computed by the robot (critical, per axis of the stiffness frame)",
        False,
        ("Franka Research 3",),
        ramp_blend_s=0.1,
    ),
    "franka-ros": Driver(
        "franka-ros",
        "franka_ros (ROS 1, from source or apt)",
        "Panda or FR3, by the libfranka franka_ros is built against",
        "scalar",
        (0.0, 400.0),
        (0.0, 30.0),
        "computed by the controller as 2·sqrt(k)",
        False,
        ("Panda", "Franka Research 3"),
    ),
}


def planning_arms(driver: str) -> tuple[str, ...]:
    """The arms whose joint limits a plan for ``driver`` (a task's ``planner.driver``) keeps
    to: every arm that driver drives (franka-ros: both), the Panda's when none is named."""
    return DRIVERS[driver].arms if driver in DRIVERS else ("Panda",)


def joint_limit_warnings(
    driver: Driver, start: np.ndarray | None, setpoints: list[np.ndarray]
) -> list[str]:
    """One warning per arm ``driver`` drives and joint whose limits the plan's start or its
    motions' joint setpoints pass: planned on the Panda's model, a plan can sit past an FR3's
    (joint 5: ±2.8065 rad against the Panda's ±2.8973)."""
    warnings = []
    for arm in driver.arms:
        low, high = JOINT_LIMITS[arm]
        for k in range(7):
            past = [q[k] for q in setpoints if not low[k] <= q[k] <= high[k]]
            at_start = start is not None and not low[k] <= start[k] <= high[k]
            if not past and not at_start:
                continue
            where = [f"the start ({start[k]:.4f} rad)"] if at_start and start is not None else []
            if past:
                worst = max(past, key=lambda v: max(low[k] - v, v - high[k]))
                where.append(
                    f"{len(past)} of {len(setpoints)} motions' joint setpoints (to {worst:.4f})"
                )
            warnings.append(
                f"on a {arm}, joint {k + 1} is past its limits [{low[k]:g}, {high[k]:g}] rad at "
                f"{' and '.join(where)}: the robot refuses the plan there; plan again with the "
                "start turned away from that limit (robot_start)"
            )
    return warnings


def ee_offset(R_WG: np.ndarray, offset_m: np.ndarray) -> np.ndarray:
    """The EE origin relative to the hand's, in world axes, for a hand rotation ``R_WG``."""
    return R_WG @ np.asarray(offset_m, dtype=float)


def _shift(r: np.ndarray) -> np.ndarray:
    """The rotation-first twist map from the hand origin to a point ``r`` away (world axes):
    ``[ω; v_r] = T [ω; v]`` with ``v_r = v + ω × r``."""
    T = np.eye(6)
    T[3:, :3] = -pin.skew(r)
    return T


def to_ee(K_hand: np.ndarray, r: np.ndarray) -> np.ndarray:
    """K at the hand origin (rotation first, world axes) → K at the point ``r`` away
    (translation first, world axes): ``T⁻ᵀ K T⁻¹``, then the axes swapped."""
    T_inv = np.linalg.inv(_shift(r))
    K = T_inv.T @ K_hand @ T_inv
    return SWAP @ ((K + K.T) / 2) @ SWAP


def to_hand(K_ee: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The inverse of `to_ee`."""
    T = _shift(r)
    K = T.T @ (SWAP @ K_ee @ SWAP) @ T
    return (K + K.T) / 2


@dataclass(frozen=True)
class Fit:
    """A driver's form of one K: ``K_ee`` (translation first, base axes at EE) as the driver
    will hold it, ``frame`` the stiffness frame's axes in base axes (libfranka's ``set_K``;
    identity otherwise), ``diagonal`` the 6 values in that frame, and a line per change."""

    K_ee: np.ndarray
    frame: np.ndarray
    diagonal: np.ndarray
    changes: list[str] = field(default_factory=list)

    def damping(self) -> np.ndarray:
        """``2·sqrtm(K_ee)``: what the planner simulated, and what each driver's own rule
        gives for the fitted form."""
        return damping(self.K_ee)


def fit(K_ee: np.ndarray, driver: Driver) -> Fit:
    """The stiffness ``driver`` accepts nearest to ``K_ee`` (translation first, base axes at
    the EE), every projection and clamp stated with its size."""
    K_ee = (np.asarray(K_ee, dtype=float) + np.asarray(K_ee, dtype=float).T) / 2
    changes: list[str] = []
    frame = np.eye(3)
    if driver.form == "full":
        return Fit(K_ee, frame, np.diag(K_ee).copy(), changes)
    if driver.form == "scalar":
        values = np.array([np.trace(K_ee[:3, :3]) / 3] * 3 + [np.trace(K_ee[3:, 3:]) / 3] * 3)
        target = np.diag(values)
    else:
        if driver.form == "diagonal-frame":
            frame = stiffness_frame(K_ee)
        block = np.kron(np.eye(2), frame)
        values = np.diag(block.T @ K_ee @ block).copy()
        target = block @ np.diag(values) @ block.T
    dropped = float(np.linalg.norm(K_ee - target)) / max(float(np.linalg.norm(K_ee)), 1e-12)
    if dropped > NOTICE:
        what = {"scalar": "made isotropic", "diagonal-base": "off-diagonal terms dropped"}
        changes.append(
            f"{what.get(driver.form, 'coupling dropped outside the stiffness frame')}: "
            f"{100 * dropped:.2g} % of |K|"
        )
    clamped = values.copy()
    clamped[:3] = np.clip(values[:3], *driver.translational)
    clamped[3:] = np.clip(values[3:], *driver.rotational)
    axes = ("x", "y", "z", "rx", "ry", "rz")
    step = 3 if driver.form == "scalar" else 1
    for i in range(0, 6, step):
        if abs(clamped[i] - values[i]) > NOTICE * max(1.0, abs(values[i])):
            unit = "N/m" if i < 3 else "N·m/rad"
            name = ("translational", "rotational")[i // 3] if step == 3 else axes[i]
            changes.append(f"{name} {values[i]:.1f} → {clamped[i]:.1f} {unit} (the driver's limit)")
    block = np.kron(np.eye(2), frame)
    return Fit(block @ np.diag(clamped) @ block.T, frame, clamped, changes)


def stiffness_frame(K_ee: np.ndarray) -> np.ndarray:
    """A right-handed frame (columns in base axes) diagonalising the translational block;
    where its eigenvalues repeat (an isotropic or axisymmetric spring), the frame within
    that eigenspace diagonalises the rotational block, so a K already of the form is kept."""
    w, V = np.linalg.eigh(K_ee[:3, :3])
    tol = 1e-9 * max(1.0, float(np.abs(w).max()))
    i = 0
    while i < 3:
        j = i + 1
        while j < 3 and w[j] - w[i] <= tol:
            j += 1
        if j - i > 1:
            S = V[:, i:j]
            _, U = np.linalg.eigh(S.T @ K_ee[3:, 3:] @ S)
            V[:, i:j] = S @ U
        i = j
    return V * np.sign(np.linalg.det(V))


def fit_hand(
    K_hand: np.ndarray, R_WG: np.ndarray, driver: Driver, offset_m: np.ndarray
) -> tuple[np.ndarray, Fit]:
    """A plan's K made into what ``driver`` holds, returned in the plan's own frame (hand
    origin, world axes, rotation first) with the driver-side `Fit`."""
    r = ee_offset(R_WG, offset_m)
    fitted = fit(to_ee(K_hand, r), driver)
    return to_hand(fitted.K_ee, r), fitted


def hand_to_ee(G_d: pin.SE3, offset_m: np.ndarray) -> pin.SE3:
    """The EE pose for a hand pose."""
    return G_d * pin.SE3(np.eye(3), np.asarray(offset_m, dtype=float))


def ee_to_hand(X_WE: pin.SE3, offset_m: np.ndarray) -> pin.SE3:
    return X_WE * pin.SE3(np.eye(3), np.asarray(offset_m, dtype=float)).inverse()
