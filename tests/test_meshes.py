"""Mesh pieces: a closed convex mesh file is one convex piece; every bad mesh is one line
naming the file, exit code 2."""

import copy
import re
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from bilba_dist.planning.bilba import plan
from bilba_dist.task.loader import builtin_tasks, load_task
from bilba_dist.task.prismatic import prism, regular_polygon
from bilba_dist.workers.rollout_worker import RolloutWorker
from tests.test_task_files import run_cli


@pytest.fixture
def hex_yaml() -> dict:
    return yaml.safe_load(builtin_tasks()["hex-peg"].read_text())


def write_mesh_task(tmp_path, data: dict, mesh: trimesh.Trimesh | bytes | None, **spec) -> str:
    """The hex-peg task with its peg read from ``mesh`` written beside the task file."""
    data = copy.deepcopy(data)
    name = spec.pop("file", "part.stl")
    if isinstance(mesh, bytes):
        (tmp_path / name).write_bytes(mesh)
    elif mesh is not None:
        mesh.export(tmp_path / name)
    data["manipuland"]["pieces"][0]["mesh"] = {
        "file": name,
        "scale": 0.001,
        "faces": {"bottom": [0, 0, -1]},
        **spec,
    }
    path = tmp_path / "task.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return str(path)


def hexagonal_peg_mm() -> trimesh.Trimesh:
    return trimesh.convex.convex_hull(np.array(prism(regular_polygon(6, 55.0), -75.0, 75.0)))


def test_the_builtin_mesh_task_is_its_stl_as_one_convex_piece():
    task = load_task("hex-peg")
    (piece,) = task.manipuland.pieces
    assert task.spec.manipuland.pieces[0].mesh is None  # resolved into vertices on load
    assert len(piece.vertices) == 12 and len(piece.faces) == 8
    across_flats = piece.vertices[:, 0].max() - piece.vertices[:, 0].min()
    assert across_flats == pytest.approx(0.055, abs=1e-7)  # corners at ±30°: flats at ±y
    bottom = task.manipuland.face("peg/bottom")
    assert bottom.normal == pytest.approx([0, 0, -1]) and bottom.offset == pytest.approx(0.075)


def test_a_mesh_in_another_unit_and_folder_is_the_same_piece(hex_yaml, tmp_path):
    metres = hexagonal_peg_mm().apply_scale(0.001)
    sub = tmp_path / "meshes"
    sub.mkdir()
    metres.export(sub / "peg.obj")
    task = load_task(write_mesh_task(tmp_path, hex_yaml, None, file="meshes/peg.obj", scale=1.0))
    builtin = load_task("hex-peg").manipuland.pieces[0].vertices
    assert np.sort(task.manipuland.pieces[0].vertices, axis=0) == pytest.approx(
        np.sort(builtin, axis=0), abs=1e-7
    )


def far_peg_obj() -> bytes:
    """The hexagonal peg as OBJ text with coordinates near the float limit (written by hand:
    trimesh's own scaling would overflow in the test)."""
    mesh = hexagonal_peg_mm()
    vertices = [
        f"v {x * 1e300:.17g} {y * 1e300:.17g} {z * 1e300:.17g}" for x, y, z in mesh.vertices
    ]
    faces = [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.faces]
    return "\n".join([*vertices, *faces, ""]).encode()


def open_box() -> trimesh.Trimesh:
    box = trimesh.creation.box((60.0, 60.0, 150.0))
    return trimesh.Trimesh(box.vertices, box.faces[:-2])  # one side left open


BAD = {
    "missing": (None, {"file": "nowhere.stl"}, "cannot read it"),
    "corrupt": (
        b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 1 2\n",
        {},
        "cannot load it|no triangles",
    ),
    "empty": (b"", {}, "cannot load it|holds no triangles"),
    "open surface": (open_box(), {}, "not a closed"),
    "flat": (
        trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [1, 3, 2]]),
        {},
        "not a closed|no volume",
    ),
    "millimetres read as metres": (hexagonal_peg_mm(), {"scale": 1.0}, "reach 75 m .*scale right"),
    "coordinates near the float limit": (
        far_peg_obj(),
        {"file": "part.obj"},
        "reach 7.5e\\+298 m .*beyond the ±2 m",
    ),
    "scale near the float limit": (hexagonal_peg_mm(), {"scale": 1e308}, "reach far from"),
    "non-convex": (
        trimesh.creation.annulus(r_min=10.0, r_max=30.0, height=100.0),
        {},
        "not convex .*coacd",
    ),
}


@pytest.mark.parametrize("case", BAD)
def test_a_bad_mesh_is_one_line_naming_the_file(case, hex_yaml, tmp_path):
    mesh, spec, message = BAD[case]
    path = write_mesh_task(tmp_path, hex_yaml, mesh, **spec)
    result = run_cli("graph", path)
    assert result.exit_code == 2, result.output
    (line,) = result.stderr.splitlines()
    assert "task.yaml:" in line and "manipuland.pieces[0]: mesh " in line
    assert str(tmp_path) in line
    assert re.search(message, line), line


@pytest.mark.parametrize("scale", [0, -0.001, ".nan", ".inf", "'a lot'"])
def test_a_scale_that_is_not_a_positive_number_is_refused(scale, hex_yaml, tmp_path):
    path = write_mesh_task(tmp_path, hex_yaml, hexagonal_peg_mm())
    file = Path(path)
    file.write_text(file.read_text().replace("scale: 0.001", f"scale: {scale}"))
    result = run_cli("graph", path)
    assert result.exit_code == 2 and len(result.stderr.splitlines()) == 1, result.output
    assert "manipuland.pieces[0].mesh.scale" in result.stderr


def test_a_piece_with_two_shapes_is_refused(hex_yaml, tmp_path):
    data = copy.deepcopy(hex_yaml)
    data["manipuland"]["pieces"][0]["box"] = {"size": [0.06, 0.06, 0.15]}
    path = tmp_path / "task.yaml"
    path.write_text(yaml.safe_dump(data))
    result = run_cli("graph", str(path))
    assert result.exit_code == 2
    assert "needs exactly one of 'box', 'convex', 'mesh'" in result.stderr


@pytest.mark.slow
def test_the_mesh_task_plans_end_to_end_from_its_stl():
    task = load_task("hex-peg")
    result = plan(task, RolloutWorker(task), "bilba-variable", seed=0, timeout_s=120)
    assert result.success, result.reason
    final = result.final_belief
    assert final is not None and all(task.goal in c for c in final.contacts)


def obj_file(path: Path, objects: dict[str, trimesh.Trimesh]) -> None:
    """An OBJ file with one ``o`` object per mesh, as CoACD writes its convex parts
    (trimesh's OBJ export of a scene, as examples/round-peg/make.py writes one)."""
    scene = trimesh.Scene()
    for name, mesh in objects.items():
        scene.add_geometry(mesh, geom_name=name)
    scene.export(path)


def halves_mm(upper: str = "half2", lower: str = "half10") -> dict[str, trimesh.Trimesh]:
    """The hexagonal peg cut in two at z = 0, as two objects (named so that a plain sort
    would put the lower one first, a natural sort the upper one)."""
    outline = regular_polygon(6, 55.0)
    return {
        lower: trimesh.convex.convex_hull(np.array(prism(outline, -75.0, 0.0))),
        upper: trimesh.convex.convex_hull(np.array(prism(outline, 0.0, 75.0))),
    }


def test_a_mesh_file_of_several_objects_is_one_piece_per_object(hex_yaml, tmp_path):
    """CoACD's output: each object of the OBJ a convex piece NAME_k, in the natural order of
    the objects' names, with the piece's face names; the peg cut in two plans as one."""
    obj_file(tmp_path / "halves.obj", halves_mm())
    hex_yaml["goal"]["manip"] = "peg_1/bottom"
    path = write_mesh_task(tmp_path, hex_yaml, None, file="halves.obj")
    task = load_task(path)
    upper, lower = task.manipuland.pieces
    assert (upper.name, lower.name) == ("peg_0", "peg_1")  # half2 before half10
    assert upper.vertices[:, 2].min() == pytest.approx(0.0) and lower.vertices[:, 2].max() == 0
    assert lower.vertices[:, 2].min() == pytest.approx(-0.075)
    assert task.manipuland.face("peg_1/bottom").offset == pytest.approx(0.075)
    assert "peg_0/bottom" in {f.name for p in task.manipuland.pieces for f in p.faces}
    result = run_cli("graph", path)
    assert result.exit_code == 0 and "(floor/top, peg_1/bottom)" in result.output


@pytest.mark.parametrize(
    "case, message",
    [
        ("not convex", r"object 'half2': not convex"),
        (
            "name taken",
            r"task.yaml:\d+: manipuland: a second piece named 'peg_1' \(the first at line \d+",
        ),
    ],
)
def test_a_bad_object_or_a_name_taken_is_one_line(case, message, hex_yaml, tmp_path):
    objects = halves_mm()
    if case == "not convex":  # two boxes apart in one object: closed, not convex
        apart = trimesh.creation.box(extents=[10, 10, 10])
        apart.apply_translation([0, 0, 100])
        objects["half2"] = trimesh.util.concatenate([objects["half2"], apart])
    obj_file(tmp_path / "halves.obj", objects)
    if case == "name taken":
        hex_yaml["manipuland"]["pieces"].append({"name": "peg_1", "box": {"size": [0.01] * 3}})
    path = write_mesh_task(tmp_path, hex_yaml, None, file="halves.obj")
    result = run_cli("graph", path)
    assert result.exit_code == 2, result.output
    (line,) = result.stderr.splitlines()
    assert re.search(message, line), line


def test_two_pieces_of_one_name_are_refused_with_both_lines(tmp_path):
    data = yaml.safe_load(builtin_tasks()["peg-in-hole"].read_text())
    data["environment"]["pieces"][2]["name"] = data["environment"]["pieces"][1]["name"]
    path = tmp_path / "task.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    result = run_cli("graph", str(path))
    assert result.exit_code == 2 and len(result.stderr.splitlines()) == 1, result.output
    assert re.search(
        r"task.yaml:\d+: environment: a second piece named 'wall_px' \(the first at line \d+",
        result.stderr,
    )


@pytest.mark.slow
def test_a_part_given_as_convex_objects_plans_end_to_end(hex_yaml, tmp_path):
    """The hexagonal peg as two objects of one OBJ (the lower one holds the goal face)."""
    obj_file(tmp_path / "halves.obj", halves_mm())
    hex_yaml["goal"]["manip"] = "peg_1/bottom"
    task = load_task(write_mesh_task(tmp_path, hex_yaml, None, file="halves.obj"))
    result = plan(task, RolloutWorker(task), "bilba-variable", seed=0, timeout_s=120)
    assert result.success, result.reason
    final = result.final_belief
    assert final is not None and all(task.goal in c for c in final.contacts)
    assert task.goal == ("floor/top", "peg_1/bottom")


def test_the_round_peg_example_is_three_mesh_files_and_reaches_its_goal():
    """examples/round-peg: a plate split by CoACD into 16 convex objects (pieces plate_0 …
    plate_15), a floor as wide as the hole, a round peg; its schedule ends in the goal."""
    path = Path(__file__).parents[1] / "examples" / "round-peg" / "round-peg.yaml"
    task = load_task(str(path))
    assert [p.name for p in task.environment.pieces] == ["floor"] + [
        f"plate_{k}" for k in range(16)
    ]
    result = run_cli("graph", str(path))
    assert result.exit_code == 0, result.output
    assert result.output.rstrip().endswith("-> (floor/top, peg/bottom)")


def test_a_goal_face_typo_on_a_mesh_names_the_named_faces_first(tmp_path):
    """A mesh piece has a facet f0, f1, … for each face the file names none for: the
    message for a typo leads with the names the user gave, and counts the rest."""
    folder = Path(__file__).parents[1] / "examples" / "round-peg"
    data = yaml.safe_load((folder / "round-peg.yaml").read_text())
    for part in ("manipuland", "environment"):
        for piece in data[part]["pieces"]:
            piece["mesh"]["file"] = str(folder / piece["mesh"]["file"])
    data["goal"]["manip"] = "peg/botom"
    (path := tmp_path / "typo.yaml").write_text(yaml.safe_dump(data))
    result = run_cli("graph", str(path))
    assert result.exit_code == 2, result.output
    (line,) = result.stderr.splitlines()
    assert line.endswith(
        "goal.manip: piece 'peg' has no face 'peg/botom'; its faces: peg/bottom and 33 "
        "unnamed facets peg/f0 … f33 (name one by its outward normal under 'faces:')"
    )


def test_more_piece_pairs_than_a_slice_can_take_is_one_line(hex_yaml, tmp_path):
    """7 environment pieces × 40 objects of one OBJ = 280 C-obstacles: refused before the
    slice (whose time grows faster than their number: hours at 1 400)."""
    boxes = {f"b{k}": trimesh.creation.box(extents=[2, 2, 2]) for k in range(40)}
    for k, box in enumerate(boxes.values()):
        box.apply_translation([0, 0, 3.0 * k])
    obj_file(tmp_path / "boxes.obj", boxes)
    hex_yaml["goal"]["manip"] = "peg_0/bottom"
    result = run_cli("graph", write_mesh_task(tmp_path, hex_yaml, None, file="boxes.obj"))
    assert result.exit_code == 2, result.output
    (line,) = result.stderr.splitlines()
    assert "7 environment pieces × 40 manipuland pieces = 280 C-obstacles, over 256" in line
