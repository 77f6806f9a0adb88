"""``benchmarks/pair_noise.py``: the noise of a mirrored pair's return difference, common vs separate starts."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from test_zoo import load_script

from sb3_es import PGPE

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "pair_noise.py"


def test_common_starting_states_remove_the_noise_of_near_identical_pairs(tmp_path: Path) -> None:
    path = tmp_path / "pgpe.zip"
    PGPE("LinearPolicy", "Pendulum-v1", population_size=4, seed=0, zero_policy=False).save(path)
    # At a tiny sigma the pair members act alike: from the same states their returns differ by almost nothing,
    # from separate ones by the states' doing (Pendulum starts at a random angle).
    args = [str(path), "Pendulum-v1", "--pairs", "3", "--episodes", "4", "--sigma", "1e-6", "--n-envs", "2"]
    out = subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True, check=True).stdout
    variances = dict(re.findall(r"(common|separate) starting states: .*var of the pair difference ([\d.e+]+)", out))
    assert set(variances) == {"common", "separate"}, out
    assert float(variances["common"]) < 1 < float(variances["separate"]), out
    assert re.search(r"ratio separate / common: [\d.]+", out), out


def test_fewer_than_two_episodes_are_refused(capsys: pytest.CaptureFixture[str]) -> None:
    """A variance over one episode is nan: refused before the model is loaded."""
    with pytest.raises(SystemExit):
        load_script("pair_noise").main(["model.zip", "Pendulum-v1", "--episodes", "1"])
    assert "--episodes 1: it must be at least 2 (the variance over episodes needs two)" in capsys.readouterr().err
