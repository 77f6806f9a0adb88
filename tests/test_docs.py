"""The docs' Python snippets are self-contained and run (`make docs` builds the docs); every algorithm page states
what SB3 users need to know that differs from SB3."""

import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from algorithms import ALGORITHMS, Algo, learn_logged, pendulum_env

DOCS_DIR = Path(__file__).resolve().parent.parent / "docs"
#: The pages a user copies code from.
PAGES = [DOCS_DIR.parent / "README.md", *sorted(path for path in DOCS_DIR.rglob("*.md") if "_build" not in path.parts)]


def python_snippets() -> list[tuple[str, str]]:
    """:return: ``(where, code)`` of every ```` ```python ```` block of the pages, list items' indented ones too."""
    found = []
    for page in PAGES:
        text = page.read_text()
        for match in re.finditer(r"^([ \t]*)```python\n(.*?)^\1```", text, re.S | re.M):
            line = text.count("\n", 0, match.start()) + 1
            found.append((f"{page.relative_to(DOCS_DIR.parent)}:{line}", textwrap.dedent(match[2])))
    return found


def test_python_snippets_are_self_contained(tmp_path: Path) -> None:
    # Each block is copied on its own: it imports what it uses (ruff's undefined-name rules), and one that makes a
    # dm_control env imports shimmy, which registers them.
    snippets = python_snippets()
    assert len(snippets) > 15
    for index, (where, code) in enumerate(snippets):
        (tmp_path / f"snippet_{index}.py").write_text(f"# {where}\n{code}")
        if "dm_control/" in code:
            assert re.search(r"^import shimmy", code, re.M), f"{where}: makes a dm_control env without importing shimmy"
    ruff = [sys.executable, "-m", "ruff", "check", "--isolated", "--no-cache", "--select", "F821,F822,F823"]
    checked = subprocess.run([*ruff, "--output-format", "concise", str(tmp_path)], capture_output=True, text=True)
    # snippet_<i>.py line n (after the comment line) is the page's line fence + n - 1
    located = {f"snippet_{index}.py": where.rsplit(":", 1) for index, (where, _) in enumerate(snippets)}

    def page_line(match: re.Match[str]) -> str:
        page, fence = located[match[1]]
        return f"{page}:{int(fence) + int(match[2]) - 1}"

    report = re.sub(r"\S*(snippet_\d+\.py):(\d+)", page_line, checked.stdout)
    assert checked.returncode == 0, report + checked.stderr


#: Pages whose snippets are not run: Ray's (a local cluster takes seconds to start; one joins a running cluster).
NOT_RUN = {"docs/guide/ray.md"}
#: Each training budget of a snippet, ``.learn(N`` or ``.learn(total_timesteps=N``, becomes 1: one generation.
BUDGET = re.compile(r"(\.learn\((?:total_timesteps=)?)[\d_.e]+")
#: Runs each snippet file given in a fork of one process (the libraries imported once), in the file's folder, with
#: every registered env's episodes cut at 20 steps (as ``test_examples.py``); prints the files that failed.
RUNNER = """
import os, runpy, sys, traceback
import gymnasium as gym
import stable_baselines3, sb3_es, torch

for spec in gym.registry.values():
    if spec.max_episode_steps is not None:
        spec.max_episode_steps = min(spec.max_episode_steps, 20)
for path in sys.argv[1:]:
    pid = os.fork()
    if pid == 0:
        os.chdir(os.path.dirname(path))
        try:
            runpy.run_path(path, run_name="__main__")
        except BaseException:
            traceback.print_exc()
            sys.exit(1)
        sys.exit(0)
    if os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) != 0:
        print(path, flush=True)  # flushed: a fork would print it again
"""


def test_python_snippets_run(tmp_path: Path) -> None:
    files = {}
    for index, (where, code) in enumerate(python_snippets()):
        if where.rsplit(":", 1)[0] in NOT_RUN:
            assert "ray" in code, f"{where}: runs without Ray; run it"
            continue
        small, budgets = BUDGET.subn(r"\g<1>1", code)
        assert budgets == code.count(".learn("), f"{where}: a learn() budget this test cannot shrink"
        path = tmp_path / str(index) / "snippet.py"
        path.parent.mkdir()
        path.write_text(small)
        files[str(path)] = where
    assert len(files) > 10
    command = [sys.executable, "-c", RUNNER, *files]
    ran = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    failed = [files[line] for line in ran.stdout.splitlines() if line in files]
    assert ran.returncode == 0 and not failed, f"failed: {failed}\n{ran.stderr}"


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
