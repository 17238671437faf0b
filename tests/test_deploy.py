"""The deploy manifests parse, agree with each other, and run commands that exist here."""

import re
import shlex
from importlib import metadata
from pathlib import Path

import click
import pytest
import yaml

from bilba_dist.cli.main import cli, register
from bilba_dist.schedulers.jobs import load_jobs

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
    ray_version = re.search(r"RAY_IMAGE=rayproject/ray:(\d+\.\d+\.\d+)", text).group(1)
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


#: Fields of KubeRay's v1 RayJob and RayCluster specs (the CRDs' OpenAPI schemas,
#: ray-operator/config/crd/bases/ray.io_rayjobs.yaml, KubeRay 1.x): a misspelt key in our
#: manifest is an error here, as it is on a cluster whose API server prunes unknown fields.
KUBERAY_FIELDS = {
    "spec": {
        "activeDeadlineSeconds", "backoffLimit", "clusterSelector", "deletionStrategy",
        "entrypoint", "entrypointNumCpus", "entrypointNumGpus", "entrypointResources", "jobId",
        "managedBy", "metadata", "rayClusterSpec", "runtimeEnvYAML", "shutdownAfterJobFinishes",
        "submissionMode", "submitterConfig", "submitterPodTemplate", "suspend",
        "ttlSecondsAfterFinished",
    },
    "rayClusterSpec": {
        "autoscalerOptions", "enableInTreeAutoscaling", "gcsFaultToleranceOptions",
        "headGroupSpec", "headServiceAnnotations", "managedBy", "rayVersion", "suspend",
        "workerGroupSpecs",
    },
    "headGroupSpec": {"enableIngress", "headService", "rayStartParams", "serviceType", "template"},
    "workerGroupSpec": {
        "groupName", "idleTimeoutSeconds", "maxReplicas", "minReplicas", "numOfHosts",
        "rayStartParams", "replicas", "scaleStrategy", "suspend", "template",
    },
}  # fmt: skip


def kubernetes_errors(manifest: dict) -> str | None:
    """The Kubernetes OpenAPI schema's verdict (strict: unknown fields are errors)."""
    kubernetes_validate = pytest.importorskip("kubernetes_validate")
    try:
        kubernetes_validate.validate(manifest, kubernetes_validate.latest_version(), strict=True)
    except kubernetes_validate.ValidationError as exc:
        return str(exc).splitlines()[0]
    return None


def pod_templates(rayjob: dict) -> list[dict]:
    cluster = rayjob["spec"]["rayClusterSpec"]
    return [cluster["headGroupSpec"]["template"]] + [
        g["template"] for g in cluster["workerGroupSpecs"]
    ]


def test_kubernetes_schema_check_catches_a_misspelt_field():
    wrong = {"spec": {"securityContext": {"fsgroup": 100}, "containers": [{"name": "a"}]}}
    manifest = {"apiVersion": "v1", "kind": "PodTemplate", "metadata": {"name": "t"}}
    assert "fsgroup" in kubernetes_errors({**manifest, "template": wrong})


def test_rayjob_and_volume_are_valid_kubernetes_and_kuberay_objects():
    rayjob = yaml.safe_load((DEPLOY / "rayjob.yaml").read_text())
    spec = rayjob["spec"]
    assert set(spec) <= KUBERAY_FIELDS["spec"]
    assert set(spec["rayClusterSpec"]) <= KUBERAY_FIELDS["rayClusterSpec"]
    assert set(spec["rayClusterSpec"]["headGroupSpec"]) <= KUBERAY_FIELDS["headGroupSpec"]
    for group in spec["rayClusterSpec"]["workerGroupSpecs"]:
        assert set(group) <= KUBERAY_FIELDS["workerGroupSpec"]
    for i, template in enumerate(pod_templates(rayjob)):
        manifest = {"apiVersion": "v1", "kind": "PodTemplate", "metadata": {"name": f"t{i}"}}
        assert kubernetes_errors({**manifest, "template": template}) is None
    pvc = yaml.safe_load((DEPLOY / "pvc.yaml").read_text())
    assert kubernetes_errors(pvc) is None


def test_the_results_volume_is_defined_and_writable_by_the_image_user():
    rayjob = yaml.safe_load((DEPLOY / "rayjob.yaml").read_text())
    pvc = yaml.safe_load((DEPLOY / "pvc.yaml").read_text())
    head = pod_templates(rayjob)[0]["spec"]
    claims = {v["persistentVolumeClaim"]["claimName"] for v in head["volumes"]}
    assert claims == {pvc["metadata"]["name"]}
    # rayproject/ray images run as user ray (uid 1000) in group users (gid 100).
    assert head["securityContext"]["fsGroup"] == 100
    out = shlex.split(rayjob["spec"]["entrypoint"])
    mounts = [m["mountPath"] for c in head["containers"] for m in c.get("volumeMounts", [])]
    assert any(out[out.index("--out") + 1].startswith(m + "/") for m in mounts)


def test_kustomization_names_every_manifest_and_sets_the_one_image():
    kustomization = yaml.safe_load((DEPLOY / "kustomization.yaml").read_text())
    assert all((DEPLOY / r).is_file() for r in kustomization["resources"])
    (image,) = kustomization["images"]
    rayjob = yaml.safe_load((DEPLOY / "rayjob.yaml").read_text())
    used = {c["image"] for t in pod_templates(rayjob) for c in t["spec"]["containers"]}
    assert {u.split(":")[0] for u in used} == {image["name"]}
    assert "docker build -f deploy/Dockerfile -t" in (DEPLOY / "Dockerfile").read_text()


def test_docker_context_leaves_out_environments_history_and_results():
    ignored = (ROOT / ".dockerignore").read_text().split()
    for entry in (".git", ".venv", "logs/*", "plans", "batches", "build"):
        assert entry in ignored
