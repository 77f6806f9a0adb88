"""
What every algorithm does alike, parametrized over ``envs.ALGORITHMS`` (as SB3's tests are over ``MODEL_LIST``):
learning CartPole, step accounting, callbacks, logging, Dict observations, non-finite rewards. The files of
each algorithm keep what is specific to it; saving and loading are in ``test_save_load.py``.
"""

from __future__ import annotations

import copy
import re
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from algorithms import (
    ALGORITHMS,
    CARTPOLE_CASES,
    POPULATION_ALGORITHMS,
    Algo,
    GenerationRecorder,
    assert_identical,
    learn_logged,
    pendulum_env,
    policy_state,
    policy_vector,
    progress_bar_after_learn,
    spy_on_ask,
)
from envs import ConstantObsEnv, NaNRewardWrapper, SpaceEnv, ToyEnv, counting_env, read_csv, rollout
from stable_baselines3.common.callbacks import BaseCallback, StopTrainingOnMaxEpisodes
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import load_results
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_es import CMAES

pytestmark = pytest.mark.usefixtures("one_torch_thread")

#: Pendulum-v1 episodes last exactly 200 steps: a generation of 2 candidates (episodes) on one env is 400 steps.
GENERATION = 2 * 200


def pendulum_model(algo: Algo, **kwargs: Any) -> Any:
    """:return: ``algo`` on one Pendulum-v1 env with generations of 2 candidates (:data:`GENERATION` steps)."""
    return algo.make(pendulum_env(), 2, **kwargs)


def assert_updates(algo: Algo, model: Any, n: int) -> None:
    """The model, and the strategy or optimizer by its own count (where it keeps one), applied ``n`` updates."""
    assert model._n_updates == n
    if algo.optimizer_steps is not None:
        assert algo.optimizer_steps(model) == n


# ---------------------------------------------------------------------------- construction
@pytest.mark.parametrize("algo", ALGORITHMS)
def test_shared_parameters_reach_the_base_class(algo: Algo, tmp_path: Path) -> None:
    """Each algorithm repeats the typed signature of its base class and passes every shared argument on."""
    shared: dict[str, Any] = dict(tensorboard_log=str(tmp_path), seed=3, max_episode_steps=50)
    if algo.population:
        shared |= dict(n_eval_episodes=3, alive_bonus_offset=-1.0, reward_clip=(-2.0, 2.0), terminal_reward=0.0)
        shared |= dict(zero_policy=False, evaluator="local")
    kwargs = dict(stats_window_size=7, policy_kwargs=dict(net_arch=[5]))
    model = algo.make("Pendulum-v1", 2, policy="MlpPolicy", **shared, **kwargs)
    for name, value in shared.items():
        assert getattr(model, name) == value, name
    assert model._stats_window_size == 7 and model.policy_kwargs["net_arch"] == [5]
    if algo.population:
        assert model._env_id == "Pendulum-v1"  # for evaluator="processes" or "ray"


# ---------------------------------------------------------------------------- learning
@pytest.mark.parametrize(("algo", "policy", "kwargs", "steps"), CARTPOLE_CASES)
def test_learns_cartpole(algo: Algo, policy: str, kwargs: dict[str, Any], steps: int) -> None:
    """Each algorithm, and the options whose learning is checked too: ``algorithms.CARTPOLE_CASES``."""
    env = make_vec_env("CartPole-v1", n_envs=algo.cartpole_envs, seed=0)
    model = algo.cls(policy, env, **{**algo.defaults, "seed": 0, **kwargs})
    model.learn(steps)
    eval_env = make_vec_env("CartPole-v1", n_envs=1, seed=123)
    mean_return, _ = evaluate_policy(model, eval_env, n_eval_episodes=10, deterministic=True)
    assert mean_return >= 475


# ---------------------------------------------------------------------------- step accounting
@pytest.mark.parametrize("algo", ALGORITHMS)
def test_exact_timestep_count(algo: Algo) -> None:
    counter = [0]
    extra = dict(n_eval_episodes=2) if algo.population else {}
    model = algo.make(counting_env("CartPole-v1", 3, counter), 6, **extra)
    recorder = GenerationRecorder()
    model.learn(1500, callback=recorder)
    assert model.num_timesteps >= 1500
    assert model.num_timesteps == counter[0]
    assert model.num_timesteps % 3 == 0
    assert recorder.n_calls == model.num_timesteps // 3  # on_step once per vec step
    assert len(recorder.rollout_starts) == recorder.rollout_ends >= 1
    assert_updates(algo, model, recorder.rollout_ends)  # one update per completed rollout
    assert recorder.training_started == recorder.training_ended == 1
    # Continuing the run keeps counting exactly.
    model.learn(500, reset_num_timesteps=False, callback=recorder)
    assert model.num_timesteps == counter[0]
    assert recorder.n_calls == model.num_timesteps // 3


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_last_generation_is_completed_and_the_budget_respected(algo: Algo) -> None:
    """learn(N) runs whole generations until at least N steps (Pendulum: generations of fixed length)."""
    model = pendulum_model(algo)
    model.learn(GENERATION + 1)
    assert model.num_timesteps == 2 * GENERATION
    assert model._n_updates == 2
    model.learn(GENERATION)
    assert model.num_timesteps == GENERATION


# ---------------------------------------------------------------------------- callbacks
@pytest.mark.parametrize("algo", ALGORITHMS)
@pytest.mark.parametrize("offset", [1, 6])
def test_callback_stop_discards_interrupted_generation(algo: Algo, offset: int) -> None:
    counter = [0]
    model = algo.make(counting_env("CartPole-v1", 2, counter), 4, seed=2)
    # Stop on the `offset`-th vec step of the 3rd generation.
    recorder = GenerationRecorder(stop_in_generation=3, offset=offset)
    model.learn(100_000, callback=recorder)
    assert len(recorder.rollout_starts) == 3
    stop_at = recorder.rollout_starts[2] + offset
    assert recorder.n_calls == stop_at  # stopped within that very vec step
    assert recorder.rollout_ends == 2  # as SB3's collect_rollouts: no on_rollout_end for the rollout cut short
    assert model.num_timesteps == stop_at * 2 == counter[0]
    assert_updates(algo, model, 2)
    # The parameters and the observation statistics are those of the last completed update.
    assert_identical(policy_state(model), recorder.state_at_start[2])
    if algo.population:
        np.testing.assert_array_equal(model.strategy.center.astype(np.float32), recorder.params_at_start[2])
    assert not np.array_equal(recorder.params_at_start[2], recorder.params_at_start[0])
    assert recorder.training_ended == 1
    # Training can go on afterwards.
    model.learn(1, reset_num_timesteps=False)
    assert_updates(algo, model, 3)


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_callback_stop_in_first_generation_keeps_initial_parameters(algo: Algo) -> None:
    counter = [0]
    model = algo.make(counting_env("CartPole-v1", 3, counter), 6)
    initial = policy_state(model)
    model.learn(10_000, callback=GenerationRecorder(stop_at=7))
    assert model.num_timesteps == counter[0] == 7 * 3
    assert_updates(algo, model, 0)
    assert_identical(policy_state(model), initial)


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_callback_stop_on_last_step_of_a_generation_discards_it(algo: Algo) -> None:
    """As PPO discards a rollout whose last step's callback returned False: the model is the one judged."""
    model = pendulum_model(algo)
    recorder = GenerationRecorder(stop_at=2 * GENERATION)
    model.learn(100_000, callback=recorder)
    assert model.num_timesteps == 2 * GENERATION
    assert_updates(algo, model, 1)  # the second generation completed on that step, and is not applied
    assert len(recorder.rollout_starts) == 2 and recorder.rollout_ends == 1
    assert_identical(policy_state(model), recorder.state_at_start[1])
    if algo.population:
        np.testing.assert_array_equal(model.strategy.center.astype(np.float32), recorder.params_at_start[1])


class RolloutEndView(BaseCallback):
    """What a callback sees at each ``on_rollout_end``: the episodes in the model's buffer, and a step's locals."""

    def __init__(self) -> None:
        super().__init__()
        self.buffered: list[int] = []
        self.step_locals: set[str] = set()

    def _on_step(self) -> bool:
        self.step_locals = set(self.locals)
        return True

    def _on_rollout_end(self) -> None:
        self.buffered.append(len(self.model.ep_info_buffer))


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_rollout_end_sees_the_rollouts_episodes(algo: Algo) -> None:
    # PPO's ep_info_buffer holds a rollout's episodes when on_rollout_end is called, and its step locals name the env
    view = RolloutEndView()
    pendulum_model(algo).learn(3 * GENERATION, callback=view)
    assert view.buffered == [2, 4, 6]  # 2 candidate episodes (or 2 episodes per update) per generation
    assert {"env", "infos", "dones", "rewards", "new_obs", "actions"} <= view.step_locals


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_training_goes_on_after_a_generation_cut_short(algo: Algo, tmp_path: Path) -> None:
    """After a callback stopped learn() within a generation, learn() goes on, in memory and from a save made then (a
    checkpoint). With a 64-unit MLP, pycma uses TPA, whose ask() uses up the mean-shift samples it injects."""
    model = algo.make(make_vec_env("CartPole-v1", n_envs=2), 4, "MlpPolicy", policy_kwargs=dict(net_arch=[64]))
    if algo.cls is CMAES:
        assert model.strategy.es.mean_shift_samples
    model.learn(100_000, callback=GenerationRecorder(stop_in_generation=3, offset=1))  # TPA is checked from there
    assert_updates(algo, model, 2)
    model.save(tmp_path / "cut.zip")
    loaded = algo.cls.load(tmp_path / "cut.zip", env=make_vec_env("CartPole-v1", n_envs=2))
    for trained in (model, loaded):
        trained.learn(1, reset_num_timesteps=False)
        assert_updates(algo, trained, 3)


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_stop_training_on_max_episodes(algo: Algo) -> None:
    counter = [0]
    model = algo.make(counting_env("CartPole-v1", 2, counter), 8)
    initial = policy_state(model)
    callback = StopTrainingOnMaxEpisodes(max_episodes=2)
    model.learn(100_000, callback=callback)
    assert callback.n_episodes >= 4  # 2 per env
    assert model.num_timesteps == counter[0] < 2_000
    assert_updates(algo, model, 0)  # 8 episodes per generation: it was interrupted
    assert_identical(policy_state(model), initial)


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_episodes_cut_at_max_episode_steps_reach_the_monitor(algo: Algo, tmp_path: Path) -> None:
    """An episode cut at a cap below the env's time limit ends in the Monitor as a truncation would: its row is in
    the Monitor file, with the env's own reward (not the +100 per step of a wrapper after the Monitor), and the
    episode buffer (rollout/ep_rew_mean) gets the Monitor's info."""
    plus_100 = dict(wrapper_class=lambda env: gym.wrappers.TransformReward(env, lambda r: r + 100.0))
    env = make_vec_env("Pendulum-v1", n_envs=2, monitor_dir=str(tmp_path), **plus_100)
    model = algo.make(env, 4, max_episode_steps=30)
    model.learn(300)
    env.close()
    episodes = load_results(str(tmp_path))
    assert model.ep_info_buffer is not None and len(model.ep_info_buffer) >= 4
    assert (episodes["l"] == 30).all() and len(episodes) >= len(model.ep_info_buffer)
    assert (episodes["r"] <= 0).all() and all(info["r"] <= 0 and info["l"] == 30 for info in model.ep_info_buffer)
    assert {round(info["r"], 4) for info in model.ep_info_buffer} <= {round(r, 4) for r in episodes["r"]}


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_progress_bar(algo: Algo) -> None:
    model = pendulum_model(algo)
    pbar = progress_bar_after_learn(model, GENERATION)
    assert model.num_timesteps == GENERATION == pbar.n == pbar.total


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_a_function_callback_with_the_progress_bar(algo: Algo) -> None:
    """A function is a callback, as SB3 takes it (wrapped in ``ConvertCallback``), with the progress bar too."""
    model, calls = pendulum_model(algo), []
    model.learn(GENERATION, callback=lambda _locals, _globals: calls.append(_locals["self"]) or True, progress_bar=True)
    assert len(calls) == GENERATION // model.n_envs and calls[0] is model


# ---------------------------------------------------------------------------- logging
@pytest.mark.parametrize("algo", ALGORITHMS)
def test_logger_csv_keys(algo: Algo, tmp_path: Path) -> None:
    """SB3's keys and the algorithm's ``train/`` keys, in every row, one row per generation (update)."""
    model = pendulum_model(algo, **algo.logged_with)
    rows = learn_logged(model, 2 * GENERATION, tmp_path)
    assert len(rows) == 2
    required = {"rollout/ep_rew_mean", "rollout/ep_len_mean", "time/fps", "time/total_timesteps", "time/iterations"}
    required |= {f"train/{key}" for key in algo.logged}
    if algo.population:
        required |= {"rollout/candidate_return_max", "rollout/candidate_return_mean", "train/best_fitness"}
    assert required <= set(rows[0])
    for row in rows:
        assert all(row[key] != "" for key in required)
    assert [int(r["time/total_timesteps"]) for r in rows] == [GENERATION, 2 * GENERATION]
    assert [int(r["time/iterations"]) for r in rows] == [1, 2]
    assert float(rows[0]["rollout/ep_len_mean"]) == 200
    if algo.population:
        # One env, one episode per candidate: the first generation's episodes are the candidates'.
        assert float(rows[0]["rollout/ep_rew_mean"]) == pytest.approx(float(rows[0]["rollout/candidate_return_mean"]))
        # No shaping, one episode: the fitness is the return, and the best so far is the generation's best.
        best = float(rows[0]["train/best_fitness"])
        assert best == pytest.approx(float(rows[0]["rollout/candidate_return_max"]))
        assert float(rows[1]["train/best_fitness"]) >= best


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_log_interval(algo: Algo, tmp_path: Path) -> None:
    model = pendulum_model(algo)
    rows = learn_logged(model, 4 * GENERATION, tmp_path, log_interval=2)
    assert [int(r["time/iterations"]) for r in rows] == [2, 4]
    # As in SB3, iterations and log_interval count the generations of each learn() call; the steps go on.
    model.learn(3 * GENERATION, reset_num_timesteps=False, log_interval=2)
    rows = read_csv(tmp_path / "progress.csv")
    assert [int(r["time/iterations"]) for r in rows] == [2, 4, 2]
    assert [int(r["time/total_timesteps"]) for r in rows] == [2 * GENERATION, 4 * GENERATION, 6 * GENERATION]


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_tensorboard_log(algo: Algo, tmp_path: Path) -> None:
    model = pendulum_model(algo, tensorboard_log=str(tmp_path))
    model.learn(GENERATION)
    run_dir = tmp_path / f"{algo.tb_log_name}_1"
    assert run_dir.is_dir()
    assert any(p.name.startswith("events.out.tfevents") and p.stat().st_size > 0 for p in run_dir.iterdir())
    model.learn(GENERATION)  # a new run gets the next id
    assert (tmp_path / f"{algo.tb_log_name}_2").is_dir()


@pytest.mark.parametrize("algo", POPULATION_ALGORITHMS)
def test_idle_slots_log_the_center_policy_return(algo: Algo, tmp_path: Path) -> None:
    """
    ``rollout/center_return`` is the return of the center (mean) policy, run by env slots with no candidate left:
    6 ToyEnv slots for 4 candidates. Logged when such an episode ends within the generation, equal to the center's
    own episode (ToyEnv ignores the reset seed; the policy's observation statistics are those of the generation).
    """

    class CenterReturn(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.expected: list[float] = []

        def _on_rollout_start(self) -> None:
            center = self.model.strategy.center.copy()
            self.expected.append(rollout(ToyEnv(), copy.deepcopy(self.model.policy), center)[0])

        def _on_step(self) -> bool:
            return True

    expected = CenterReturn()
    model = algo.make(DummyVecEnv([ToyEnv] * 6), 4, max_episode_steps=12)
    rows = learn_logged(model, 100, tmp_path, callback=expected)
    assert len(rows) == len(expected.expected) >= 2
    logged = [row.get("rollout/center_return", "") for row in rows]
    assert logged[0] != ""  # the first center episode (no longer than the candidates') ended in the generation
    for value, center_return in zip(logged, expected.expected):
        if value != "":
            assert float(value) == pytest.approx(center_return, rel=1e-6)


# ---------------------------------------------------------------------------- environments
@pytest.mark.parametrize("algo", ALGORITHMS)
def test_dm_control_dict_observations(algo: Algo) -> None:
    """dm_control's walker-walk through shimmy: Dict observations, 6 Box actions (episodes cut to 50 steps)."""
    import shimmy

    gym.register_envs(shimmy)
    env = make_vec_env("dm_control/walker-walk-v0", n_envs=1, env_kwargs=dict(max_episode_steps=50))
    assert isinstance(env.observation_space, gym.spaces.Dict)
    model = algo.make(env, 4, policy="MultiInputPolicy")
    initial = policy_vector(model)
    model.learn(1)
    assert model.num_timesteps == 4 * 50
    assert_updates(algo, model, 1)
    assert not np.array_equal(policy_vector(model), initial)
    if algo.population:
        assert model.policy.obs_dim == 24
        assert model.policy.obs_count.item() == pytest.approx(4 * 50 + 1e-4)
    action, _ = model.predict(env.reset(), deterministic=True)
    assert action.shape == (1, 6) and np.all(np.abs(action) <= 1.0)


# ---------------------------------------------------------------------------- policy arguments
@pytest.mark.parametrize("algo", ALGORITHMS)
def test_sb3_actor_critic_net_arch_forms(algo: Algo, tmp_path: Path) -> None:
    # SB3's dict form gives the policy's layers (pi); a missing vf is [] as in SB3; the old list form warns as SB3.
    expected = policy_state(algo.make("Pendulum-v1", 2, policy="MlpPolicy", policy_kwargs=dict(net_arch=[8])))
    forms: list[Any] = [dict(pi=[8]), dict(pi=[8], vf=[])]
    for net_arch in forms:
        model = algo.make("Pendulum-v1", 2, policy="MlpPolicy", policy_kwargs=dict(net_arch=net_arch))
        assert_identical(policy_state(model), expected)
    with pytest.warns(UserWarning, match="shared layers"):
        model = algo.make("Pendulum-v1", 2, policy="MlpPolicy", policy_kwargs=dict(net_arch=[dict(pi=[8])]))
    assert_identical(policy_state(model), expected)
    model.learn(1)
    model.save(tmp_path / "model.zip")
    loaded = algo.cls.load(tmp_path / "model.zip")
    assert_identical(policy_state(loaded), policy_state(model))
    # No hidden layer in the policy: pi=[] (or no pi entry) as in SB3.
    linear = [algo.make("Pendulum-v1", 2, policy="MlpPolicy", policy_kwargs=dict(net_arch=a)) for a in ([], {"vf": []})]
    assert_identical(policy_state(linear[0]), policy_state(linear[1]))


# ---------------------------------------------------------------------------- non-finite returns
def strategy_state(model: Any) -> dict[str, Any]:
    """:return: What a failed generation must leave as it was: policy state, strategy center, best fitness."""
    return dict(
        policy_state(model),
        center=model.strategy.center.copy(),
        best_fitness=getattr(model.strategy, "best_fitness", -np.inf),
    )


@pytest.mark.parametrize("algo", POPULATION_ALGORITHMS)
def test_nan_rewards_name_the_candidates_and_leave_everything_unchanged(algo: Algo) -> None:
    """Constant observation 1: a candidate's action has the sign of its weight, NaN reward when positive."""
    model = algo.make(DummyVecEnv([ConstantObsEnv]), 6)
    asked = spy_on_ask(model)
    before = strategy_state(model)
    with pytest.raises(ValueError, match="candidate") as info:
        model.learn(100)
    bad = np.flatnonzero(asked[0][:, 0] > 0).tolist()
    assert 0 < len(bad) < 6
    assert str(bad) in str(info.value)
    assert_identical(strategy_state(model), before)
    assert_updates(algo, model, 0)


@pytest.mark.parametrize("algo", POPULATION_ALGORITHMS)
def test_nan_rewards_after_training_leave_last_update(algo: Algo) -> None:
    model = algo.make(make_vec_env("Pendulum-v1", n_envs=1), 4)
    model.learn(1)
    assert model._n_updates == 1
    before = strategy_state(model)
    model.set_env(make_vec_env("Pendulum-v1", n_envs=1, wrapper_class=NaNRewardWrapper))
    with pytest.raises(ValueError, match=re.escape("candidate(s) [0, 1, 2, 3]")):
        model.learn(1, reset_num_timesteps=False)
    assert_identical(strategy_state(model), before)
    assert_updates(algo, model, 1)


F32_MAX = float(np.finfo(np.float32).max)
ACTION_SPACES = {
    "int_box": gym.spaces.Box(0, 10, shape=(2,), dtype=np.int64),
    "float32_limit_bounds": gym.spaces.Box(-F32_MAX, F32_MAX, shape=(2,), dtype=np.float32),
    "box_3x2": gym.spaces.Box(np.arange(6.0).reshape(3, 2), np.arange(6.0).reshape(3, 2) + 1, dtype=np.float32),
}


@pytest.mark.parametrize("policy", ["MlpPolicy", None])
@pytest.mark.parametrize("space", list(ACTION_SPACES))
@pytest.mark.parametrize("algo", ALGORITHMS)
def test_actions_stay_in_the_action_space(algo: Algo, space: str, policy: str | None) -> None:
    """Integer Box actions are integers; bounds near the float32 limit give finite actions; a 2-D Box its own bounds."""
    action_space = ACTION_SPACES[space]
    obs_space = gym.spaces.Box(-1, 1, shape=(3,), dtype=np.float32)
    env = DummyVecEnv([lambda: SpaceEnv(obs_space, action_space)] * 2)
    model = algo.make(env, 4, policy=policy)
    model.learn(60)
    seen = [a for e in env.envs for a in e.unwrapped.actions]
    assert seen and all(action_space.contains(np.asarray(a)) for a in seen), [a for a in seen[:3]]
    actions, _ = model.predict(np.stack([obs_space.sample() for _ in range(3)]), deterministic=True)
    assert actions.shape == (3, *action_space.shape)
    assert all(action_space.contains(a) for a in actions), actions


OBSERVATION_SPACES = {
    "discrete_start": gym.spaces.Discrete(3, start=2),
    "multidiscrete_start": gym.spaces.MultiDiscrete([2, 3], start=[1, -1]),
    "scalar_box": gym.spaces.Box(-1, 1, shape=(), dtype=np.float32),
}


@pytest.mark.parametrize("space", list(OBSERVATION_SPACES))
@pytest.mark.parametrize("algo", ALGORITHMS)
def test_observation_spaces_learn_and_predict(algo: Algo, space: str) -> None:
    """Discrete observations counted from a nonzero start, and a scalar Box, train and predict (single and batch)."""
    obs_space = OBSERVATION_SPACES[space]
    action_space = gym.spaces.Box(-1, 1, shape=(1,), dtype=np.float32)
    model = algo.make(DummyVecEnv([lambda: SpaceEnv(obs_space, action_space)] * 2), 4)
    model.learn(60)
    obs_space.seed(0)
    batch = np.stack([obs_space.sample() for _ in range(4)])
    actions, _ = model.predict(batch, deterministic=True)
    assert actions.shape == (4, 1)
    single, _ = model.predict(batch[0], deterministic=True)
    np.testing.assert_allclose(single, actions[0], rtol=1e-5)
