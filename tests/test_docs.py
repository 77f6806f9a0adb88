"""The Sphinx docs build without warnings (same flags as `make docs`); every algorithm page states what SB3 users
need to know that differs from SB3."""

import re
from pathlib import Path

import pytest
from algorithms import ALGORITHMS, Algo, learn_logged, pendulum_env

DOCS_DIR = Path(__file__).resolve().parent.parent / "docs"


def test_docs_build(tmp_path: Path) -> None:
    pytest.importorskip("sphinx")
    pytest.importorskip("myst_parser")
    from sphinx.cmd.build import build_main

    out_dir = tmp_path / "html"
    doctree_dir = tmp_path / "doctrees"
    args = ["-W", "--keep-going", "-b", "html", "-q", "-d", str(doctree_dir), str(DOCS_DIR), str(out_dir)]
    assert build_main(args) == 0
    assert (out_dir / "index.html").exists()


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_algorithm_page_states_the_training_budget(algo: Algo) -> None:
    # learn(N) ends at a generation (update) boundary, past N: each algorithm's page says so and links the details.
    page = (DOCS_DIR / "modules" / f"{algo.cls.__module__.split('.')[1]}.md").read_text()
    text = " ".join(page.split())
    assert "**Training budget.**" in text
    unit = "generation" if algo.population else "update"
    assert re.search(rf"`learn\(N\)` completes the {unit} during which `num_timesteps` reaches `N`", text)
    assert f"by up to one {unit}" in text and "`verbose=1` prints" in text
    assert "design.md#timesteps-and-the-training-budget" in text


#: Keys SB3's own algorithms log, which the pages name as SB3's rather than one by one.
SB3_KEYS = {"rollout/ep_rew_mean", "rollout/ep_len_mean", "time/fps", "time/iterations", "time/time_elapsed"}


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_algorithm_page_lists_every_key_it_logs(algo: Algo, tmp_path: Path) -> None:
    # Each key a short run writes to progress.csv, but SB3's own, is named on the algorithm's page.
    rows = learn_logged(algo.make(pendulum_env(), 4), 2_000, tmp_path)
    logged = set(rows[0]) - SB3_KEYS - {"time/total_timesteps"}
    assert any(key.startswith("train/") for key in logged)
    page = (DOCS_DIR / "modules" / f"{algo.cls.__module__.split('.')[1]}.md").read_text()
    missing = sorted(key for key in logged if f"`{key}`" not in page)
    assert not missing, f"{algo.name} logs {missing}, which docs/modules/ does not list"
