"""Fixtures shared by several test modules (helpers: ``envs.py``; the algorithm list: ``algorithms.py``)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
import torch as th


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
def one_torch_thread() -> Iterator[None]:
    """Small torch networks (REINFORCE) run fastest, with reproducible timings, on one thread (2-core machines)."""
    threads = th.get_num_threads()
    th.set_num_threads(1)
    yield
    th.set_num_threads(threads)
