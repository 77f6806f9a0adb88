"""Population evaluation on Ray actors: same results as the local engine, fault tolerance, callbacks, save/load."""

from __future__ import annotations

import gc
import logging
import os
import subprocess
import sys
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

ray = pytest.importorskip("ray")

import envs  # noqa: E402
from envs import StepCounter, ToyEnv  # noqa: E402
from stable_baselines3.common.callbacks import BaseCallback  # noqa: E402
from stable_baselines3.common.env_util import make_vec_env  # noqa: E402
from stable_baselines3.common.vec_env import VecEnv  # noqa: E402

from sb3_es import ARS  # noqa: E402
from sb3_es.common.policies import MlpPolicy  # noqa: E402
from sb3_es.evaluation import PopulationResult, VecEnvEvaluator  # noqa: E402
from sb3_es.evaluation.ray import RayEvaluator  # noqa: E402
from sb3_es.strategies.noise import NoiseTablePopulation, SharedNoiseTable  # noqa: E402

pytestmark = pytest.mark.ray

ENVS_PER_WORKER = 2
POLICY_KWARGS = dict(net_arch=[8])


class CrashingToyEnv(ToyEnv):
    """
    ``ToyEnv`` whose process dies (``os._exit``) at its ``crash_step``-th step if ``crash_flag`` can still be
    created (so exactly one env, in one actor, dies once), and which raises ``ValueError`` while ``error_flag``
    exists.
    """

    def __init__(self, crash_flag: str, error_flag: str, crash_step: int = 5) -> None:
        super().__init__()
        self.crash_flag = crash_flag
        self.error_flag = error_flag
        self.crash_step = crash_step
        self.steps = 0

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        self.steps += 1
        if self.steps == self.crash_step:
            try:
                os.close(os.open(self.crash_flag, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            except FileExistsError:
                pass
            else:
                os._exit(1)
        if os.path.exists(self.error_flag):
            raise ValueError("env error raised inside a Ray actor")
        return super().step(action)


@pytest.fixture(scope="module", autouse=True)
def ray_session() -> Iterator[None]:
    # The test helpers live in modules that Ray workers cannot import: ship them by value.
    ray.cloudpickle.register_pickle_by_value(envs)
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    # address="local": a new instance, even if a cluster started with `ray start` runs on this machine.
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


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


def remote_steps(evaluator: RayEvaluator) -> int:
    """:return: Env steps counted by the actors' ``StepCounter`` wrappers since the last call (then reset)."""

    def read_and_reset(venv: VecEnv) -> int:
        counter = venv.get_attr("counter")[0]
        count, counter[0] = counter[0], 0
        return count

    return sum(evaluator.call_workers(read_and_reset))


def toy_policy() -> MlpPolicy:
    env = ToyEnv()
    policy = MlpPolicy(env.observation_space, env.action_space, **POLICY_KWARGS)
    # Non-trivial observation statistics, so that the actors must receive them to act as locally.
    policy.update_obs_rms(np.array([0.2, 0.3]), np.array([0.5, 0.2]), 10)
    return policy


def toy_population(policy: MlpPolicy, n: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(scale=0.5, size=(n, policy.num_params))


def assert_same_candidates(ray_result: PopulationResult, local: PopulationResult) -> None:
    np.testing.assert_array_equal(ray_result.returns, local.returns)
    np.testing.assert_array_equal(ray_result.lengths, local.lengths)
    assert ray_result.obs_stats.count == local.obs_stats.count
    # The same moments; only the order of the float64 merges differs.
    np.testing.assert_allclose(ray_result.obs_stats.mean, local.obs_stats.mean, rtol=1e-12)
    np.testing.assert_allclose(ray_result.obs_stats.var, local.obs_stats.var, rtol=1e-10)
    assert len(ray_result.ep_infos) == len(local.ep_infos)
    assert not ray_result.stopped


class Counter(BaseCallback):
    """Counts ``on_step`` calls and the env steps they report; returns False at call ``stop_at``."""

    def __init__(self, stop_at: int | None = None) -> None:
        super().__init__()
        self.stop_at = stop_at
        self.steps = 0
        self.dones = 0

    def _on_step(self) -> bool:
        self.steps += self.locals["n_envs"]
        self.dones += int(np.sum(self.locals["dones"]))
        assert len(self.locals["infos"]) == self.locals["n_envs"] == len(self.locals["dones"])
        # The replay gives the remote steps' rewards; observations and actions are not sent back.
        assert np.shape(self.locals["rewards"]) == (self.locals["n_envs"],)
        assert np.all(np.isfinite(self.locals["rewards"]))
        assert self.locals["new_obs"] is None and self.locals["actions"] is None
        return self.stop_at is None or self.n_calls < self.stop_at


def test_same_results_as_local_engine(toy_ray: RayEvaluator) -> None:
    policy = toy_policy()
    population = toy_population(policy, 7)
    center = population.mean(axis=0)
    remote_steps(toy_ray)
    calls: list[int] = []

    def hook(n_envs: int, infos: list[dict[str, Any]], dones: np.ndarray, *_: Any) -> bool:
        calls.append(n_envs)
        return True

    result = toy_ray.evaluate(policy, population, center, 2, seed=5, step_hook=hook)
    local = VecEnvEvaluator(make_vec_env(ToyEnv, n_envs=4)).evaluate(policy, population, center, 2, seed=5)
    assert_same_candidates(result, local)
    # Every env step taken remotely is counted once, and the hook ran once per remote vec step.
    assert result.n_steps == remote_steps(toy_ray) == sum(calls) == sum(toy_ray.last_timings["n_steps"])
    assert len(calls) == result.n_steps // ENVS_PER_WORKER
    assert len(toy_ray.last_timings["eval_times"]) == 2
    # With two shares, each actor, once its share is done, runs the center policy until the driver has seen
    # both shares done (those steps are in n_steps and in the replay above).
    assert all(t > 0 for t in toy_ray.last_timings["linger_times"])

    # A single share runs on actor 0 with the generation's seed: bit for bit the local engine on 2 envs,
    # center-policy episodes and step count included.
    one = toy_ray.evaluate(policy, population[:1], center, 1, seed=5)
    local_one = VecEnvEvaluator(make_vec_env(ToyEnv, n_envs=ENVS_PER_WORKER)).evaluate(
        policy, population[:1], center, 1, seed=5
    )
    assert_same_candidates(one, local_one)
    np.testing.assert_array_equal(one.obs_stats.mean, local_one.obs_stats.mean)
    assert one.n_steps == local_one.n_steps
    assert one.center_returns == local_one.center_returns
    assert toy_ray.last_timings["linger_times"] == [0.0]


def test_noise_table_population(toy_ray: RayEvaluator) -> None:
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
    from_table = toy_ray.evaluate(policy, population, center, 1, seed=2)
    from_rows = toy_ray.evaluate(policy, dense, center, 1, seed=2)
    np.testing.assert_array_equal(from_table.returns, from_rows.returns)
    np.testing.assert_array_equal(from_table.obs_stats.mean, from_rows.obs_stats.mean)


def make_ars(env: Any, **kwargs: Any) -> ARS:
    return ARS("MlpPolicy", env, n_delta=3, seed=1, policy_kwargs=POLICY_KWARGS, **kwargs)


def learn_generations(model: ARS, n: int, callback: BaseCallback | None = None) -> None:
    for i in range(n):
        model.learn(1, callback=callback, reset_num_timesteps=i == 0)


def test_ars_same_parameters_as_local(toy_ray: RayEvaluator) -> None:
    local = make_ars(make_vec_env(ToyEnv, n_envs=2))
    remote = make_ars(make_vec_env(ToyEnv, n_envs=2), evaluator=toy_ray)
    learn_generations(local, 2)
    learn_generations(remote, 2)
    assert local._n_updates == remote._n_updates == 2
    assert not np.array_equal(local.strategy.center, np.zeros_like(local.strategy.center))
    np.testing.assert_array_equal(remote.strategy.center, local.strategy.center)
    # Same observations; the float64 sums differ only by the order of their additions (~1e-18 here).
    np.testing.assert_allclose(remote.policy.obs_mean.numpy(), local.policy.obs_mean.numpy(), rtol=1e-12)
    np.testing.assert_allclose(remote.policy.obs_var.numpy(), local.policy.obs_var.numpy(), rtol=1e-12)
    assert remote.policy.obs_count.item() == local.policy.obs_count.item()


def test_timesteps_and_callbacks(toy_ray: RayEvaluator) -> None:
    model = make_ars(ToyEnv(), evaluator=toy_ray)
    callback = Counter()
    remote_steps(toy_ray)
    learn_generations(model, 2, callback)
    steps = remote_steps(toy_ray)
    assert model.num_timesteps == callback.steps == steps
    # on_step once per remote vec step; each episode's end appears in the replayed dones.
    assert callback.n_calls == steps // ENVS_PER_WORKER
    assert callback.dones >= 2 * 2 * model.n_delta


def test_callback_stops_training(toy_ray: RayEvaluator) -> None:
    model = make_ars(ToyEnv(), evaluator=toy_ray)
    start = model.policy.parameters_to_vector()
    callback = Counter(stop_at=3)
    model.learn(10_000, callback=callback)
    # The stop request takes effect once the generation is back: the replay stops there and the
    # generation is discarded, as with the local engine.
    assert callback.n_calls == 3
    assert model.num_timesteps == 3 * ENVS_PER_WORKER
    assert model._n_updates == 0
    np.testing.assert_array_equal(model.policy.parameters_to_vector(), start)


def test_actor_death_is_survived(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    crash_flag, error_flag = str(tmp_path / "crashed"), str(tmp_path / "error")
    policy = toy_policy()
    population = toy_population(policy, 8, seed=3)
    center = np.zeros(policy.num_params)
    local = VecEnvEvaluator(make_vec_env(ToyEnv, n_envs=2)).evaluate(policy, population, center, 1, seed=0)

    def crashing_env() -> CrashingToyEnv:
        return CrashingToyEnv(crash_flag, error_flag)

    with RayEvaluator(crashing_env, num_workers=2, num_cpus_per_worker=0.5) as evaluator:
        # One actor's process dies mid-generation: it is replaced and its share re-run.
        with caplog.at_level(logging.WARNING, logger="sb3_es.evaluation.ray"):
            result = evaluator.evaluate(policy, population, center, 1, seed=0)
        assert os.path.exists(crash_flag)
        assert evaluator.restarted_actors == 1
        assert any("died" in record.getMessage() for record in caplog.records)
        assert_same_candidates(result, local)

        # An actor killed between generations is replaced too.
        ray.kill(evaluator._actors[1])
        result = evaluator.evaluate(policy, population, center, 1, seed=0)
        assert evaluator.restarted_actors == 2
        assert_same_candidates(result, local)

        # An exception raised by the env is not retried: it reaches the driver, and the actors are dropped.
        Path(error_flag).touch()
        with pytest.raises(ValueError, match="env error raised inside a Ray actor"):
            evaluator.evaluate(policy, population, center, 1, seed=0)
        assert evaluator._actors == []
        assert evaluator.restarted_actors == 2

        # A KeyboardInterrupt while waiting for the actors kills them (fresh ones are created next time).
        os.remove(error_flag)
        real_wait = ray.wait

        def interrupted_wait(*args: Any, **kwargs: Any) -> Any:
            raise KeyboardInterrupt

        ray.wait = interrupted_wait
        try:
            with pytest.raises(KeyboardInterrupt):
                evaluator.evaluate(policy, population, center, 1, seed=0)
        finally:
            ray.wait = real_wait
        assert evaluator._actors == []
    assert evaluator._actors == []


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
    local = ARS("LinearPolicy", "Pendulum-v1", n_delta=1, seed=0)
    remote = ARS("LinearPolicy", "Pendulum-v1", n_delta=1, seed=0, evaluator="ray")
    try:
        local.learn(1)
        remote.learn(1)
        evaluator = remote._evaluator
        assert isinstance(evaluator, RayEvaluator)
        assert evaluator.env == "Pendulum-v1"
        # One env slot, seeded as locally: Pendulum's random starts included, the same generation bit for bit.
        assert evaluator.num_workers == 1
        assert remote.num_timesteps == local.num_timesteps == 2 * 200
        np.testing.assert_array_equal(remote.strategy.center, local.strategy.center)
    finally:
        if remote._evaluator is not None:
            remote._evaluator.close()


def assert_dead(actors: list[Any]) -> None:
    for actor in actors:
        with pytest.raises(ray.exceptions.RayActorError):
            ray.get(actor.ready.remote(), timeout=60)


@pytest.mark.timeout(300, method="thread")
def test_models_in_a_loop(toy_ray: RayEvaluator) -> None:
    # A seed loop (or a notebook re-run) of the documented one-liner, never closing the evaluators: toy_ray holds
    # one of the two CPUs and the first model's actor the other, yet every model trains (they share the actors).
    evaluators = []
    for seed in range(3):
        model = ARS("LinearPolicy", "Pendulum-v1", n_delta=1, seed=seed, evaluator="ray")
        model.learn(1)
        assert model._n_updates == 1 and model.num_timesteps == 2 * 200
        evaluators.append(model._evaluator)
    assert all(isinstance(e, RayEvaluator) and e.num_workers == 1 for e in evaluators)
    actors = evaluators[0]._actors
    assert [a._actor_id for a in evaluators[2]._actors] == [a._actor_id for a in actors]
    # The actors live while an evaluator uses them, and are killed when the last one is closed.
    for evaluator in evaluators[:2]:
        evaluator.close()
    assert ray.get(actors[0].ready.remote(), timeout=60) == 1
    evaluators[2].close()
    assert_dead(actors)


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
    # More actors than the cluster can ever place: a clear error after start_timeout, not a hang.
    too_many = RayEvaluator(ToyEnv, num_workers=3, start_timeout=5)
    with pytest.raises(RuntimeError, match=r"could not start \d of 3 actor\(s\) within start_timeout=5 s"):
        too_many.evaluate(policy, population, population[0], 1, seed=0)
    assert too_many._actors == []
    # toy_ray starts again when used.
    assert toy_ray.evaluate(policy, population, population[0], 1, seed=0).returns.shape == (4, 1)
