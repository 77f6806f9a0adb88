"""ARS as an SB3 algorithm: learning, step accounting, callbacks, logging, schedules and environments."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from envs import GenerationRecorder as Recorder
from envs import StepCounter
from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

from sb3_es import ARS
from sb3_es.strategies import ARSStrategy

PENDULUM_GENERATION = 2 * 2 * 200  # n_delta=2, 200-step episodes, 1 env


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


# ---------------------------------------------------------------------------- learning
def test_learns_cartpole() -> None:
    model = ARS("LinearPolicy", "CartPole-v1", n_delta=2, seed=0)
    model.learn(40_000)
    eval_env = make_vec_env("CartPole-v1", n_envs=1, seed=123)
    mean_return, _ = evaluate_policy(model, eval_env, n_eval_episodes=10, deterministic=True)
    assert mean_return >= 475


# ---------------------------------------------------------------------------- step accounting and callbacks
def counting_env(env_id: str, n_envs: int, counter: list[int], **kwargs: Any) -> Any:
    return make_vec_env(
        env_id, n_envs=n_envs, wrapper_class=StepCounter, wrapper_kwargs=dict(counter=counter), **kwargs
    )


def test_exact_timestep_count() -> None:
    counter = [0]
    env = counting_env("CartPole-v1", 3, counter)
    model = ARS("LinearPolicy", env, n_delta=3, n_eval_episodes=2, seed=1)
    recorder = Recorder()
    model.learn(1500, callback=recorder)
    assert model.num_timesteps >= 1500
    assert model.num_timesteps == counter[0]
    assert model.num_timesteps % 3 == 0
    # on_step once per vec step
    assert recorder.n_calls == model.num_timesteps // 3
    assert len(recorder.rollout_starts) == model._n_updates
    assert recorder.training_started == recorder.training_ended == 1
    # Continuing the run keeps counting exactly.
    model.learn(500, reset_num_timesteps=False, callback=recorder)
    assert model.num_timesteps == counter[0]
    assert recorder.n_calls == model.num_timesteps // 3


def test_last_generation_completed_and_budget_respected() -> None:
    """learn(N) runs whole generations until at least N steps (Pendulum: fixed 800-step generations)."""
    model = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, seed=0)
    model.learn(PENDULUM_GENERATION + 1)
    assert model.num_timesteps == 2 * PENDULUM_GENERATION
    assert model._n_updates == 2
    model.learn(PENDULUM_GENERATION)
    assert model.num_timesteps == PENDULUM_GENERATION


@pytest.mark.parametrize("offset", [1, 6])
def test_callback_stop_discards_interrupted_generation(offset: int) -> None:
    counter = [0]
    env = counting_env("CartPole-v1", 2, counter)
    model = ARS("LinearPolicy", env, n_delta=2, seed=2)
    # Stop on the `offset`-th vec step of the 3rd generation.
    recorder = Recorder(stop_in_generation=3, offset=offset)
    model.learn(100_000, callback=recorder)
    assert len(recorder.rollout_starts) == 3
    stop_at = recorder.rollout_starts[2] + offset
    assert recorder.n_calls == stop_at
    assert model.num_timesteps == stop_at * 2 == counter[0]
    assert model._n_updates == 2
    # Parameters (and observation statistics) are those of the last completed generation.
    np.testing.assert_array_equal(model.policy.parameters_to_vector(), recorder.params_at_start[2])
    np.testing.assert_array_equal(model.strategy.center.astype(np.float32), recorder.params_at_start[2])
    assert model.policy.obs_count.item() == recorder.obs_count_at_start[2]
    assert not np.array_equal(recorder.params_at_start[2], recorder.params_at_start[0])
    assert recorder.training_ended == 1


def test_callback_stop_on_last_step_of_a_generation_keeps_it() -> None:
    model = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, seed=0)
    recorder = Recorder(stop_at=2 * PENDULUM_GENERATION)
    model.learn(100_000, callback=recorder)
    assert model.num_timesteps == 2 * PENDULUM_GENERATION
    assert model._n_updates == 2  # the generation completed on that step: its update is applied
    assert len(recorder.rollout_starts) == 2
    assert not np.array_equal(model.policy.parameters_to_vector(), recorder.params_at_start[1])
    np.testing.assert_array_equal(model.policy.parameters_to_vector(), model.strategy.center.astype(np.float32))


def test_callback_stop_in_first_generation_keeps_initial_parameters() -> None:
    model = ARS("LinearPolicy", "CartPole-v1", n_delta=2, seed=0, zero_policy=False)
    initial = model.policy.parameters_to_vector()
    model.learn(10_000, callback=Recorder(stop_at=7))
    assert model.num_timesteps == 7
    assert model._n_updates == 0
    np.testing.assert_array_equal(model.policy.parameters_to_vector(), initial)
    assert model.policy.obs_count.item() == pytest.approx(1e-4)


def test_stop_training_on_max_episodes() -> None:
    counter = [0]
    env = counting_env("CartPole-v1", 2, counter)
    model = ARS("LinearPolicy", env, n_delta=4, seed=0)
    callback = StopTrainingOnMaxEpisodes(max_episodes=2)
    model.learn(100_000, callback=callback)
    assert callback.n_episodes >= 4  # 2 per env
    assert model.num_timesteps == counter[0] < 2_000
    assert model._n_updates == 0  # 8 candidates: the generation was interrupted
    np.testing.assert_array_equal(model.policy.parameters_to_vector(), 0.0)


def test_progress_bar() -> None:
    model = ARS("LinearPolicy", "Pendulum-v1", n_delta=1, seed=0)
    model.learn(400, progress_bar=True)
    assert model.num_timesteps == 400


# ---------------------------------------------------------------------------- logging
def test_logger_csv_keys(tmp_path: Path) -> None:
    model = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, seed=0)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    model.learn(2 * PENDULUM_GENERATION)
    rows = read_csv(tmp_path / "progress.csv")
    assert len(rows) == 2
    required = {
        "rollout/ep_rew_mean",
        "rollout/ep_len_mean",
        "time/fps",
        "time/total_timesteps",
        "time/iterations",
        "train/step_size",
        "train/delta_std",
        "train/return_std",
        "train/learning_rate",
    }
    assert required <= set(rows[0])
    for row in rows:
        assert all(row[key] != "" for key in required)
    assert [int(r["time/total_timesteps"]) for r in rows] == [PENDULUM_GENERATION, 2 * PENDULUM_GENERATION]
    assert [int(r["time/iterations"]) for r in rows] == [1, 2]
    assert float(rows[0]["train/learning_rate"]) == pytest.approx(0.02)
    assert float(rows[0]["train/delta_std"]) == pytest.approx(0.05)
    assert float(rows[0]["rollout/ep_len_mean"]) == 200
    # With one env and one episode per candidate, the first generation's episodes are the candidates'.
    assert float(rows[0]["rollout/ep_rew_mean"]) == pytest.approx(float(rows[0]["rollout/candidate_return_mean"]))
    assert float(rows[0]["train/return_std"]) > 0 and float(rows[0]["train/step_size"]) > 0


def test_log_interval(tmp_path: Path) -> None:
    model = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, seed=0)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    model.learn(4 * PENDULUM_GENERATION, log_interval=2)
    rows = read_csv(tmp_path / "progress.csv")
    assert [int(r["time/iterations"]) for r in rows] == [2, 4]


def test_tensorboard_log(tmp_path: Path) -> None:
    model = ARS("LinearPolicy", "Pendulum-v1", n_delta=1, seed=0, tensorboard_log=str(tmp_path))
    model.learn(400)
    run_dir = tmp_path / "ARS_ES_1"  # not sb3-contrib's "ARS_1"
    assert run_dir.is_dir()
    assert any(p.name.startswith("events.out.tfevents") and p.stat().st_size > 0 for p in run_dir.iterdir())
    model.learn(400)  # a new run gets the next id
    assert (tmp_path / "ARS_ES_2").is_dir()


# ---------------------------------------------------------------------------- hyperparameters
def test_schedules_are_applied(tmp_path: Path) -> None:
    total = 4 * PENDULUM_GENERATION
    model = ARS(
        "LinearPolicy",
        "Pendulum-v1",
        n_delta=2,
        learning_rate=lambda progress: 0.02 * progress,
        delta_std=lambda progress: 0.05 * progress,
        seed=0,
    )
    model.set_logger(configure(str(tmp_path), ["csv"]))
    asked: list[tuple[float, np.ndarray, np.ndarray, np.ndarray]] = []
    ask = model.strategy.ask

    def spy() -> np.ndarray:
        center = model.strategy.center.copy()
        population = ask()
        asked.append((model.strategy.delta_std, center, population, model.strategy._deltas.copy()))
        return population

    model.strategy.ask = spy  # type: ignore[method-assign]
    model.learn(total)
    rows = read_csv(tmp_path / "progress.csv")
    assert len(rows) == 4
    starts = [0] + [int(r["time/total_timesteps"]) for r in rows[:-1]]
    progress = [1.0 - s / total for s in starts]
    np.testing.assert_allclose([float(r["train/learning_rate"]) for r in rows], [0.02 * p for p in progress])
    np.testing.assert_allclose([float(r["train/delta_std"]) for r in rows], [0.05 * p for p in progress])
    # The perturbations really use the scheduled noise.
    for (delta_std, center, population, deltas), p in zip(asked, progress):
        assert delta_std == pytest.approx(0.05 * p)
        np.testing.assert_allclose(population[:2] - center, delta_std * deltas, atol=1e-12)
        np.testing.assert_allclose(population[2:] - center, -delta_std * deltas, atol=1e-12)


def test_ars_strategy_update_rule() -> None:
    """One tell(): top-b directions by max(r+, r-), step lr / (b * std of the 2b returns used)."""
    strategy = ARSStrategy(np.array([1.0, -1.0, 0.5]), n_delta=4, n_top=2, delta_std=0.2, learning_rate=0.1, seed=0)
    center = strategy.center.copy()
    population = strategy.ask()
    deltas = (population[:4] - center) / 0.2
    fitness = np.array([1.0, 5.0, 0.0, 2.0, 3.0, 0.5, 7.0, 1.0])
    info = strategy.tell(fitness)
    plus, minus = fitness[:4], fitness[4:]
    top = [2, 1]  # max(r+, r-) = [3, 5, 7, 2]
    used = np.concatenate([plus[top], minus[top]])
    step = 0.1 / (2 * used.std())
    expected = center + step * ((plus[top] - minus[top]) @ deltas[top])
    np.testing.assert_allclose(strategy.center, expected, rtol=1e-10)
    assert info["step_size"] == pytest.approx(step)
    assert info["return_std"] == pytest.approx(used.std())


def test_v1_leaves_obs_stats_untouched_v2_updates_them() -> None:
    v1 = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, seed=0, policy_kwargs=dict(normalize_observations=False))
    v1.learn(PENDULUM_GENERATION)
    np.testing.assert_array_equal(v1.policy.obs_mean.numpy(), 0.0)
    np.testing.assert_array_equal(v1.policy.obs_var.numpy(), 1.0)
    assert v1.policy.obs_count.item() == pytest.approx(1e-4)
    assert v1._n_updates == 1

    v2 = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, seed=0)
    v2.learn(PENDULUM_GENERATION)
    assert not np.allclose(v2.policy.obs_mean.numpy(), 0.0)
    assert not np.allclose(v2.policy.obs_var.numpy(), 1.0)
    # Every step of every candidate (one env: no idle slot) is counted once.
    assert v2.policy.obs_count.item() == pytest.approx(PENDULUM_GENERATION + 1e-4)
    # Pendulum observations are (cos, sin, angular velocity): |cos|, |sin| <= 1.
    assert np.all(np.abs(v2.policy.obs_mean.numpy()[:2]) <= 1.0)


def test_n_top_smaller_than_n_delta() -> None:
    model = ARS("LinearPolicy", "Pendulum-v1", n_delta=4, n_top=2, seed=0)
    model.learn(2 * 4 * 2 * 200)
    assert model._n_updates == 2
    assert np.any(model.policy.parameters_to_vector() != 0.0)
    assert model.strategy.n_top == 2


def test_alive_bonus_offset_changes_the_fitness() -> None:
    """With CartPole (reward 1 per step), an offset of -1 makes every fitness 0: no update at all."""
    model = ARS("LinearPolicy", "CartPole-v1", n_delta=2, alive_bonus_offset=-1.0, seed=0)
    model.learn(1)
    assert model._n_updates == 1
    np.testing.assert_array_equal(model.policy.parameters_to_vector(), 0.0)
    reference = ARS("LinearPolicy", "CartPole-v1", n_delta=2, seed=0)
    reference.learn(1)
    assert np.any(reference.policy.parameters_to_vector() != 0.0)


# ---------------------------------------------------------------------------- environments
def test_mlp_pendulum_subproc_vec_env() -> None:
    env = make_vec_env("Pendulum-v1", n_envs=2, vec_env_cls=SubprocVecEnv)
    try:
        model = ARS("MlpPolicy", env, n_delta=2, seed=0, policy_kwargs=dict(net_arch=[16, 16]))
        model.learn(2 * PENDULUM_GENERATION)
        assert model._n_updates == 2
        assert model.num_timesteps == 2 * PENDULUM_GENERATION
        assert np.any(model.policy.parameters_to_vector() != 0.0)
        assert np.all(np.isfinite(model.policy.parameters_to_vector()))
    finally:
        env.close()


def test_mlp_pendulum_vec_normalize() -> None:
    env = VecNormalize(make_vec_env("Pendulum-v1", n_envs=2))
    model = ARS("MlpPolicy", env, n_delta=2, seed=0, policy_kwargs=dict(net_arch=[16], normalize_observations=False))
    model.learn(PENDULUM_GENERATION)
    assert model._n_updates == 1
    assert model.get_vec_normalize_env() is env
    assert env.obs_rms.count > PENDULUM_GENERATION  # VecNormalize saw the training steps
    action, _ = model.predict(env.reset())
    assert action.shape == (2, 1)


def test_dm_control_dict_observations() -> None:
    shimmy = pytest.importorskip("shimmy")
    gym.register_envs(shimmy)
    env = make_vec_env("dm_control/walker-walk-v0", n_envs=1)
    assert isinstance(env.observation_space, gym.spaces.Dict)
    model = ARS("MlpPolicy", env, n_delta=1, seed=0, policy_kwargs=dict(net_arch=[16]))
    assert model.policy.obs_dim == 24
    model.learn(2 * 2 * 1000)
    assert model._n_updates == 2
    assert np.any(model.policy.parameters_to_vector() != 0.0)
    assert model.policy.obs_count.item() == pytest.approx(4000 + 1e-4)
    action, _ = model.predict(env.reset())
    assert action.shape == (1, 6) and np.all(np.abs(action) <= 1.0)


@pytest.mark.parametrize(("env_id", "n_envs"), [("Swimmer-v5", 1), ("BipedalWalker-v3", 2)])
def test_mujoco_and_box2d_run_a_generation(env_id: str, n_envs: int) -> None:
    counter = [0]
    env = counting_env(env_id, n_envs, counter)
    model = ARS("LinearPolicy", env, n_delta=1, seed=0)
    model.learn(1)
    assert model._n_updates == 1
    assert model.num_timesteps == counter[0] > 0
    assert np.all(np.isfinite(model.policy.parameters_to_vector()))
