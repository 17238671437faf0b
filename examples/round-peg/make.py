"""Make this example's meshes as a user would make theirs (needs `pip install coacd
manifold3d`; the files it writes are in the repository, so running it is optional).

- peg.stl: a 55 mm round peg, 150 mm long, as a 32-sided prism (millimetres).
- floor.stl: the hole's floor, a 48-sided disc exactly as wide as the hole: the goal face
  must exist only where the peg is home (a floor as wide as the plate shows its top along
  the plate's outer edges, and a plan could "succeed" there).
- plate.obj: a 140 × 140 × 40 mm plate with a 58 mm round through hole (1.5 mm of
  clearance a side), non-convex, so split by CoACD into convex objects, each a piece.
  CoACD's hulls fill some of the hole: at `threshold=0.05` (its default) they reach within
  26 mm of the axis and the peg no longer fits; at 0.02 (used here) 28-28.5 mm.
"""

from pathlib import Path

import coacd
import trimesh

here = Path(__file__).parent
trimesh.creation.cylinder(radius=27.5, height=150, sections=32).export(here / "peg.stl")
floor = trimesh.creation.cylinder(radius=29.0, height=20, sections=48)
floor.apply_translation([0, 0, -10])  # top at z = 0, the plate's underside
floor.export(here / "floor.stl")

plate = trimesh.creation.box(extents=[140, 140, 40]).difference(
    trimesh.creation.cylinder(radius=29.0, height=60, sections=48)
)
plate.apply_translation([0, 0, 20])  # from z = 0 to 40 mm
parts = coacd.run_coacd(
    coacd.Mesh(plate.vertices, plate.faces), threshold=0.02, preprocess_mode="off", seed=0
)
scene = trimesh.Scene()
for k, (vertices, faces) in enumerate(parts):
    scene.add_geometry(trimesh.Trimesh(vertices, faces), geom_name=f"part_{k}")
scene.export(here / "plate.obj")
print(f"plate.obj: {len(parts)} convex parts")
