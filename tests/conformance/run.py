"""
``make conformance``: run the test files of the pinned stable-baselines3 and sb3-contrib releases on sb3-es.

Downloads their source distributions from PyPI into a temporary folder (``pip download --no-deps --no-binary
:all:``), extracts their ``tests/`` folders, adds ``conftest_sb3es.py`` (the substitutions and the selection) as
``conftest.py``, and runs pytest there with a per-test timeout, deselecting the tests of ``deselect.txt``. Their test
code is never copied into this repository. Prints pytest's counts; the exit status is pytest's.

Usage: ``python tests/conformance/run.py [--timeout SECONDS] [--keep DIR] [-- extra pytest arguments]``
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
from importlib import metadata
from pathlib import Path

#: The releases whose tests are run (those of ``constraints.txt``).
PINNED = {"stable-baselines3": "2.9.2", "sb3-contrib": "2.9.2"}
#: Folder of each release's tests inside the run folder.
FOLDERS = {"stable-baselines3": "sb3_tests", "sb3-contrib": "contrib_tests"}
#: Modules the downloaded tests import that sb3-es's dev install lacks, with the release installed for the run
#: (into the run folder, not the environment): SB3's ``test_utils.py`` imports ``ale_py`` at module level.
TEST_REQUIREMENTS = {"ale_py": "ale-py==0.12.1"}
HERE = Path(__file__).resolve().parent

PYTEST_INI = """[pytest]
markers =
    expensive: SB3's expensive tests
    slow: sb3-contrib's slow tests
filterwarnings =
    ignore::DeprecationWarning
    ignore::UserWarning:gymnasium
    ignore:rich is experimental
"""


def download(folder: Path) -> None:
    """Download the pinned source distributions and extract their ``tests/`` folders into ``folder``."""
    archives = folder / "sdist"
    requirements = [f"{name}=={version}" for name, version in PINNED.items()]
    subprocess.run(
        [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--no-binary", ":all:", "-d", archives]
        + requirements,
        check=True,
    )
    for name, version in PINNED.items():
        stem = f"{name.replace('-', '_')}-{version}"
        with tarfile.open(archives / f"{stem}.tar.gz") as tar:
            members = [m for m in tar.getmembers() if m.name.startswith(f"{stem}/tests/") and m.isfile()]
            for member in members:
                member.name = member.name.removeprefix(f"{stem}/tests/")
            tar.extractall(folder / FOLDERS[name], members=members, filter="data")


def install_test_requirements(folder: Path) -> Path | None:
    """Install the missing :data:`TEST_REQUIREMENTS` into ``folder/deps``; return that folder, or ``None``."""
    missing = [req for module, req in TEST_REQUIREMENTS.items() if importlib.util.find_spec(module) is None]
    if not missing:
        return None
    target = folder / "deps"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", target, *missing], check=True
    )
    return target


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[1] if __doc__ else None)
    parser.add_argument("--timeout", type=int, default=300, help="seconds allowed per test (pytest-timeout)")
    parser.add_argument("--keep", type=Path, help="run in this folder and keep it (default: a temporary folder)")
    parser.add_argument("pytest_args", nargs="*", help="extra pytest arguments (after --)")
    args = parser.parse_args()
    for name, version in PINNED.items():
        installed = metadata.version(name)
        if installed != version:
            print(f"warning: {name} {installed} is installed, but the tests are those of {version}", file=sys.stderr)
    folder = args.keep or Path(tempfile.mkdtemp(prefix="sb3es-conformance-"))
    folder.mkdir(parents=True, exist_ok=True)
    try:
        download(folder)
        shutil.copy(HERE / "conftest_sb3es.py", folder / "conftest.py")
        (folder / "pytest.ini").write_text(PYTEST_INI)
        deps = install_test_requirements(folder)
        # This checkout's sb3_es, whatever is installed.
        paths = (str(HERE.parents[1]), str(deps) if deps else None, os.environ.get("PYTHONPATH"))
        path = os.pathsep.join(p for p in paths if p)
        env = {**os.environ, "PYTHONPATH": path, "SB3ES_CONFORMANCE_DESELECT": str(HERE / "deselect.txt")}
        env["SB3_LOGDIR"] = str(folder / "sb3_logs")  # SB3's default log folders, else one $TMPDIR/SB3-* per learn()
        command = [
            sys.executable,
            "-m",
            "pytest",
            "-p",
            "no:cacheprovider",
            "--import-mode=importlib",
            f"--timeout={args.timeout}",
            "-o",
            "timeout_func_only=true",  # time the test, not the formatting of its report
            "-q",
            "-rfEs",
            *FOLDERS.values(),
            *args.pytest_args,
        ]
        return subprocess.run(command, cwd=folder, env=env).returncode
    finally:
        if args.keep is None:
            shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
