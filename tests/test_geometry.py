from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from bilba_dist.errors import GeometryError
from bilba_dist.geometry.piece import box_piece, convex_piece, smooth_surfaces
from bilba_dist.geometry.pose import pose_from_xyz_rpy, snap_rotation

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
CUBE = [[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)]


def test_box_has_six_named_faces_with_outward_normals():
    box = box_piece("b", [0.2, 0.4, 0.6], pin.SE3.Identity())
    assert sorted(f.name for f in box.faces) == sorted(
        f"b/{n}" for n in ("+x", "-x", "+y", "-y", "+z", "-z")
    )
    assert np.allclose(box.face("b/+y").normal, [0, 1, 0])
    assert box.face("b/+y").offset == pytest.approx(0.2)
    assert len(box.vertices) == 8 and len(box.edges) == 12


def test_coplanar_triangles_merge_into_one_face_each():
    cube = convex_piece("c", CUBE, pin.SE3.Identity())
    assert len(cube.faces) == 6
    assert all(len(f.vertices) == 4 for f in cube.faces)
    assert sorted(f.name for f in cube.faces) == [f"c/f{i}" for i in range(6)]


@given(st.integers(0, 2**32 - 1))
@settings(max_examples=40, deadline=None)
@example(0)
def test_hull_faces_are_closed_counter_clockwise_rings(seed):
    """Random clouds and a rotated box (faces symmetric about their centres): every face's
    ring is planar and counter-clockwise seen from outside, and the rings close up into a
    polyhedron (each edge in two faces; V - E + F = 2)."""
    from bilba_dist.geometry.hull import convex_hull, face_edges, planar_faces

    rng = np.random.default_rng(seed)
    box = np.array(CUBE, dtype=float) * [1.0, 2.0, 3.0] @ pin.exp3(rng.normal(size=3)).T
    for points in (rng.normal(size=(int(rng.integers(5, 40)), 3)), box):
        hull = convex_hull(points, "cloud")
        faces = planar_faces(points, hull)
        for face in faces:
            ring = points[list(face.vertices)]
            assert np.allclose(ring @ face.normal, face.offset, atol=1e-9)
            assert np.all(points @ face.normal <= face.offset + 1e-9)
            turns = np.cross(np.roll(ring, -1, axis=0) - ring, np.roll(ring, -2, axis=0) - ring)
            assert np.all(turns @ face.normal > 0)
        edges = face_edges(f.vertices for f in faces)
        rims = [
            tuple(sorted(e))
            for f in faces
            for e in zip(f.vertices, np.roll(f.vertices, -1), strict=True)
        ]
        assert all(rims.count(tuple(e)) == 2 for e in edges.tolist())
        assert len(hull.vertices) - len(edges) + len(faces) == 2


def test_face_means_add_in_the_order_a_plain_mean_does():
    """Face normals and centres are means over a face's rows, computed for all faces at
    once; rounded differently, a symmetric face's ring would start at another corner."""
    from bilba_dist.geometry.hull import _mean_by

    rng = np.random.default_rng(7)
    values = rng.normal(size=(400, 3)) * 10.0 ** rng.uniform(-9, 0, size=(400, 1))
    groups = rng.integers(0, 37, size=400)
    means = _mean_by(values, groups, 37)
    for g in range(37):
        assert np.array_equal(means[g], values[groups == g].mean(axis=0))


def test_name_map_names_faces_by_normal():
    cube = convex_piece("c", CUBE, pin.SE3.Identity(), {"top": [0, 0, 2], "left": [-1, 0, 0]})
    assert np.allclose(cube.face("c/top").normal, [0, 0, 1])
    assert np.allclose(cube.face("c/left").normal, [-1, 0, 0])
    assert sum(f.name.startswith("c/f") for f in cube.faces) == 4
    huge = convex_piece(
        "c", CUBE, pin.SE3.Identity(), {"right": [1e308, 0, 0], "far": [0, 0, -9e307]}
    )
    assert np.allclose(huge.face("c/right").normal, [1, 0, 0])  # no norm of 1e308 overflows
    assert np.allclose(huge.face("c/far").normal, [0, 0, -1])


def prism(sides: int, radius: float = 0.03, height: float = 0.1) -> list[list[float]]:
    angles = 2 * np.pi * np.arange(sides) / sides
    return [[radius * np.cos(a), radius * np.sin(a), z] for a in angles for z in (0.0, height)]


@pytest.mark.parametrize(("sides", "names"), [(32, 3), (16, 3), (8, 10), (6, 8)])
def test_a_meshed_cylinders_sides_are_one_surface_a_polygons_are_not(sides, names):
    """32 or 16 sections (11.25°, 22.5° apart): the sides are one face name, the lowest
    ``f`` number, beside the two caps; an octagon's or hexagon's sides (45°, 60°) keep
    their own."""
    piece = smooth_surfaces(convex_piece("p", prism(sides), pin.SE3.Identity()))
    assert len(piece.faces) == sides + 2
    assert len({f.name for f in piece.faces}) == names
    if names == 3:
        sides_named = {f.name for f in piece.faces if abs(f.normal[2]) < 0.5}
        assert sides_named == {"p/f0"}  # f0: the +x side, first by normal


def test_a_named_facet_stays_out_of_a_smooth_surface():
    half = np.pi / 32  # the first side facet's normal lies between its two edges
    front = [np.cos(half), np.sin(half), 0.0]
    piece = smooth_surfaces(convex_piece("p", prism(32), pin.SE3.Identity(), {"front": front}))
    names = [f.name for f in piece.faces]
    assert names.count("p/front") == 1
    assert len(set(names)) == 4  # front, the other 31 sides, the two caps
    assert max(names.count(n) for n in set(names)) == 31


def test_an_environments_smooth_surface_is_cut_into_patches():
    """With a spread (the environment's), a cylinder's sides become patches of facets whose
    normals all lie within it of each other: a round wall is not one face, whose contacts
    on opposite sides would be one contact."""
    from bilba_dist.geometry.piece import SMOOTH_ANGLE

    piece = smooth_surfaces(convex_piece("p", prism(32), pin.SE3.Identity()), SMOOTH_ANGLE)
    sides = [f for f in piece.faces if abs(f.normal[2]) < 0.5]
    patches: dict[str, list[np.ndarray]] = {}
    for f in sides:
        patches.setdefault(f.name, []).append(f.normal)
    assert 11 <= len(patches) < 32  # 32 sides 11.25° apart: at most 3 a patch
    for normals in patches.values():
        assert min(a @ b for a in normals for b in normals) >= np.cos(SMOOTH_ANGLE) - 1e-12


def test_the_round_peg_example_has_one_side_face_and_a_patched_floor():
    from bilba_dist.geometry.piece import SMOOTH_ANGLE
    from bilba_dist.task.loader import load_task

    task = load_task(str(EXAMPLES / "round-peg" / "round-peg.yaml"))
    (peg,) = task.manipuland.pieces
    assert len(peg.faces) == 34 and len({f.name for f in peg.faces}) == 3
    floor = next(p for p in task.environment.pieces if p.name == "floor")
    assert 2 < len({f.name for f in floor.faces}) < len(floor.faces)
    for piece in task.environment.pieces:
        for name in {f.name for f in piece.faces}:
            normals = [f.normal for f in piece.faces if f.name == name]
            assert min(a @ b for a in normals for b in normals) >= np.cos(SMOOTH_ANGLE) - 1e-12


def test_a_goal_given_as_an_unnamed_facet_stays_a_face(tmp_path):
    """A goal on the peg's facet f5 (one of its round sides) still names that facet."""
    import yaml

    from bilba_dist.task.loader import load_task

    folder = EXAMPLES / "round-peg"
    data = yaml.safe_load((folder / "round-peg.yaml").read_text())
    for part in ("manipuland", "environment"):
        for piece in data[part]["pieces"]:
            piece["mesh"]["file"] = str(folder / piece["mesh"]["file"])
    data["goal"] = {"env": "plate_4/f1", "manip": "peg/f5"}
    path = tmp_path / "side-goal.yaml"
    path.write_text(yaml.safe_dump(data))
    task = load_task(str(path))
    names = [f.name for f in task.manipuland.pieces[0].faces]
    assert names.count("peg/f5") == 1 and names.count("peg/f0") == 31
    plate = task.environment.piece("plate_4/f1")
    assert [f.name for f in plate.faces].count("plate_4/f1") == 1


def test_the_built_in_tasks_have_no_smooth_surfaces():
    """Every face of every piece of the built-ins keeps a name of its own: their modes,
    and so their searches, are what they were before smooth surfaces."""
    from bilba_dist.task.loader import builtin_tasks, load_task

    for name in builtin_tasks():
        task = load_task(name)
        for piece in (*task.manipuland.pieces, *task.environment.pieces):
            names = [f.name for f in piece.faces]
            assert len(names) == len(set(names)), (name, piece.name)


def test_a_contact_on_the_edge_between_two_sides_of_a_cylinder_is_one_pair():
    from bilba_dist.geometry.labels import label_points
    from bilba_dist.geometry.piece import Part

    peg = Part("peg", (smooth_surfaces(convex_piece("peg", prism(32), pin.SE3.Identity())),))
    wall = box_piece("wall", [0.02, 0.2, 0.2], pin.SE3(np.eye(3), np.array([0.04, 0, 0.05])))
    x, y, _ = prism(32)[0]
    corner = np.array([[x, y, 0.05]])  # on the edge between two side facets
    contacts = label_points(wall, peg, corner, np.array([[-1.0, 0, 0]]), corner, np.eye(3))
    assert contacts == {("wall/-x", "peg/f0")}


def test_pose_moves_vertices_and_face_planes():
    X = pose_from_xyz_rpy([1, 2, 3], [0, 0, np.pi / 2])
    box = box_piece("b", [2, 2, 2], X)
    face = box.face("b/+x")  # the box's +x now points along world +y
    assert np.array_equal(face.normal, [0.0, 1.0, 0.0])  # exact: 90° rotations are snapped
    assert face.offset == pytest.approx(3.0)
    assert np.allclose(box.vertices.mean(axis=0), [1, 2, 3])


@pytest.mark.parametrize(
    ("point", "faces"),
    [
        ([0.5, 0.5, 1.0], {"c/top"}),
        ([1.0, 0.5, 1.0], {"c/top", "c/right"}),
        ([1.0, 1.0, 1.0], {"c/top", "c/right", "c/back"}),
    ],
)
def test_faces_at_names_every_face_through_a_point(point, faces):
    cube = convex_piece(
        "c", CUBE, pin.SE3.Identity(), {"top": [0, 0, 1], "right": [1, 0, 0], "back": [0, 1, 0]}
    )
    assert {cube.faces[i].name for i in cube.faces_at(np.array(point))} == faces
    assert cube.faces_at(np.array(point) + 0.01) == []  # off the piece


@pytest.mark.parametrize(
    ("vertices", "names", "complaint"),
    [
        ([*CUBE, [0.5, 0.5, 0.5]], None, "not convex"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], None, "degenerate"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], None, "at least 4"),
        (CUBE, {"slanted": [1, 1, 0]}, "no facet has the normal"),
        (CUBE, {"slanted": [1e308, 1e308, 0]}, r"no facet has the normal \[0.7071, 0.7071, 0.0\]"),
        (CUBE, {"nowhere": [0, 0, 0]}, "nonzero 3-vector"),
        (CUBE, {"a": [1, 0, 0], "b": [1, 0, 0]}, "name the same facet"),
        (CUBE, {"f5": [1, 0, 0]}, "share a name"),
    ],
)
def test_bad_convex_pieces_are_geometry_errors(vertices, names, complaint):
    with pytest.raises(GeometryError, match=complaint):
        convex_piece("p", vertices, pin.SE3.Identity(), names)


def test_zero_sized_box_is_rejected():
    with pytest.raises(GeometryError, match="positive"):
        box_piece("b", [0.1, 0.0, 0.1], pin.SE3.Identity())


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-np.pi, np.pi), min_size=3, max_size=3))
@example([0.0, 1.0, 1e-12])  # a tiny yaw: entries once snapped to 0 on one side only
def test_rpy_poses_are_rotations(rpy):
    R = pose_from_xyz_rpy([0, 0, 0], rpy).rotation
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_snap_makes_right_angles_exact():
    R = snap_rotation(pin.rpy.rpyToMatrix(np.array([0, 0, np.pi / 2])))
    assert np.array_equal(R, [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
