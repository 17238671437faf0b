"""What `pip install .` puts in site-packages: the library and its two folders installed as
`bilba_dist.workers` / `bilba_dist.schedulers`, and nothing with a generic top-level name."""

import subprocess
import sys
import venv
import zipfile
from pathlib import Path

import tomllib

ROOT = Path(__file__).resolve().parents[1]


def _declared() -> tuple[list[str], dict[str, str]]:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    return config["packages"], config["package-dir"]


def _folder(package: str, mapping: dict[str, str]) -> Path:
    for name, folder in mapping.items():
        if package == name or package.startswith(name + "."):
            return (
                ROOT
                / folder
                / Path(*package[len(name) + 1 :].split(".") if package != name else ())
            )
    return ROOT / Path(*package.split("."))


def test_every_python_folder_is_declared_as_a_package():
    packages, mapping = _declared()
    declared = {_folder(p, mapping).resolve() for p in packages}
    roots = [ROOT / "bilba_dist", *(ROOT / f for f in mapping.values())]
    found = {
        f.parent.resolve()
        for root in roots
        for f in root.rglob("*.py")
        if "__pycache__" not in f.parts
    }
    assert found - declared == set(), "folders with Python files missing from pyproject packages"
    assert all((folder / "__init__.py").is_file() for folder in declared)


def test_the_wheel_installs_nothing_named_workers_or_schedulers(tmp_path):
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps",
         "-w", str(tmp_path), str(ROOT)],
        check=True, capture_output=True,
    )  # fmt: skip
    (wheel,) = tmp_path.glob("bilba_dist-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names}
    assert {t for t in tops if not t.startswith("bilba_dist")} == set(), tops
    for expected in (
        "bilba_dist/workers/pool.py",
        "bilba_dist/schedulers/batch.py",
        "bilba_dist/task/tasks/hex-peg.stl",
        "bilba_dist/task/tasks/peg-in-hole.yaml",
        "bilba_dist/plans/plan-v2.schema.json",
    ):
        assert expected in names

    env = tmp_path / "venv"
    venv.create(env, with_pip=True)
    python = env / "bin" / "python"
    subprocess.run(
        [str(python), "-m", "pip", "install", "-q", "--no-deps", str(wheel)],
        check=True, capture_output=True,
    )  # fmt: skip
    probe = (
        "import importlib.util as u, sys; "
        "sys.exit(0 if u.find_spec('workers') is None and u.find_spec('schedulers') is None "
        "and u.find_spec('bilba_dist.workers') and u.find_spec('bilba_dist.schedulers.jobs') "
        "else 1)"
    )
    subprocess.run([str(python), "-c", probe], check=True, cwd=tmp_path)
