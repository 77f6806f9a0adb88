"""The sharded evaluator on each host (worker processes, Ray actors): same results as the local engine, callbacks
replayed, dead workers replaced, errors and interrupts handled."""

from __future__ import annotations

import functools
import logging
import math
import os
import signal
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from algorithms import progress_bar_after_learn
from envs import IMAGE_ID, CrashingToyEnv, NeverEndingEnv, SpaceEnv, StepCounter, ToyEnv
from gymnasium import spaces
from sharded_helpers import (
    ENVS_PER_WORKER,
    ReplayCounter,
    assert_same_candidates,
    learn_generations,
    make_ars,
    remote_steps,
    toy_policy,
    toy_population,
)
from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecTransposeImage

from sb3_es.common.policies import MlpPolicy
from sb3_es.evaluation import VecEnvEvaluator, sharded
from sb3_es.evaluation.process_worker import RemoteTraceback
from sb3_es.evaluation.processes import ProcessEvaluator
from sb3_es.evaluation.sharded import ShardedEvaluator
from sb3_es.evaluation.worker import DEFAULT_ENVS_PER_WORKER
from sb3_es.strategies.noise import NoiseTablePopulation, SharedNoiseTable

HOSTS = ["processes", pytest.param("ray", marks=pytest.mark.ray)]


@pytest.fixture(scope="module", params=HOSTS)
def host(request: pytest.FixtureRequest) -> str:
    if request.param == "ray":
        ray = request.getfixturevalue("ray_cluster")
        # The envs defined here cannot be imported by Ray workers: ship them by value.
        ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    return request.param


def make_evaluator(host: str, env: Any, **kwargs: Any) -> ShardedEvaluator:
    if host == "ray":
        from sb3_es.evaluation.ray import RayEvaluator

        # Half a CPU each: two such evaluators fit in the 2-CPU test cluster.
        return RayEvaluator(env, num_cpus_per_worker=0.5, **kwargs)
    return ProcessEvaluator(env, **kwargs)


def kill_worker(evaluator: ShardedEvaluator, k: int) -> None:
    """Kill worker ``k`` from outside, as the OOM killer or a lost node would."""
    if isinstance(evaluator, ProcessEvaluator):
        os.kill(evaluator._workers[k].pid, signal.SIGKILL)
        evaluator._workers[k].join()
    else:
        import ray

        ray.kill(evaluator._actors[k])  # type: ignore[attr-defined]


def workers(evaluator: ShardedEvaluator) -> list[Any]:
    if isinstance(evaluator, ProcessEvaluator):
        return evaluator._workers
    return evaluator._actors  # type: ignore[attr-defined]


class HeldToyEnv(CrashingToyEnv):
    """
    ``CrashingToyEnv`` (the first env to reach ``crash_step``, in any worker, dies or raises there) whose other envs
    wait at that step until the file ``release`` exists: the other workers' shares cannot end before the test says.
    """

    def __init__(self, release: str, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.release = release

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        result = super().step(action)
        if self.steps == self.crash_step:
            while not os.path.exists(self.release):
                time.sleep(0.005)
        return result


def share_steps(policy: Any, population: np.ndarray, center: np.ndarray, k: int, n_shares: int = 2) -> int:
    """:return: The env steps of ToyEnv share ``k`` without lingering (the local engine on a worker's slots)."""
    share = np.array_split(np.arange(len(population)), n_shares)[k]
    local = VecEnvEvaluator(make_vec_env(ToyEnv, n_envs=DEFAULT_ENVS_PER_WORKER))
    return local.evaluate(policy, population[share], center, 1, seed=0).n_steps


def stops_delivered(evaluator: ShardedEvaluator, monkeypatch: pytest.MonkeyPatch) -> Callable[[], None]:
    """
    :return: A function that waits until the stop-lingering signals sent so far have reached the workers: a worker
        process's is a shared integer, set at once; a Ray actor's is a call, run when Ray runs it.
    """
    if isinstance(evaluator, ProcessEvaluator):
        return lambda: None
    import ray

    pool: Any = evaluator.pool
    sent: list[Any] = []

    def stop_lingering(k: int, token: int) -> None:  # RayActorPool.stop_lingering, keeping the call's reference
        sent.append(pool.actors[k].stop.options(concurrency_group="signal").remote(token))

    def wait() -> None:
        ray.get(sent)

    monkeypatch.setattr(pool, "stop_lingering", stop_lingering)
    return wait


@pytest.fixture(scope="module")
def toy(host: str) -> Iterator[ShardedEvaluator]:
    """Two workers with two ToyEnv slots each, counting steps."""
    evaluator = make_evaluator(
        host,
        ToyEnv,
        num_workers=2,
        envs_per_worker=ENVS_PER_WORKER,
        wrapper_class=StepCounter,
        wrapper_kwargs=dict(counter=[0]),
    )
    with evaluator:
        yield evaluator


def test_same_results_as_local_engine(toy: ShardedEvaluator) -> None:
    policy = toy_policy()
    population = toy_population(policy, 7)
    center = population.mean(axis=0)
    remote_steps(toy)
    calls: list[int] = []

    def hook(n_envs: int, infos: list[dict[str, Any]], dones: np.ndarray, *_: Any) -> bool:
        calls.append(n_envs)
        return True

    result = toy.evaluate(policy.network_spec(), population, center, 2, seed=5, step_hook=hook)
    local = VecEnvEvaluator(make_vec_env(ToyEnv, n_envs=4)).evaluate(policy, population, center, 2, seed=5)
    assert_same_candidates(result, local)
    # Every env step taken remotely is counted once, and the hook ran once per remote vec step.
    assert result.n_steps == remote_steps(toy) == sum(calls) == sum(toy.last_timings["n_steps"])
    assert len(calls) == result.n_steps // ENVS_PER_WORKER
    assert len(toy.last_timings["eval_times"]) == 2
    # With two shares, each worker, once its share is done, runs the center policy until the driver has seen
    # both shares done (those steps are in n_steps and in the replay above).
    assert all(t > 0 for t in toy.last_timings["linger_times"])

    # A single share runs on worker 0 with the generation's seed: bit for bit the local engine on 2 envs,
    # center-policy episodes and step count included.
    one = toy.evaluate(policy, population[:1], center, 1, seed=5)
    local_one = VecEnvEvaluator(make_vec_env(ToyEnv, n_envs=ENVS_PER_WORKER)).evaluate(
        policy, population[:1], center, 1, seed=5
    )
    assert_same_candidates(one, local_one)
    np.testing.assert_array_equal(one.obs_stats.mean, local_one.obs_stats.mean)
    assert one.n_steps == local_one.n_steps
    assert one.center_returns == local_one.center_returns
    assert toy.last_timings["linger_times"] == [0.0]


def test_noise_table_population(toy: ShardedEvaluator) -> None:
    policy = toy_policy()
    table = SharedNoiseTable(size=10_000, seed=3)
    rng = np.random.default_rng(1)
    offsets = np.repeat(table.sample_offsets(rng, policy.num_params, 3), 2)
    scales = np.tile([0.3, -0.3], 3)
    center = rng.normal(size=policy.num_params) * 0.1
    population = NoiseTablePopulation(table, center, offsets, scales)
    dense = np.asarray(population)
    assert population.shape == dense.shape == (6, policy.num_params)
    noise = table.get(offsets[1], policy.num_params).astype(np.float64)
    np.testing.assert_array_equal(dense[1], center - 0.3 * noise)
    from_table = toy.evaluate(policy, population, center, 1, seed=2)
    from_rows = toy.evaluate(policy, dense, center, 1, seed=2)
    np.testing.assert_array_equal(from_table.returns, from_rows.returns)
    np.testing.assert_array_equal(from_table.obs_stats.mean, from_rows.obs_stats.mean)


def test_ars_same_parameters_as_local(toy: ShardedEvaluator) -> None:
    local = make_ars(make_vec_env(ToyEnv, n_envs=2))
    remote = make_ars(make_vec_env(ToyEnv, n_envs=2), evaluator=toy)
    learn_generations(local, 2)
    learn_generations(remote, 2)
    assert local._n_updates == remote._n_updates == 2
    assert not np.array_equal(local.strategy.center, np.zeros_like(local.strategy.center))
    np.testing.assert_array_equal(remote.strategy.center, local.strategy.center)
    # Same observations; the float64 statistics differ only by the order of the merges.
    np.testing.assert_allclose(remote.policy.obs_mean.numpy(), local.policy.obs_mean.numpy(), rtol=1e-12)
    np.testing.assert_allclose(remote.policy.obs_var.numpy(), local.policy.obs_var.numpy(), rtol=1e-12)
    assert remote.policy.obs_count.item() == local.policy.obs_count.item()


def test_timesteps_and_callbacks(toy: ShardedEvaluator) -> None:
    model = make_ars(ToyEnv(), evaluator=toy)
    callback = ReplayCounter()
    remote_steps(toy)
    learn_generations(model, 2, callback)
    steps = remote_steps(toy)
    assert model.num_timesteps == callback.steps == steps
    # on_step once per env step of the model env's single slot; each episode's end appears in the replayed dones.
    assert callback.n_calls == steps
    assert callback.dones >= 2 * 2 * model.n_delta


class CallSizes(BaseCallback):
    """The env steps (``n_envs``) of each ``on_step`` call, one list per generation."""

    def __init__(self) -> None:
        super().__init__()
        self.sizes: list[list[int]] = []

    def _on_rollout_start(self) -> None:
        self.sizes.append([])

    def _on_step(self) -> bool:
        assert len(self.locals["infos"]) == len(self.locals["dones"]) == len(self.locals["rewards"])
        self.sizes[-1].append(self.locals["n_envs"])
        return True


@pytest.mark.parametrize("n_envs", [1, 3])
def test_callback_calls_have_the_model_envs_size(toy: ShardedEvaluator, n_envs: int) -> None:
    """The workers' vec steps (ENVS_PER_WORKER slots) reach the callbacks as calls of the model env's num_envs
    steps, as SB3's callbacks count them; a generation's last call may have fewer."""
    model = make_ars(make_vec_env(ToyEnv, n_envs=n_envs), evaluator=toy)
    callback = CallSizes()
    remote_steps(toy)
    learn_generations(model, 2, callback)
    assert sum(map(sum, callback.sizes)) == model.num_timesteps == remote_steps(toy)
    assert len(callback.sizes) == 2
    for sizes in callback.sizes:
        assert set(sizes[:-1]) == {n_envs} and 0 < sizes[-1] <= n_envs


def test_checkpoints_at_the_env_steps_asked(toy: ShardedEvaluator, tmp_path: Path) -> None:
    """SB3's CheckpointCallback saves every save_freq calls, that is every save_freq * num_envs env steps, as with
    the local evaluator (rl-zoo sizes its eval_freq and save_freq so)."""
    model = make_ars(ToyEnv(), evaluator=toy)
    model.learn(60, callback=CheckpointCallback(save_freq=7, save_path=str(tmp_path)))
    saved = sorted(int(path.stem.split("_")[2]) for path in tmp_path.glob("rl_model_*_steps.zip"))
    assert saved == list(range(7, model.num_timesteps + 1, 7))


def test_progress_bar_counts_the_workers_steps(toy: ShardedEvaluator) -> None:
    """The workers' vec steps are of ENVS_PER_WORKER slots, the model env's of one: the bar counts env steps."""
    model = make_ars(ToyEnv(), evaluator=toy)
    pbar = progress_bar_after_learn(model, 1)
    assert pbar.n == model.num_timesteps > ENVS_PER_WORKER


def test_callback_stops_training(toy: ShardedEvaluator) -> None:
    model = make_ars(ToyEnv(), evaluator=toy)
    start = model.policy.parameters_to_vector()
    callback = ReplayCounter(stop_at=3)
    model.learn(10_000, callback=callback)
    # The stop request takes effect once the generation is back: the replay stops there and the
    # generation is discarded, as with the local engine.
    assert callback.n_calls == 3
    assert model.num_timesteps == 3  # calls of the model env's single slot
    assert model._n_updates == 0
    np.testing.assert_array_equal(model.policy.parameters_to_vector(), start)


def test_episodes_without_time_limit_are_cut_in_the_workers(host: str) -> None:
    """A factory without a time limit: the workers cut the episodes at the model's max_episode_steps."""
    evaluator = make_evaluator(host, NeverEndingEnv, num_workers=1, envs_per_worker=2)
    model = make_ars(make_vec_env(NeverEndingEnv, n_envs=2), evaluator=evaluator, max_episode_steps=15)
    counter = ReplayCounter()
    with evaluator:
        model.learn(100, callback=counter)
    assert model.num_timesteps >= 100
    # Every candidate's episode ended at the cap, in a worker, and the replay showed its done.
    assert model.ep_info_buffer is not None and {info["l"] for info in model.ep_info_buffer} == {15}
    assert counter.dones >= 6


IMAGE_ENV = functools.partial(SpaceEnv, spaces.Box(0, 255, (6, 6, 3), np.uint8), spaces.Box(-1, 1, (1,)), 100)


def test_image_observations_are_transposed_as_sb3_does(host: str) -> None:
    """SB3 wraps a model env of channels-last images in VecTransposeImage: the workers do the same, and common seeds
    and the episode cap work through it, with the local engine's results."""
    kwargs: dict[str, Any] = dict(common_seeds=True, max_episode_steps=7, n_eval_episodes=2)
    local = make_ars(make_vec_env(IMAGE_ENV, n_envs=ENVS_PER_WORKER), **kwargs)
    assert isinstance(local.env, VecTransposeImage)
    learn_generations(local, 2)
    with make_evaluator(host, IMAGE_ENV, num_workers=1, envs_per_worker=ENVS_PER_WORKER) as evaluator:
        remote = make_ars(make_vec_env(IMAGE_ENV, n_envs=1), evaluator=evaluator, **kwargs)
        learn_generations(remote, 2)
    np.testing.assert_array_equal(remote.strategy.center, local.strategy.center)
    assert remote.ep_info_buffer is not None and {info["l"] for info in remote.ep_info_buffer} == {7}
    if host == "processes":  # by name, the workers rebuild the model's VecEnv (its VecTransposeImage was SB3's)
        by_name = make_ars(make_vec_env(IMAGE_ID, n_envs=ENVS_PER_WORKER), evaluator=host, **kwargs)
        learn_generations(by_name, 2)
        by_name._evaluator.close()
        assert by_name.ep_info_buffer is not None and {info["l"] for info in by_name.ep_info_buffer} == {7}


def test_reset_seeds_same_episodes_as_local(host: str) -> None:
    """With reset seeds (common_seeds), each job starts from its own seed's state, wherever it runs."""
    env = make_vec_env("Pendulum-v1", n_envs=1)
    policy = MlpPolicy(env.observation_space, env.action_space, net_arch=[4])
    population = np.random.default_rng(0).normal(scale=0.3, size=(5, policy.num_params))
    reset_seeds = np.arange(10).reshape(5, 2) % 3  # repeated seeds across candidates and episodes
    local = VecEnvEvaluator(make_vec_env("Pendulum-v1", n_envs=3)).evaluate(
        policy, population, population[0], 2, seed=1, reset_seeds=reset_seeds
    )
    with make_evaluator(host, "Pendulum-v1", num_workers=2, envs_per_worker=2) as evaluator:
        remote = evaluator.evaluate(policy, population, population[0], 2, seed=2, reset_seeds=reset_seeds)
    np.testing.assert_allclose(remote.returns, local.returns, rtol=1e-6)
    assert not np.allclose(local.returns[:, 0], local.returns[0, 0])


def test_no_lingering_after_a_death(host: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A worker still running its share when another dies does not linger through the replacement's start-up."""
    release = str(tmp_path / "release")
    policy = toy_policy()
    population = toy_population(policy, 8, seed=3)
    center = np.zeros(policy.num_params)
    local = VecEnvEvaluator(make_vec_env(ToyEnv, n_envs=2)).evaluate(policy, population, center, 1, seed=0)

    def held_env() -> HeldToyEnv:  # one worker dies at its second step; the other waits there until released
        return HeldToyEnv(release, str(tmp_path / "crashed"), str(tmp_path / "no_error"), crash_step=2)

    with make_evaluator(host, held_env, num_workers=2) as evaluator:
        evaluator.start()
        replace, delivered = evaluator.pool.replace, stops_delivered(evaluator, monkeypatch)
        replaced: list[int] = []

        def replace_after_releasing(k: int) -> None:  # the survivor's share ends while the replacement starts
            replaced.append(k)
            delivered()
            Path(release).touch()
            replace(k)

        monkeypatch.setattr(evaluator.pool, "replace", replace_after_releasing)
        result = evaluator.evaluate(policy, population, center, 1, seed=0)
        assert evaluator.restarted_workers == 1 and len(replaced) == 1
        assert_same_candidates(result, local)
        # Told to stop lingering before its share could end: the survivor ran its share's steps, not one more.
        survivor = 1 - replaced[0]
        expected = share_steps(policy, population, center, survivor)
        assert evaluator.last_timings["n_steps"][survivor] == expected, evaluator.last_timings


def test_an_env_error_is_raised_at_once(host: str, tmp_path: Path) -> None:
    """One worker's env raises at its first step while the other's share cannot end: the error comes at once, not
    once the other share is done (nor as a TimeoutError hiding it)."""
    release = str(tmp_path / "release")
    policy = toy_policy()
    population = toy_population(policy, 8, seed=3)

    def held_env() -> HeldToyEnv:
        return HeldToyEnv(release, str(tmp_path / "raised"), str(tmp_path / "no_error"), crash_step=1, raise_once=True)

    # The other share waits until released, which comes only after evaluate() has returned: a driver that waited
    # for it would raise a TimeoutError (after generation_timeout, far above what the error takes to come).
    try:
        with make_evaluator(host, held_env, num_workers=2, generation_timeout=120.0) as evaluator:
            with pytest.raises(ValueError, match="env error raised once inside a worker"):
                evaluator.evaluate(policy, population, population[0], 1, seed=0)
            assert workers(evaluator) == []
    finally:
        Path(release).touch()


def test_an_env_that_cannot_be_built_raises_its_own_error(host: str) -> None:
    """An unknown env id gives the worker's gymnasium error with the hint for envs registered by a script (on Ray it
    was an ActorDiedError: an error raised in an actor's constructor loses its type)."""
    evaluator = make_evaluator(host, "NoSuchEnv-v0", num_workers=1)
    with pytest.raises(gym.error.NameNotFound, match=r"NoSuchEnv.*\(in a worker process\)\. An env registered"):
        evaluator.start()
    assert workers(evaluator) == []


def test_a_replacements_start_is_not_counted_in_generation_timeout(
    host: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A worker dies; its replacement takes longer to start than the whole generation_timeout (start_timeout bounds
    it): the generation completes."""
    policy = toy_policy()
    population = toy_population(policy, 4)

    def env() -> CrashingToyEnv:
        return CrashingToyEnv(str(tmp_path / "crashed"), str(tmp_path / "no_error"), crash_step=2)

    with make_evaluator(host, env, num_workers=2, envs_per_worker=2, generation_timeout=1.0) as evaluator:
        replace = evaluator._replace

        def slow_replace(*args: Any) -> None:
            time.sleep(1.5)
            replace(*args)

        monkeypatch.setattr(evaluator, "_replace", slow_replace)
        result = evaluator.evaluate(policy, population, population[0], 1, seed=0)
        assert evaluator.restarted_workers == 1
        assert len(result.returns) == 4


def test_timeouts_without_a_limit(host: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """math.inf is no limit; a timeout beyond what the OS (about 24 days) or Ray take is waited in pieces."""
    assert make_evaluator(host, ToyEnv, generation_timeout=math.inf).generation_timeout is None
    policy = toy_policy()
    population = toy_population(policy, 4)
    local = VecEnvEvaluator(make_vec_env(ToyEnv, n_envs=4)).evaluate(policy, population, population[0], 1, seed=0)
    with make_evaluator(host, ToyEnv, num_workers=2, start_timeout=math.inf, generation_timeout=1e12) as evaluator:
        assert evaluator.generation_timeout == 1e12
        assert_same_candidates(evaluator.evaluate(policy, population, population[0], 1, seed=0), local)
        # Pieces far shorter than the waits: each wait goes on after its pieces that end with nothing ready.
        monkeypatch.setattr(sharded, "MAX_WAIT", 0.001)
        assert_same_candidates(evaluator.evaluate(policy, population, population[0], 1, seed=0), local)
        assert evaluator.restarted_workers == 0


@pytest.mark.parametrize(
    "error", [SystemExit(3), KeyboardInterrupt("raised by the env")], ids=["SystemExit", "KeyboardInterrupt"]
)
def test_an_exit_raised_by_the_env_is_raised_not_retried(host: str, error: BaseException) -> None:
    """SystemExit and KeyboardInterrupt raised by the env's code (workers ignore SIGINT) are env errors: raised
    in the driver with the worker's traceback, not taken for a dead worker (nor, on Ray, for a cancellation)."""
    policy = toy_policy()
    population = toy_population(policy, 4)

    class ExitingEnv(ToyEnv):
        def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
            raise error

    def exit_in_call(venv: Any) -> None:
        raise error

    restarts = {"max_actor_restarts" if host == "ray" else "max_worker_restarts": 1}
    with make_evaluator(host, ExitingEnv, num_workers=2, envs_per_worker=1, **restarts) as evaluator:
        with pytest.raises(type(error), match=str(error)) as info:
            evaluator.evaluate(policy, population, population[0], 1, seed=0)
        assert "in step" in str(info.value.__cause__)  # the worker's traceback
        assert evaluator.restarted_workers == 0
        assert workers(evaluator) == []
        with pytest.raises(type(error), match=str(error)) as info:
            evaluator.call_workers(exit_in_call)
        assert "in exit_in_call" in str(info.value.__cause__)
        assert evaluator.restarted_workers == 0


def test_faults(host: str, tmp_path: Path, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch) -> None:
    crash_flag, error_flag, release = str(tmp_path / "crashed"), str(tmp_path / "error"), str(tmp_path / "release")
    policy = toy_policy()
    population = toy_population(policy, 8, seed=3)
    center = np.zeros(policy.num_params)
    local = VecEnvEvaluator(make_vec_env(ToyEnv, n_envs=2)).evaluate(policy, population, center, 1, seed=0)

    def crashing_env() -> HeldToyEnv:
        return HeldToyEnv(release, crash_flag, error_flag, crash_step=2)

    with make_evaluator(host, crashing_env, num_workers=2) as evaluator:
        # One worker's process dies mid-generation: it is replaced and its share re-run. The other worker's share
        # is held until the driver, having seen the death, starts the replacement: told at once to stop lingering,
        # it runs no center-policy steps while the replacement starts and re-runs the dead worker's share (tens of
        # thousands per second on ToyEnv would count otherwise).
        replace, delivered = evaluator.pool.replace, stops_delivered(evaluator, monkeypatch)
        replaced: list[int] = []

        def replace_after_releasing(k: int) -> None:
            replaced.append(k)
            delivered()
            Path(release).touch()
            replace(k)

        monkeypatch.setattr(evaluator.pool, "replace", replace_after_releasing)
        with caplog.at_level(logging.WARNING):
            result = evaluator.evaluate(policy, population, center, 1, seed=0)
        monkeypatch.undo()
        assert os.path.exists(crash_flag)
        assert evaluator.restarted_workers == 1 and len(replaced) == 1
        assert any("died" in record.getMessage() for record in caplog.records)
        assert_same_candidates(result, local)
        survivor = 1 - replaced[0]
        expected = share_steps(policy, population, center, survivor)
        assert evaluator.last_timings["n_steps"][survivor] == expected, evaluator.last_timings

        # A worker killed between generations is replaced too.
        kill_worker(evaluator, 1)
        result = evaluator.evaluate(policy, population, center, 1, seed=0)
        assert evaluator.restarted_workers == 2
        assert_same_candidates(result, local)

        # An exception raised by the env is not retried: it reaches the driver, and the workers are stopped.
        Path(error_flag).touch()
        with pytest.raises(ValueError, match="env error raised inside a worker") as error:
            evaluator.evaluate(policy, population, center, 1, seed=0)
        if host == "processes":  # with the worker's traceback (Ray puts it in the message)
            assert isinstance(error.value.__cause__, RemoteTraceback)
            assert "in step" in str(error.value.__cause__) and "CrashingToyEnv" not in str(error.value)
        assert workers(evaluator) == []
        assert evaluator.restarted_workers == 2

        # A KeyboardInterrupt while waiting for the workers stops them (fresh ones are started next time).
        os.remove(error_flag)
        evaluator.start()
        running = workers(evaluator)

        def interrupted(*args: Any, **kwargs: Any) -> Any:
            raise KeyboardInterrupt

        monkeypatch.setattr(evaluator.pool, "wait_share_done", interrupted)
        with pytest.raises(KeyboardInterrupt):
            evaluator.evaluate(policy, population, center, 1, seed=0)
        assert workers(evaluator) == []
        if host == "processes":
            assert not any(process.is_alive() for process in running)
        monkeypatch.undo()
        assert_same_candidates(evaluator.evaluate(policy, population, center, 1, seed=0), local)
    assert workers(evaluator) == []
