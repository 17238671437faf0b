"""The deploy manifests parse, agree with each other, and run commands that exist here."""

import re
import shlex
from importlib import metadata
from pathlib import Path

import click
import pytest
import yaml

from bilba_dist.cli.main import cli, register
from schedulers.jobs import load_jobs

ROOT = Path(__file__).resolve().parents[1]
DEPLOY = ROOT / "deploy"
IMAGE_ROOT = "/home/ray/bilba_dist"  # where deploy/Dockerfile puts the repository


def check_bilba_command(argv: list[str], image_root: str | None = None) -> None:
    """``argv`` is a `bilba` command line whose options parse and whose jobs file exists."""
    scripts = {e.name for e in metadata.entry_points(group="console_scripts")}
    assert argv[0] in scripts  # installed from pyproject's [project.scripts]
    register()
    command = cli.commands[argv[1]]
    with click.Context(command) as ctx:
        command.parse_args(ctx, list(argv[2:]))
        jobs = Path(ctx.params["jobs_file"])
    if image_root is not None:
        jobs = ROOT / jobs.relative_to(image_root)
    elif not jobs.is_absolute():
        jobs = ROOT / jobs
    assert load_jobs(jobs).jobs


def test_dockerfile_installs_the_project_where_the_manifests_expect_it():
    text = (DEPLOY / "Dockerfile").read_text()
    assert f"WORKDIR {IMAGE_ROOT}" in text and "pip install --no-cache-dir ." in text
    ray_version = re.search(r"FROM rayproject/ray:(\d+\.\d+\.\d+)", text).group(1)
    rayjob = yaml.safe_load((DEPLOY / "rayjob.yaml").read_text())
    assert rayjob["spec"]["rayClusterSpec"]["rayVersion"] == ray_version


def test_rayjob_manifest_runs_a_batch_of_this_project():
    rayjob = yaml.safe_load((DEPLOY / "rayjob.yaml").read_text())
    assert rayjob["apiVersion"] == "ray.io/v1" and rayjob["kind"] == "RayJob"
    argv = shlex.split(rayjob["spec"]["entrypoint"])
    assert argv[:2] == ["bilba", "batch"] and "--address" in argv
    check_bilba_command(argv, IMAGE_ROOT)
    cluster = rayjob["spec"]["rayClusterSpec"]
    images = [c["image"] for c in cluster["headGroupSpec"]["template"]["spec"]["containers"]]
    for group in cluster["workerGroupSpecs"]:
        images += [c["image"] for c in group["template"]["spec"]["containers"]]
    launcher = yaml.safe_load((DEPLOY / "cluster.yaml").read_text())
    assert set(images) == {launcher["docker"]["image"]}


def test_cluster_launcher_yaml_is_complete_and_its_submit_line_works():
    text = (DEPLOY / "cluster.yaml").read_text()
    config = yaml.safe_load(text)
    for key in ("cluster_name", "provider", "available_node_types", "head_node_type"):
        assert key in config
    assert config["head_node_type"] in config["available_node_types"]
    for local in config["file_mounts"].values():
        assert (ROOT / local).is_dir()
    (submit,) = [line for line in text.splitlines() if "ray job submit" in line]
    check_bilba_command(shlex.split(submit.split(" -- ", 1)[1]))


def test_readme_ray_job_submit_line_names_a_real_batch():
    lines = [
        line.strip()
        for line in (ROOT / "README.md").read_text().splitlines()
        if line.strip().startswith("ray job submit")
    ]
    assert lines
    for line in lines:
        check_bilba_command(shlex.split(line.split(" -- ", 1)[1]))


@pytest.mark.parametrize("name", sorted(p.name for p in (DEPLOY / "jobs").glob("*.yaml")))
def test_every_shipped_jobs_file_loads(name):
    assert load_jobs(DEPLOY / "jobs" / name).jobs
