"""Fixtures shared by several test modules."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest


@pytest.fixture(scope="session")
def ray_cluster() -> Iterator[Any]:
    """A local Ray instance with 2 CPUs for the whole session (started once: it takes seconds)."""
    ray = pytest.importorskip("ray")
    import envs
    import sharded_helpers

    # The test helpers live in modules that Ray workers cannot import: ship them by value.
    ray.cloudpickle.register_pickle_by_value(envs)
    ray.cloudpickle.register_pickle_by_value(sharded_helpers)
    # address="local": a new instance, even if a cluster started with `ray start` runs on this machine.
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()
