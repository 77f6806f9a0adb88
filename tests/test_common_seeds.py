"""Common random numbers (``common_seeds``): candidates compared by the update start from the same states."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from algorithms import POPULATION_ALGORITHMS, Algo
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

from sb3_es.common.policies import LinearPolicy
from sb3_es.evaluation import Generation, PopulationResult, VecEnvEvaluator

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def pendulum_population(n: int) -> tuple[LinearPolicy, np.ndarray]:
    env = make_vec_env("Pendulum-v1", n_envs=1)
    policy = LinearPolicy(env.observation_space, env.action_space)
    return policy, 0.3 * np.random.default_rng(0).standard_normal((n, policy.num_params))


@pytest.mark.parametrize("n_envs", [1, 3])
def test_same_reset_seed_same_episode_whatever_the_slot(n_envs: int) -> None:
    policy, rows = pendulum_population(3)
    population = np.concatenate([rows, rows])  # candidates k and k + 3 have the same parameters
    evaluator = VecEnvEvaluator(make_vec_env("Pendulum-v1", n_envs=n_envs))
    paired = np.array([[11, 21], [12, 22], [13, 23]] * 2)
    result = evaluator.evaluate(policy, population, rows[0], 2, seed=5, reset_seeds=paired)
    np.testing.assert_array_equal(result.returns[:3], result.returns[3:])
    # Each episode depends on its seed alone: the same returns on one slot as on three, whatever the generation seed.
    alone = VecEnvEvaluator(make_vec_env("Pendulum-v1", n_envs=1)).evaluate(
        policy, population, rows[0], 2, seed=99, reset_seeds=paired
    )
    np.testing.assert_allclose(result.returns, alone.returns, rtol=1e-6)
    # Different seeds: different starting states (Pendulum starts at a random angle).
    other = evaluator.evaluate(policy, population, rows[0], 2, seed=5, reset_seeds=paired + 100 * np.arange(6)[:, None])
    assert not np.allclose(other.returns[:3], other.returns[3:])


def test_reset_seeds_errors() -> None:
    policy, population = pendulum_population(2)
    with pytest.raises(ValueError, match=r"reset_seeds has shape \(3, 1\).*\(2, 1\)"):
        Generation(policy.network_spec(), population, population[0], 1, 0, reset_seeds=np.zeros((3, 1)))
    env = VecNormalize(make_vec_env("Pendulum-v1", n_envs=2), norm_reward=False)
    with pytest.raises(ValueError, match="through VecNormalize.*or set common_seeds=False"):
        VecEnvEvaluator(env).evaluate(policy, population, population[0], 1, seed=0, reset_seeds=np.zeros((2, 1)))


@pytest.mark.parametrize("algo", POPULATION_ALGORITHMS)
def test_a_model_with_common_seeds_refuses_a_vec_env_wrapper_at_once(algo: Algo, tmp_path: Path) -> None:
    match = "through VecNormalize.*or set common_seeds=False"
    wrapped = VecNormalize(make_vec_env("Pendulum-v1", n_envs=2), norm_reward=False)
    with pytest.raises(ValueError, match=match):  # at construction, not at the first generation
        algo.make(wrapped, 2, common_seeds=True)
    model = algo.make(make_vec_env("Pendulum-v1", n_envs=2), 2, common_seeds=True)
    with pytest.raises(ValueError, match=match):
        model.set_env(wrapped)
    algo.make(wrapped, 2).save(tmp_path / "model.zip")
    with pytest.raises(ValueError, match=match):
        algo.cls.load(tmp_path / "model.zip", env=wrapped, common_seeds=True)
    model.save(tmp_path / "common.zip")  # the saved setting, with the wrapper given to load()
    with pytest.raises(ValueError, match=match):
        algo.cls.load(tmp_path / "common.zip", env=wrapped)


class RecordingEvaluator(VecEnvEvaluator):
    """The local engine, keeping each generation's reset seeds and results."""

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        self.generations: list[tuple[np.ndarray | None, PopulationResult]] = []

    def _evaluate(self, generation: Generation, step_hook: Any) -> PopulationResult:
        result = super()._evaluate(generation, step_hook)
        self.generations.append((generation.reset_seeds, result))
        return result


#: Keyword arguments that make every candidate (almost) the center, so that returns differ only by starting state.
TINY_NOISE = {
    "ARS": dict(delta_std=1e-9),
    "OpenES": dict(sigma=1e-9),
    "CMAES": dict(sigma=1e-6),  # at 1e-9 the returns agree within pycma's tolfun, which stops CMA-ES
    "PGPE": dict(stdev_init=1e-9),
    "SimpleES": dict(sigma=1e-9),
}
#: The strategies whose candidates come in mirrored pairs ``center +/- d``.
MIRRORED = {"ARS", "OpenES", "PGPE"}


@pytest.mark.parametrize("algo", POPULATION_ALGORITHMS)
@pytest.mark.parametrize("common_seeds", [True, False])
def test_common_seeds_start_compared_candidates_alike(algo: Algo, common_seeds: bool) -> None:
    env = make_vec_env("Pendulum-v1", n_envs=2)
    evaluator = RecordingEvaluator(env)
    model = algo.make(
        env,
        6,
        evaluator=evaluator,
        n_eval_episodes=2,
        common_seeds=common_seeds,
        zero_policy=False,
        **TINY_NOISE[algo.name],
    )
    model.learn(2 * 6 * 2 * 200)
    assert len(evaluator.generations) == 2
    for seeds, result in evaluator.generations:
        if not common_seeds:
            assert seeds is None
            assert not np.allclose(result.returns[0], result.returns[3], atol=1e-3)
            continue
        assert seeds is not None and seeds.shape == (6, 2)
        assert len(np.unique(seeds[0])) == 2  # a candidate's two episodes start from different states
        groups = [[0, 3], [1, 4], [2, 5]] if algo.name in MIRRORED else [list(range(6))]
        for group in groups:
            # Same seeds within a group, so (nearly) the same returns for (nearly) the same parameters.
            assert (seeds[group] == seeds[group[0]]).all()
            np.testing.assert_allclose(
                result.returns[group], np.broadcast_to(result.returns[group[0]], (len(group), 2)), atol=1e-3
            )
        if len(groups) > 1:
            assert len({tuple(seeds[group[0]]) for group in groups}) == len(groups)
    # Fresh seeds each generation.
    first, second = (seeds for seeds, _ in evaluator.generations)
    assert not common_seeds or not np.array_equal(first, second)
