"""The benchmark scripts' own argument checks (their runs are minutes long: not tested here)."""

import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.mark.parametrize(
    ("flag", "value", "shown"),
    [
        ("--sample-patience", "-1", "-1"),
        ("--race-contacts", "-1", "-1"),
        ("--near-edges", "-0.001", "-0.001"),
        ("--near-edges", "nan", "nan"),
        ("--press", "-0.02", "-0.02"),
    ],
)
def test_planning_benchmark_refuses_a_negative_setting_in_one_line(flag, value, shown):
    run = subprocess.run(
        [sys.executable, str(BENCHMARKS / "planning.py"), flag, value],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 2
    errors = [line for line in run.stderr.splitlines() if "error:" in line]
    assert errors == [f"planning.py: error: argument {flag}: must be 0 or more, got {shown}"]
