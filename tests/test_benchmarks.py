"""The benchmark scripts' own argument checks (their runs are minutes long: not tested here)."""

import subprocess
import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def test_planning_benchmark_refuses_a_negative_patience_in_one_line():
    run = subprocess.run(
        [sys.executable, str(BENCHMARKS / "planning.py"), "--sample-patience", "-1"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 2
    errors = [line for line in run.stderr.splitlines() if "error:" in line]
    assert errors == ["planning.py: error: argument --sample-patience: must be 0 or more, got -1"]
