"""Ray rollout workers: a PyBullet world per worker, the Panda and floating controllers."""

import os


def _import_pybullet_quietly() -> None:
    """pybullet prints its build time on stderr when imported; keep the CLI's stderr for
    errors (one line each). Importing it here, first, covers every module of the package."""
    saved, null = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 2)
    try:
        import pybullet  # noqa: F401
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)


_import_pybullet_quietly()
