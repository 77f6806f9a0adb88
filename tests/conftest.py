"""Fixtures shared by several test modules (helpers: ``envs.py``; the algorithm list: ``algorithms.py``)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
import torch as th


@pytest.fixture(scope="session", autouse=True)
def sb3_logdir(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """SB3's logger folder when a run gives none: ``configure()`` reads ``SB3_LOGDIR``, else makes a new
    ``$TMPDIR/SB3-<time>`` per ``learn()``. Subprocesses inherit it."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("SB3_LOGDIR", str(tmp_path_factory.mktemp("sb3_logdir")))
        yield


#: Torch's thread count when the session starts.
TORCH_THREADS = th.get_num_threads()


@pytest.fixture(autouse=True)
def torch_threads() -> Iterator[None]:
    """After each test, torch's thread count (process-wide) is the session's again: benchmark scripts and rl-zoo's
    ``--num-threads`` set it, in tests and in module fixtures."""
    yield
    th.set_num_threads(TORCH_THREADS)


@pytest.fixture(scope="session")
def ray_cluster() -> Iterator[Any]:
    """A local Ray instance with 2 CPUs for the whole session (started once: it takes seconds)."""
    import envs
    import ray
    import sharded_helpers

    # The test helpers live in modules that Ray workers cannot import: ship them by value.
    ray.cloudpickle.register_pickle_by_value(envs)
    ray.cloudpickle.register_pickle_by_value(sharded_helpers)
    # address="local": a new instance, even if a cluster started with `ray start` runs on this machine.
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


@pytest.fixture
def one_torch_thread() -> None:
    """Small torch networks (REINFORCE) run fastest, with reproducible timings, on one thread (2-core machines);
    ``torch_threads`` restores the count."""
    th.set_num_threads(1)
