"""The layering the design promises: strategies <- evaluation <- glue <- algorithms, and Ray imported on demand."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import sb3_es

PACKAGE = Path(sb3_es.__file__).parent
#: What each lower layer may import from sb3_es.
ALLOWED = {"strategies": {"strategies"}, "evaluation": {"strategies", "evaluation"}}


def sb3_es_imports(path: Path) -> set[str]:
    """:return: The ``sb3_es`` subpackages that a module imports (absolute or relative imports)."""
    package = path.relative_to(PACKAGE.parent).with_suffix("").parts[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = list(package[: len(package) - node.level + 1]) if node.level else []
            module = ".".join([*base, *(node.module.split(".") if node.module else [])])
            names = [module] if node.module else [f"{module}.{alias.name}" for alias in node.names]
        for name in names:
            parts = name.split(".")
            if parts[0] == "sb3_es" and len(parts) > 1:
                found.add(parts[1])
    return found


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_lower_layers_do_not_import_upper_ones(layer: str) -> None:
    modules = sorted((PACKAGE / layer).glob("*.py"))
    assert modules
    wrong = {str(m.relative_to(PACKAGE)): sorted(sb3_es_imports(m) - ALLOWED[layer]) for m in modules}
    assert {m: names for m, names in wrong.items() if names} == {}


def test_the_check_sees_imports() -> None:
    assert sb3_es_imports(PACKAGE / "common" / "policies.py") >= {"evaluation"}
    assert "strategies" in sb3_es_imports(PACKAGE / "evaluation" / "sharded.py")


def test_import_sb3_es_imports_neither_ray_nor_pycma() -> None:
    # Ray is an extra; pycma imports SciPy and matplotlib (about 2 s), which every Ray actor and worker process
    # would pay at start-up: both are imported where they are used.
    heavy = ("ray", "cma", "scipy", "matplotlib")
    script = (
        "import sys\n"
        "import sb3_es, sb3_es.evaluation, sb3_es.evaluation.worker, sb3_es.evaluation.process_worker\n"
        f"print(sorted(m for m in sys.modules if m.split('.')[0] in {heavy!r} or m == 'sb3_es.evaluation.ray'))\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600, check=True)
    assert out.stdout.strip() == "[]"
