"""Ray rollout workers: a PyBullet world per worker and the Panda controller (issue 3, 5)."""
