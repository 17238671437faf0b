"""The simulated collision shapes are the task's pieces: for every face of every piece, a
probe point pushed out of the face's centre along its normal is as far from the simulated
body as from the piece itself — on the Panda model, on the floating model, and for the
environment's bodies. (A convex manipuland once loaded as an empty mesh, and passed through
the hole; convex meshes on a URDF link carry PyBullet's 1 mm collision margin.)"""

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest
import yaml

from bilba_dist.geometry.piece import ConvexPiece, Part
from bilba_dist.task.loader import Task, load_task
from bilba_dist.task.prismatic import peg_in_hole_task, rectangle, regular_polygon
from bilba_dist.workers.floating_sim import FloatingSim
from bilba_dist.workers.panda_sim import PandaSim
from bilba_dist.workers.settings import SimSettings

#: How far the probe points sit outside each face [m], and the agreement asked for [m].
PROBE_OUT_M = (0.002, 0.0003)
TOL_M = 5e-5
PROBE_RADIUS_M = 1e-4

GENERATED = {
    "octagon": ([regular_polygon(8, 0.06)], 0.003, 0.006),
    "triangle": ([regular_polygon(3, 0.05)], 0.002, 0.0),
    "hexagon": ([regular_polygon(6, 0.05, turn=0.3)], 0.004, 0.01),
    "L": (
        [rectangle(0.06, 0.03, (0, -0.015)), rectangle(0.03, 0.03, (-0.015, 0.015))],
        0.004,
        0.005,
    ),
}


def generated_task(tmp_path_factory, name: str) -> Task:
    peg, clearance, chamfer = GENERATED[name]
    path = tmp_path_factory.mktemp("tasks") / f"{name}.yaml"
    path.write_text(yaml.safe_dump(peg_in_hole_task(name, peg, clearance, chamfer)))
    return load_task(str(path))


@pytest.fixture(scope="module", params=["peg-in-hole", "puzzle", *GENERATED])
def task(request, tmp_path_factory) -> Task:
    if request.param in GENERATED:
        return generated_task(tmp_path_factory, request.param)
    return load_task(request.param)


def face_probes(piece: ConvexPiece, others: list[ConvexPiece], out: float):
    """(point in the part frame, exact distance) per face of ``piece`` whose probe is
    clearly nearer ``piece`` than any other piece of the part."""
    for face in piece.faces:
        centre = piece.vertices[list(face.vertices)].mean(axis=0)
        point = centre + out * face.normal
        near_other = any(
            max(f.normal @ point - f.offset for f in other.faces) < out + 1e-3 for other in others
        )
        if not near_other:
            yield point, out


def measured(client: int, probe: int, body: int, link: int, point: np.ndarray) -> float:
    p.resetBasePositionAndOrientation(probe, point.tolist(), [0, 0, 0, 1], physicsClientId=client)
    found = p.getClosestPoints(probe, body, 0.05, linkIndexB=link, physicsClientId=client)
    assert found, f"nothing of body {body} link {link} within 5 cm of {point}"
    return min(c[8] for c in found) + PROBE_RADIUS_M


def probe_body(client: int) -> int:
    shape = p.createCollisionShape(p.GEOM_SPHERE, radius=PROBE_RADIUS_M, physicsClientId=client)
    body = p.createMultiBody(0, shape, -1, basePosition=[9, 9, 9], physicsClientId=client)
    p.changeDynamics(body, -1, collisionMargin=0.0, physicsClientId=client)
    return body


def check_part(client: int, part: Part, located) -> list[str]:
    """Compare every probe of ``part``; ``located(i)`` gives (body, link, X_W_part) for
    piece i. Returns the disagreements."""
    probe, wrong = probe_body(client), []
    for i, piece in enumerate(part.pieces):
        body, link, X = located(i)
        others = [q for q in part.pieces if q is not piece]
        for out in PROBE_OUT_M:
            for point, exact in face_probes(piece, others, out):
                got = measured(client, probe, body, link, X.act(point))
                if abs(got - exact) > TOL_M:
                    wrong.append(f"{piece.name}: {got * 1000:.3f} mm, exact {exact * 1000:.3f}")
    p.removeBody(probe, physicsClientId=client)
    return wrong


def environment_check(sim, task: Task) -> list[str]:
    X_WO = task.X_WO
    sim.env.place(X_WO)
    return check_part(sim.client, task.environment, lambda i: (sim.env.bodies[i], -1, X_WO))


def manipuland_check(sim: PandaSim, task: Task) -> list[str]:
    """``check_part`` on the Panda model's part link, where the arm holds it now."""
    state = p.getLinkState(sim.robot, sim.part_link, physicsClientId=sim.client)
    X_WP = pin.XYZQUATToSE3(np.array([*state[4], *state[5]]))
    return check_part(sim.client, task.manipuland, lambda i: (sim.robot, sim.part_link, X_WP))


def test_panda_model_shapes_are_the_pieces(task):
    sim = PandaSim(task, task.X_GM, SimSettings())
    try:
        assert manipuland_check(sim, task) == []
        assert environment_check(sim, task) == []
    finally:
        sim.close()


def test_floating_model_shapes_are_the_pieces(task):
    sim = FloatingSim(task, SimSettings())
    try:
        X_WM = pin.SE3(pin.rpy.rpyToMatrix(0.3, -0.2, 1.0), np.array([0.2, 0.5, 0.9]))
        sim.reset(pin.SE3.Identity(), X_WM, np.zeros(6))
        assert check_part(sim.client, task.manipuland, lambda i: (sim.body, -1, X_WM)) == []
        assert environment_check(sim, task) == []
    finally:
        sim.close()


def test_a_part_named_anything_loads_with_its_shapes(tmp_path):
    """The part's name is free text: one with XML's special characters, a slash and a
    non-ASCII letter once broke the URDF the Panda model loads (it named the mesh files)."""
    data = peg_in_hole_task("names", [regular_polygon(3, 0.05)], 0.002, 0.0)
    data["manipuland"]["name"] = 'peg & "<co>" / ü'
    path = tmp_path / "names.yaml"
    path.write_text(yaml.safe_dump(data, allow_unicode=True), encoding="utf-8")
    task = load_task(str(path))
    sim = PandaSim(task, task.X_GM, SimSettings())
    try:
        assert manipuland_check(sim, task) == []
    finally:
        sim.close()
