"""
pytest plugin of ``make conformance``: copied as ``conftest.py`` beside the test files of the pinned
stable-baselines3 and sb3-contrib source distributions (downloaded at run time, never committed), it makes those
tests run on sb3-es's algorithms.

Substitutions (made before the test modules import them):

=============================  ==============================  ==========================================
name in the tests              sb3-es class                    smallest hyperparameters
=============================  ==============================  ==========================================
``sb3_contrib.ARS``            :class:`sb3_es.ARS`             the tests' own (same names)
``stable_baselines3.PPO``      :class:`sb3_es.OpenES`          ``population_size=4``
``sb3_contrib.TRPO``           :class:`sb3_es.CMAES`           ``population_size=4``
``stable_baselines3.A2C``      :class:`sb3_es.REINFORCE`       ``n_episodes=2``, ``use_baseline=True``
=============================  ==============================  ==========================================

REINFORCE learns a value baseline in place of A2C's critic (so ``net_arch=dict(pi=..., vf=...)`` means what it
means for A2C). The substitutes (except ARS, which has sb3-contrib's signature) drop the keyword arguments that the
ES method does not have (``n_steps``, ``batch_size``, ``gae_lambda``, ...): they are the original algorithm's
hyperparameters, not behaviour under test. ``policy_kwargs`` are passed unchanged.

Selection: a test runs only if an sb3-es class takes part in it: one of its parameters is a substituted class,
or, when no parameter is an algorithm class, its code names one. The others test SB3's own algorithms and
utilities. Tests listed in ``deselect.txt`` (path in ``SB3ES_CONFORMANCE_DESELECT``) are deselected: each line
is ``node id prefix | reason``, and a test is listed only when it tests something ES does not have.
"""

from __future__ import annotations

import inspect
import os
import types
from pathlib import Path
from typing import Any

import pytest
import sb3_contrib
import stable_baselines3
from stable_baselines3.common.base_class import BaseAlgorithm

import sb3_es


def _substitute(cls: type[BaseAlgorithm], defaults: dict[str, Any]) -> type[BaseAlgorithm]:
    """
    :param cls: An sb3-es algorithm.
    :param defaults: Keyword arguments added when the test does not give them.
    :return: A subclass of the same name that drops the keyword arguments ``cls`` does not take.
    """
    accepted = set(inspect.signature(cls.__init__).parameters)

    def __init__(self: Any, policy: Any, env: Any = None, **kwargs: Any) -> None:
        kwargs = {key: value for key, value in kwargs.items() if key in accepted}
        cls.__init__(self, policy, env, **{**defaults, **kwargs})

    return types.new_class(cls.__name__, (cls,), exec_body=lambda ns: ns.update(__init__=__init__, __module__=__name__))


SUBSTITUTES: dict[tuple[Any, str], type[BaseAlgorithm]] = {
    (sb3_contrib, "ARS"): sb3_es.ARS,
    (stable_baselines3, "PPO"): _substitute(sb3_es.OpenES, dict(population_size=4)),
    (sb3_contrib, "TRPO"): _substitute(sb3_es.CMAES, dict(population_size=4)),
    (stable_baselines3, "A2C"): _substitute(sb3_es.REINFORCE, dict(n_episodes=2, use_baseline=True)),
}
for (module, name), substitute in SUBSTITUTES.items():
    setattr(module, name, substitute)
    setattr(getattr(module, name.lower()), name, substitute)  # e.g. stable_baselines3.ppo.PPO
SUBSTITUTED_NAMES = {name for _, name in SUBSTITUTES}
SUBSTITUTED_CLASSES = set(SUBSTITUTES.values())


def _names_in(code: types.CodeType) -> set[str]:
    """:return: The global and attribute names a code object (and the functions nested in it) refers to."""
    names = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            names |= _names_in(const)
    return names


def involves_sb3_es(item: pytest.Item) -> bool:
    """:return: Whether an sb3-es class takes part in a test (see the module docstring)."""
    params = getattr(getattr(item, "callspec", None), "params", {})
    algos = [v for v in params.values() if isinstance(v, type) and issubclass(v, BaseAlgorithm)]
    if algos:
        return any(algo in SUBSTITUTED_CLASSES for algo in algos)
    function = getattr(item, "function", None)
    return function is not None and bool(_names_in(function.__code__) & SUBSTITUTED_NAMES)


def read_deselect_list(path: Path) -> list[tuple[str, str]]:
    """:return: ``(node id prefix, reason)`` pairs; an entry without a reason is an error."""
    entries = []
    for number, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        prefix, _, reason = (part.strip() for part in line.partition("|"))
        if not reason:
            raise ValueError(f"{path}:{number}: '{line}' has no reason (write 'node id prefix | reason').")
        entries.append((prefix, reason))
    return entries


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    listed = os.environ.get("SB3ES_CONFORMANCE_DESELECT")
    entries = read_deselect_list(Path(listed)) if listed else []
    used = set()
    selected, not_es, listed_out = [], [], []
    for item in items:
        entry = next((e for e in entries if item.nodeid.startswith(e[0])), None)
        if not involves_sb3_es(item):
            not_es.append(item)
        elif entry is not None:
            used.add(entry)
            listed_out.append(item)
        else:
            selected.append(item)
    config.hook.pytest_deselected(items=not_es + listed_out)
    items[:] = selected
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        reporter.write_line(
            f"sb3-es conformance: {len(selected)} tests selected; deselected: {len(not_es)} without an sb3-es "
            f"class, {len(listed_out)} listed in deselect.txt (ES lacks what they test)"
        )
        for prefix, reason in entries:
            if (prefix, reason) not in used:
                reporter.write_line(f"  unused deselect entry (matches no sb3-es test): {prefix}")
