"""What is Ray's own: saves without Ray, evaluator="ray" from an env id, actors shared and released, timeouts.

Ray's behaviour as a host of the sharded evaluator (same results as locally, callbacks, faults) is tested with the
worker processes' in ``test_sharded.py``."""

from __future__ import annotations

import gc
import logging
import math
import os
import re
import subprocess
import sys
import threading
import time
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import ray
from envs import StepCounter, ToyEnv
from sharded_helpers import ENVS_PER_WORKER, learn_generations, make_ars, toy_policy, toy_population, wait_gone
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import SubprocVecEnv

from sb3_es import ARS
from sb3_es.evaluation import VecEnvEvaluator
from sb3_es.evaluation.ray import RayEvaluator
from sb3_es.evaluation.ray_actor import RayWorker
from sb3_es.evaluation.shaping import RewardShaping
from sb3_es.evaluation.worker import DEFAULT_ENVS_PER_WORKER, env_config

pytestmark = pytest.mark.ray


@pytest.fixture(scope="module", autouse=True)
def ray_session(ray_cluster: Any) -> None:
    # Helpers defined here cannot be imported by Ray workers: ship them by value.
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])


@pytest.fixture(scope="module")
def toy_ray() -> Iterator[RayEvaluator]:
    """Two actors (half a CPU each, leaving room for other actors) with two ToyEnv slots each, counting steps."""
    evaluator = RayEvaluator(
        ToyEnv,
        num_workers=2,
        envs_per_worker=ENVS_PER_WORKER,
        wrapper_class=StepCounter,
        wrapper_kwargs=dict(counter=[0]),
        num_cpus_per_worker=0.5,
    )
    with evaluator:
        yield evaluator


def test_saved_model_loads_without_ray(toy_ray: RayEvaluator, tmp_path: Path) -> None:
    model = make_ars(ToyEnv(), evaluator=toy_ray)
    learn_generations(model, 1)
    path = tmp_path / "model.zip"
    model.save(path)
    with zipfile.ZipFile(path) as archive:
        data = archive.read("data").decode()
    assert '"evaluator"' not in data and '"_env_id"' not in data
    obs = np.array([0.3, 0.1], dtype=np.float32)
    expected = model.predict(obs, deterministic=True)[0]
    script = (
        "import sys; sys.modules['ray'] = None\n"  # any `import ray` now fails
        "import numpy as np\n"
        "from sb3_es import ARS\n"
        f"model = ARS.load({str(path)!r})\n"
        "assert 'ray' not in [m for m in sys.modules if sys.modules[m] is not None]\n"
        "print(repr(model.predict(np.array([0.3, 0.1], dtype=np.float32), deterministic=True)[0].tolist()))\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=True)
    np.testing.assert_array_equal(np.array(eval(out.stdout.strip().splitlines()[-1])), expected)


def test_evaluator_ray_from_env_id(toy_ray: RayEvaluator) -> None:
    # toy_ray holds one of the two CPUs, so evaluator="ray" gets one worker (one per available CPU).
    with pytest.raises(ValueError, match="env id"):
        ARS("LinearPolicy", ToyEnv(), evaluator="ray")
    local = ARS("LinearPolicy", make_vec_env("Pendulum-v1", n_envs=DEFAULT_ENVS_PER_WORKER), n_delta=1, seed=0)
    remote = ARS("LinearPolicy", "Pendulum-v1", n_delta=1, seed=0, evaluator="ray")
    try:
        local.learn(1)
        remote.learn(1)
        evaluator = remote._evaluator
        assert isinstance(evaluator, RayEvaluator)
        assert evaluator.env == "Pendulum-v1"
        # One actor with the default env slots, seeded as a local VecEnv of as many envs: Pendulum's random starts
        # included, the same generation bit for bit (2 candidates, 2 slots on the center policy).
        assert evaluator.num_workers == 1 and evaluator.envs_per_worker == DEFAULT_ENVS_PER_WORKER
        assert remote.num_timesteps == local.num_timesteps == DEFAULT_ENVS_PER_WORKER * 200
        np.testing.assert_array_equal(remote.strategy.center, local.strategy.center)
    finally:
        if remote._evaluator is not None:
            remote._evaluator.close()


def assert_dead(actors: list[Any]) -> None:
    refs = [actor.ready.remote() for actor in actors]
    # A call to a killed actor fails once Ray has processed the kill: on a loaded machine that can take a while.
    ray.wait(refs, num_returns=len(refs), timeout=300)
    for ref in refs:
        with pytest.raises(ray.exceptions.RayActorError):
            ray.get(ref, timeout=1)


@pytest.mark.timeout(300, method="thread")
def test_models_in_a_loop_share_and_release_actors(toy_ray: RayEvaluator, caplog: pytest.LogCaptureFixture) -> None:
    # A seed loop (or notebook re-runs) of the documented one-liner, never closing the evaluators: every model
    # trains, on the first model's actor. toy_ray holds one of the two CPUs, so evaluator="ray" gets one worker
    # (one per free CPU), whatever the timing of Ray's resource reports, and toy_ray keeps its actors.
    toy_ray.start()
    toy_actors = [a._actor_id for a in toy_ray._actors]
    evaluators = []
    with caplog.at_level(logging.WARNING):
        for seed in range(10):
            model = ARS("LinearPolicy", "Pendulum-v1", n_delta=1, seed=seed, evaluator="ray")
            model.learn(1)
            assert isinstance(model._evaluator, RayEvaluator)
            evaluators.append(model._evaluator)
            # One worker runs the two candidates' episodes side by side, its other default slots on the center
            # policy (no lingering with one share).
            assert model._evaluator.num_workers == 1
            assert model._n_updates == 1 and model.num_timesteps == DEFAULT_ENVS_PER_WORKER * 200
    assert not [r for r in caplog.records if "idle Ray actor" in r.getMessage()]
    assert [a._actor_id for a in toy_ray._actors] == toy_actors
    actors = evaluators[0]._actors
    assert len(actors) == 1
    for evaluator in evaluators[1:]:
        assert [a._actor_id for a in evaluator._actors] == [a._actor_id for a in actors]
    # The actors live while an evaluator uses them, and are killed when the last one is closed.
    for evaluator in evaluators[:-1]:
        evaluator.close()
    assert ray.get(actors[0].ready.remote(), timeout=60) == DEFAULT_ENVS_PER_WORKER
    evaluators[-1].close()
    assert_dead(actors)
    # A new model after the closed ones gets a worker again at once.
    model = ARS("LinearPolicy", "Pendulum-v1", n_delta=1, seed=0, evaluator="ray")
    try:
        model.learn(1)
        assert model._evaluator.num_workers == 1  # type: ignore[union-attr]
    finally:
        model._evaluator.close()  # type: ignore[union-attr]


@pytest.mark.timeout(300, method="thread")
def test_unused_evaluator_releases_its_actors() -> None:
    evaluator = RayEvaluator(ToyEnv, num_workers=1, num_cpus_per_worker=0.5)
    evaluator.start()
    actors = evaluator._actors
    del evaluator
    gc.collect()
    assert_dead(actors)


@pytest.mark.timeout(300, method="thread")
def test_new_evaluator_makes_room_or_names_the_cause(toy_ray: RayEvaluator, caplog: pytest.LogCaptureFixture) -> None:
    toy_ray.start()
    policy = toy_policy()
    population = toy_population(policy, 4)
    # toy_ray is idle and holds one CPU: an evaluator that needs both stops its actors (they restart when used).
    with caplog.at_level(logging.WARNING), RayEvaluator(ToyEnv, num_workers=2) as evaluator:
        result = evaluator.evaluate(policy, population, population[0], 1, seed=0)
        assert result.returns.shape == (4, 1)
    assert any("idle Ray actor" in record.getMessage() for record in caplog.records)
    assert toy_ray._actors == []
    # More actors than the cluster can ever place: a warning at once, a clear error after start_timeout, not a hang.
    too_many = RayEvaluator(ToyEnv, num_workers=3, start_timeout=5)
    warning = r"num_workers=3 Ray actors of num_cpus_per_worker=1 CPU\(s\) need 3 CPUs and the Ray cluster has 2 in"
    with (
        pytest.warns(UserWarning, match=warning),
        pytest.raises(RuntimeError, match=r"could not start \d of 3 actor\(s\) within start_timeout=5 s"),
    ):
        too_many.evaluate(policy, population, population[0], 1, seed=0)
    assert too_many._actors == []
    # toy_ray starts again when used.
    assert toy_ray.evaluate(policy, population, population[0], 1, seed=0).returns.shape == (4, 1)


@pytest.mark.timeout(300, method="thread")
def test_worker_count_right_after_a_start_or_a_close(toy_ray: RayEvaluator, caplog: pytest.LogCaptureFixture) -> None:
    # Ray reports the CPUs of actors it just started (or killed) a moment later: one per free CPU must count them
    # anyway, so the number of workers of a new evaluator does not depend on that timing.
    for _ in range(3):
        toy_ray.close()
        toy_ray.start()  # holds one of the two CPUs
        with caplog.at_level(logging.WARNING), RayEvaluator("Pendulum-v1") as first:
            assert first.num_workers == 1
        with caplog.at_level(logging.WARNING), RayEvaluator("Pendulum-v1") as second:
            assert second.num_workers == 1
        # Nothing was stopped to make room: toy_ray kept its actors.
        assert not [r for r in caplog.records if "idle Ray actor" in r.getMessage()]
        assert len(toy_ray._actors) == 2


_DRIVER_PID = os.getpid()


def _shaping_only_here(fields: dict[str, Any]) -> RewardShaping:
    if os.getpid() != _DRIVER_PID:
        raise ImportError("No module named 'my_package' (missing where the actor runs)")
    return RewardShaping(**fields)


class ShapingFromMissingModule(RewardShaping):
    """A shaping that cannot be unpickled in an actor, as if its module were missing there."""

    def __reduce__(self) -> Any:
        return _shaping_only_here, (dict(reward_clip=self.reward_clip),)


class FakeShare:
    """Stands for ``ShareRunner.run`` in a :class:`RayWorker`: a share of ``seconds``, then lingering (or an error)."""

    def __init__(self, seconds: float = 0.0, error: bool = False) -> None:
        self.seconds = seconds
        self.error = error
        self.lingered = 0

    def __call__(self, payload: Any, jobs: Any, seed: int, share_done: Any, keep_lingering: Any) -> dict[str, Any]:
        time.sleep(self.seconds)
        if self.error:
            raise ValueError("the env failed")
        share_done()
        while keep_lingering():
            self.lingered += 1
            time.sleep(0.001)
        return {"lingered": self.lingered}


def in_thread(fn: Any, *args: Any) -> tuple[threading.Thread, list[Any]]:
    """:return: A started thread running ``fn(*args)``, and the list its return value or error goes to."""
    out: list[Any] = []

    def run() -> None:
        try:
            out.append(fn(*args))
        except Exception as e:
            out.append(e)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, out


@pytest.mark.timeout(60, method="thread")
def test_actor_signals_in_any_order(monkeypatch: pytest.MonkeyPatch) -> None:
    # Ray does not order an actor's calls across concurrency groups: stop() and jobs_done() may run before
    # evaluate() starts or after it returned. Neither may leave the actor lingering, nor jobs_done() waiting.
    worker = RayWorker(env_config(ToyEnv, 1))
    share = FakeShare()
    monkeypatch.setattr(worker.runner, "run", share)
    worker.stop(1)  # before the share began: no lingering
    assert worker.evaluate({}, np.arange(2), 0, token=1) == {"lingered": 0}
    assert worker.jobs_done(1) is False  # after the evaluation returned: at once (its result tells)
    worker.stop(1)  # too late: ignored, and the next generation still lingers until its own stop
    share.seconds = 0.05
    waiting, done = in_thread(worker.jobs_done, 2)
    evaluating, result = in_thread(worker.evaluate, {}, np.arange(2), 0, 2)
    waiting.join(10)
    assert done == [True]
    time.sleep(0.05)
    assert evaluating.is_alive()  # lingering
    worker.stop(2)
    evaluating.join(10)
    assert result[0]["lingered"] > 0
    # A failed share: the waiting jobs_done() returns False, and the error is the evaluation's result.
    monkeypatch.setattr(worker.runner, "run", FakeShare(seconds=0.05, error=True))
    waiting, done = in_thread(worker.jobs_done, 3)
    with pytest.raises(ValueError, match="the env failed"):
        worker.evaluate({}, np.arange(2), 0, token=3)
    waiting.join(10)
    assert done == [False]
    assert not worker._generations  # nothing kept for generations whose evaluation returned


@pytest.mark.timeout(300, method="thread")
def test_generation_data_that_actors_cannot_load_is_an_error() -> None:
    # With several actors the driver waits for each to finish its share; one whose arguments cannot be unpickled
    # never starts it: its error is raised at once, not after generation_timeout (nor never, without one).
    policy = toy_policy()
    population = toy_population(policy, 4)
    shaping = ShapingFromMissingModule(reward_clip=(-1.0, 1.0))
    # A driver that waited for the shares to be done would raise a TimeoutError after generation_timeout (far above
    # what the error takes to come, below the test's timeout), which does not match.
    with RayEvaluator(ToyEnv, num_workers=2, num_cpus_per_worker=0.5, generation_timeout=200) as evaluator:
        with pytest.raises(Exception, match="my_package") as info:
            evaluator.evaluate(policy, population, population[0], 1, seed=0, shaping=shaping)
        assert not isinstance(info.value, TimeoutError)
    # linger=False is accepted, as by the worker processes: no actor lingers once its share is done.
    with RayEvaluator(ToyEnv, num_workers=2, num_cpus_per_worker=0.5, linger=False) as evaluator:
        result = evaluator.evaluate(policy, population, population[0], 1, seed=0)
        assert result.returns.shape == (4, 1)
        assert evaluator.last_timings["linger_times"] == [0.0, 0.0]


def test_bad_arguments() -> None:
    # Each is named, with what to give instead (not a comparison error between a str and an int).
    for wrong in ("1", None):
        with pytest.raises(TypeError, match=rf"num_cpus_per_worker={wrong!r}: it must be a number"):
            RayEvaluator(ToyEnv, num_cpus_per_worker=wrong)  # type: ignore[arg-type]
    for wrong in (0, math.inf, math.nan):
        with pytest.raises(ValueError, match=rf"num_cpus_per_worker={wrong}: it must be a positive number"):
            RayEvaluator(ToyEnv, num_cpus_per_worker=wrong)
    with pytest.raises(TypeError, match=r"start_timeout=None: it must be a number"):
        RayEvaluator(ToyEnv, start_timeout=None)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"generation_timeout='10': it must be a number"):
        RayEvaluator(ToyEnv, generation_timeout="10")  # type: ignore[arg-type]
    for wrong in ("x", [("num_cpus", 2)]):  # a bare dict() error, or taken
        with pytest.raises(TypeError, match=rf"ray_init_kwargs={re.escape(repr(wrong))}: it must be a dict of keyword"):
            RayEvaluator(ToyEnv, ray_init_kwargs=wrong)  # type: ignore[arg-type]
    assert RayEvaluator(ToyEnv, ray_init_kwargs=None).ray_init_kwargs == {}
    # make_vec_env's arguments are checked as for the worker processes (test_processes.py).
    with pytest.raises(TypeError, match=r"vec_env_cls='DummyVecEnv': pass the VecEnv class itself, not its name"):
        RayEvaluator(ToyEnv, vec_env_cls="DummyVecEnv")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"env_kwargs=\[1\]: it must be a dict of keyword arguments"):
        RayEvaluator(ToyEnv, env_kwargs=[1])  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"wrapper_class=3: it must be a gym.Wrapper class"):
        RayEvaluator(ToyEnv, wrapper_class=3)  # type: ignore[arg-type]
    # The worker processes' name for it is not taken for an env argument.
    with pytest.raises(TypeError, match="max_worker_restarts: that is ProcessEvaluator's; this evaluator's is max_act"):
        RayEvaluator(ToyEnv, max_worker_restarts=1)  # type: ignore[call-arg]


@pytest.mark.timeout(300, method="thread")
def test_subproc_vec_env_in_an_actor() -> None:
    # Unlike a worker process, an actor is no daemon: its envs may run in processes of their own, which end with it.
    policy = toy_policy()
    population = toy_population(policy, 4)
    local = VecEnvEvaluator(make_vec_env(ToyEnv, n_envs=2)).evaluate(policy, population, population[0], 1, seed=0)
    evaluator = RayEvaluator(
        ToyEnv, num_workers=1, envs_per_worker=2, num_cpus_per_worker=0.5, vec_env_cls=SubprocVecEnv
    )
    with evaluator:
        result = evaluator.evaluate(policy, population, population[0], 1, seed=0)
        # Its rewards come as float64 (DummyVecEnv's as float32): the same up to float32 rounding.
        np.testing.assert_allclose(result.returns, local.returns, rtol=1e-6)
        [pids] = evaluator.call_workers(lambda venv: [process.pid for process in venv.processes])
    assert len(pids) == 2
    assert wait_gone(pids, timeout=60)  # the env processes see their pipes close when the actor is killed


#: The ray.init arguments of the ray_cluster fixture (conftest.py): a test that restarts Ray restarts it so.
CLUSTER_INIT_KWARGS: dict[str, Any] = dict(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)


@pytest.mark.timeout(300, method="thread")
def test_ray_restarted_by_the_user(toy_ray: RayEvaluator, caplog: pytest.LogCaptureFixture) -> None:
    # An evaluator whose actors belonged to an earlier Ray session starts new ones, and closing it does not shut down
    # the session the user started since. That session is started as the ray_cluster fixture's (and so again should
    # the test fail midway), and toy_ray's actors are started again in it: the later tests find what they found.
    policy = toy_policy()
    population = toy_population(policy, 4)
    toy_ray.close()
    ray.shutdown()
    evaluator = RayEvaluator(ToyEnv, num_workers=1, ray_init_kwargs=CLUSTER_INIT_KWARGS)
    try:
        evaluator.evaluate(policy, population, population[0], 1, seed=0)  # starts Ray
        ray.shutdown()
        ray.init(**CLUSTER_INIT_KWARGS)  # the user's own session
        result = evaluator.evaluate(policy, population, population[0], 1, seed=0)
        assert result.returns.shape == (4, 1)
        evaluator.close()
        assert ray.is_initialized()
        # ray_init_kwargs that cannot apply, since Ray runs: said, not silently ignored.
        with caplog.at_level(logging.WARNING), RayEvaluator(ToyEnv, num_workers=1, ray_init_kwargs=dict(num_cpus=1)):
            pass
        assert any("were not applied" in record.getMessage() for record in caplog.records)
    finally:
        evaluator.close()  # shuts Ray down if the evaluator started it
        if not ray.is_initialized():
            ray.init(**CLUSTER_INIT_KWARGS)
        toy_ray.start()
    assert ray.cluster_resources().get("CPU") == 2 and len(toy_ray._actors) == 2
