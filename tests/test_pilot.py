"""``benchmarks/pilot.py``: train until a threshold, save that model, check it over more episodes."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "pilot.py"


def test_pilot_stops_at_the_threshold_and_checks_the_saved_model(tmp_path: Path) -> None:
    out = tmp_path / "cartpole"
    args = ["ARS", '{"n_delta": 4, "n_top": 4}', "--env", "CartPole-v1", "--every", "5000", "--threshold", "200"]
    train = subprocess.run(
        [sys.executable, str(SCRIPT), *args, "--seconds", "120", "--out", str(out)],
        capture_output=True,
        text=True,
        check=True,
    )
    evaluations = [float(m) for m in re.findall(r"eval +(-?[\d.]+)", train.stdout)]
    assert evaluations and evaluations[-1] >= 200 > max(evaluations[:-1], default=0), train.stdout
    assert (tmp_path / "cartpole_hit.zip").exists(), "the model that reached the threshold is saved"
    checked = subprocess.run(
        [sys.executable, str(SCRIPT), "ARS", "--env", "CartPole-v1", "--check", f"{out}_hit.zip", "--check-episodes=5"],
        capture_output=True,
        text=True,
        check=True,
    )
    match = re.search(r": (-?[\d.]+) \+- [\d.]+ \(min (-?[\d.]+), n=5\)", checked.stdout)
    assert match, checked.stdout
    assert float(match.group(1)) >= 100
