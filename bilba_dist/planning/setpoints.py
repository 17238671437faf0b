"""Gripper setpoints for a contact: manipuland poses on (and just inside) the C-obs surface of
the contact, per particle, turned into ``G_d = X_WO · X_OM · X_GM⁻¹`` with that particle's
grasp and environment pose (paper §4.2, "Gripper Targets for Individual Particles")."""

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from bilba_dist.belief.particles import Particle, make_particle
from bilba_dist.cspace.slice import INSIDE
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.modes.schedule import SliceCache


@dataclass(frozen=True)
class SetpointParams:
    on_surface: int = 32  # per particle
    noisy: int = 32  # per particle: moved by uniform noise, kept only if inside C-obs
    noise_m: float = 0.01  # ± per axis [m]
    press_m: float = 0.003  # surface samples are pushed inside by up to this [m]: a setpoint
    # exactly on the surface makes the contact with zero force, which the sim may or may not see
    patience: int = 0  # stop scoring samples after this many in a row without a better score


def start_rotation(particle: Particle, X_WG0: pin.SE3) -> np.ndarray:
    """``R_OM`` of the particle's part at the start (gripper at ``X_WG0``): the slice the
    setpoints fall back to where the current rotation holds no point of a mode."""
    return (particle.X_WO.inverse() * X_WG0 * particle.X_GM).rotation


def sample_setpoints(
    particle: Particle,
    X_WM: pin.SE3,
    mode: ContactPair,
    cache: SliceCache,
    params: SetpointParams,
    rng: np.random.Generator,
) -> list[pin.SE3]:
    """Gripper setpoints that would put this particle's manipuland in ``mode``, at its
    current rotation: ``on_surface`` on the mode's region, then ``noisy`` ones pushed by
    noise (those that land outside C-obs keep their surface point).

    Where the slice at the current rotation has no point of the mode, the samples are taken
    at the particle's start rotation instead (the setpoints then command that rotation), and
    where that has none either, at the nominal part's start rotation (the setpoints then turn
    the gripper so that this particle's part is as the nominal one). A part resting tilted
    by 1e-4 rad can lose a mode that needs its faces parallel to the environment's (the
    puzzle's lower block against a slot wall, 0.25 mm clearance); one held 2° pitched in the
    gripper loses the goal slot at its start rotation too: with no samples for that
    particle, MakeContact would only sample for the others."""
    total = params.on_surface + params.noisy
    X_OM = particle.X_WO.inverse() * X_WM
    rotation = X_OM.rotation
    cslice = cache.get(rotation)
    points = cslice.sample_mode(mode, total, rng, depth=(0.0, params.press_m))
    for fallback in (particle, make_particle(cache.task, {})):
        if len(points) > 0:
            break
        rotation = start_rotation(fallback, cache.task.X_WG0)
        cslice = cache.get(rotation)
        points = cslice.sample_mode(mode, total, rng, depth=(0.0, params.press_m))
    if len(points) == 0:
        return []
    points = points[rng.integers(len(points), size=total)] if len(points) < total else points
    noisy = points[params.on_surface :]
    moved = noisy + rng.uniform(-params.noise_m, params.noise_m, size=noisy.shape)
    inside = cslice.classify(moved) == INSIDE
    noisy[inside] = moved[inside]
    X_MG = particle.X_GM.inverse()
    return [particle.X_WO * pin.SE3(rotation, p) * X_MG for p in points]
