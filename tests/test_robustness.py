"""Episodes that never end, non-finite observations, discrete observations, success rate, the learn() budget and
the callbacks' locals, for every algorithm (issue 10 items 2, 3, 8, 9, 10; issue 11 item 10)."""

from __future__ import annotations

import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from algorithms import ALGORITHMS, ALGOS, POPULATION_ALGORITHMS, Algo, GenerationRecorder, policy_vector
from envs import NEVER_ENDING_ID, DiscreteMatchEnv, NaNObsWrapper, NeverEndingEnv, SuccessInfoWrapper, ToyEnv
from gymnasium import spaces
from gymnasium.wrappers import TimeLimit
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.envs import BitFlippingEnv
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.logger import configure
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.preprocessing import preprocess_obs
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

from sb3_es.common.base_class import DEFAULT_MAX_EPISODE_STEPS
from sb3_es.common.policies import MlpPolicy
from sb3_es.evaluation import ObsStats
from sb3_es.evaluation.time_limit import env_time_limit


def make_model(algo: Algo, env: Any, **kwargs: Any) -> BaseAlgorithm:
    """A small MLP model of ``algo``: 4 candidates per generation, or 2 episodes per update."""
    return algo.make(env, 4 if algo.population else 2, policy="MlpPolicy", policy_kwargs=dict(net_arch=[8]), **kwargs)


class EpisodeLengths(BaseCallback):
    """Records the length of every episode that ends, from the callbacks' ``dones`` (per env slot)."""

    def __init__(self) -> None:
        super().__init__()
        self.lengths: list[int] = []
        self.running: np.ndarray | None = None

    def _on_step(self) -> bool:
        dones = np.asarray(self.locals["dones"])
        if self.running is None or len(self.running) != len(dones):
            self.running = np.zeros(len(dones), dtype=np.int64)
        self.running += 1
        self.lengths.extend(self.running[dones].tolist())
        self.running[dones] = 0
        return True

    def _on_rollout_start(self) -> None:
        self.running = None  # every generation / update starts from a reset


# ---------------------------------------------------------------------------- episodes that never end
@pytest.mark.timeout(120)
@pytest.mark.parametrize("algo", ALGORITHMS)
def test_env_id_without_time_limit_gets_one(algo: Algo) -> None:
    """An env id registered without a time limit: learn() returns, episodes last the default cap, one warning."""
    model = make_model(algo, NEVER_ENDING_ID)
    assert model.get_env().env_is_wrapped(TimeLimit) == [True]  # type: ignore[union-attr]
    lengths = EpisodeLengths()
    with pytest.warns(UserWarning, match="no time limit") as record:
        model.learn(1, callback=lengths)
        model.learn(1, callback=lengths, reset_num_timesteps=False)
    assert sum("no time limit" in str(w.message) for w in record) == 1
    assert lengths.lengths and set(lengths.lengths) == {DEFAULT_MAX_EPISODE_STEPS}
    # The model's env is capped too, so SB3's evaluation of it returns.
    _, episode_length = evaluate_policy(model, model.get_env(), n_eval_episodes=1, return_episode_rewards=True)
    assert episode_length == [DEFAULT_MAX_EPISODE_STEPS]


@pytest.mark.timeout(120)
@pytest.mark.parametrize("algo", ALGORITHMS)
@pytest.mark.parametrize("n_envs", [1, 3])
def test_vec_env_without_time_limit_is_cut_by_the_evaluation(algo: Algo, n_envs: int) -> None:
    """A user VecEnv without a time limit: each slot is reset when its episode reaches max_episode_steps."""
    env = make_vec_env(NeverEndingEnv, n_envs=n_envs)
    model = make_model(algo, env, max_episode_steps=25)
    lengths = EpisodeLengths()
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=".*time limit")  # an explicit max_episode_steps: no warning
        model.learn(300, callback=lengths)
    assert model.num_timesteps >= 300
    assert lengths.lengths and set(lengths.lengths) == {25}
    assert model.ep_info_buffer is not None and {info["l"] for info in model.ep_info_buffer} == {25}


@pytest.mark.timeout(60)
@pytest.mark.parametrize("algo", ALGORITHMS)
def test_vec_env_without_time_limit_warns_once_and_uses_the_default(algo: Algo) -> None:
    model = make_model(algo, make_vec_env(NeverEndingEnv, n_envs=2))
    with pytest.warns(UserWarning, match=f"no time limit.*{DEFAULT_MAX_EPISODE_STEPS} steps"):
        model.learn(1)
    assert model.ep_info_buffer is not None
    assert {info["l"] for info in model.ep_info_buffer} == {DEFAULT_MAX_EPISODE_STEPS}


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_env_time_limit_is_used_without_warning(algo: Algo) -> None:
    model = make_model(algo, "Pendulum-v1")
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=".*time limit")
        model.learn(1)
    assert model.episode_step_limit() == 200  # type: ignore[attr-defined]
    model = make_model(algo, "Pendulum-v1", max_episode_steps=30)
    lengths = EpisodeLengths()
    model.learn(1, callback=lengths)
    assert set(lengths.lengths) == {30}


@pytest.mark.timeout(60)
def test_the_time_limit_of_subprocess_envs_is_found_under_rl_zoo() -> None:
    # rl_zoo3 replaces gymnasium's TimeLimit with a subclass in this process; the workers of a SubprocVecEnv do not
    # import rl_zoo3, so their TimeLimit is gymnasium's own, which a class check from here does not recognize
    import rl_zoo3.gym_patches  # noqa: F401

    env = make_vec_env("Pendulum-v1", n_envs=2, vec_env_cls=SubprocVecEnv)
    try:
        assert env_time_limit(env) == 200
        model = make_model(ALGOS[0], env)
        with warnings.catch_warnings():
            warnings.filterwarnings("error", message=".*time limit")
            assert model.episode_step_limit() == 200  # type: ignore[attr-defined]
    finally:
        env.close()
    assert env_time_limit(make_vec_env(NeverEndingEnv, n_envs=2)) is None


@pytest.mark.timeout(60)
@pytest.mark.parametrize("algo", ALGORITHMS)
def test_vec_env_wrapper_without_time_limit_is_a_clear_error(algo: Algo) -> None:
    """A single slot cannot be reset through VecNormalize: an error says to give the envs a time limit (instead of a
    hang), at construction for a max_episode_steps below the env's own limit, else once an episode reaches the cap."""
    fix = r"through VecNormalize .*make_vec_env\(env_id, env_kwargs=dict\(max_episode_steps=20\)\)"
    with pytest.raises(ValueError, match=fix):
        make_model(algo, VecNormalize(make_vec_env(NeverEndingEnv, n_envs=2)), max_episode_steps=20)
    with pytest.raises(ValueError, match=fix):
        make_model(algo, VecNormalize(make_vec_env("Pendulum-v1", n_envs=2)), max_episode_steps=20)
    make_model(algo, VecNormalize(make_vec_env("Pendulum-v1", n_envs=2)), max_episode_steps=200)  # the env's own
    model = make_model(algo, VecNormalize(make_vec_env(NeverEndingEnv, n_envs=2)))  # the default cap: 1000
    with pytest.warns(UserWarning, match="no time limit"), pytest.raises(RuntimeError, match="1000") as info:
        model.learn(100)
    assert "env_kwargs=dict(max_episode_steps=1000)" in str(info.value) and "VecNormalize" in str(info.value)


# ---------------------------------------------------------------------------- observation statistics
def test_obs_stats_skip_and_count_non_finite_rows() -> None:
    stats = ObsStats(2)
    stats.add(np.array([[1.0, 2.0], [np.nan, 0.0], [3.0, np.inf], [3.0, 4.0]]))
    assert stats.count == 2 and stats.n_nonfinite == 2
    np.testing.assert_allclose(stats.mean, [2.0, 3.0])
    np.testing.assert_allclose(stats.var, [1.0, 1.0])
    stats.add(np.full((3, 2), np.nan))  # a batch of nothing but NaN
    assert stats.count == 2 and stats.n_nonfinite == 5
    assert np.all(np.isfinite(stats.mean)) and np.all(np.isfinite(stats.var))


def test_obs_stats_large_offset_and_exact_merge() -> None:
    """Observations 1e8 + N(0, 1): sums of squares lose the variance; the two-pass batches and Chan's merge keep it,
    and merging workers' statistics in any order gives the statistics of all the observations."""
    rng = np.random.default_rng(0)
    batches = [1e8 + rng.standard_normal((int(n), 3)) for n in rng.integers(1, 40, size=30)]
    data = np.concatenate(batches)
    whole = ObsStats(3)
    for batch in batches:
        whole.add(batch)
    np.testing.assert_allclose(whole.mean, data.mean(axis=0), rtol=1e-14)
    np.testing.assert_allclose(whole.var, data.var(axis=0), rtol=1e-6)
    workers = []
    for part in (batches[:7], batches[7:8], batches[8:20], batches[20:]):
        stats = ObsStats(3)
        for batch in part:
            stats.add(batch)
        workers.append(stats)
    forward, backward = ObsStats(3), ObsStats(3)
    for stats in workers:
        forward.merge(stats)
    for stats in reversed(workers):
        backward.merge(stats)
    for merged in (forward, backward):
        assert merged.count == len(data)
        np.testing.assert_allclose(merged.mean, data.mean(axis=0), rtol=1e-14)
        np.testing.assert_allclose(merged.var, data.var(axis=0), rtol=1e-6)
    assert ObsStats(3).count == 0
    forward.merge(ObsStats(3))  # merging empty statistics changes nothing
    assert forward.count == len(data)


@pytest.mark.parametrize("algo", POPULATION_ALGORITHMS)
def test_nan_observation_stays_out_of_the_statistics(algo: Algo) -> None:
    # Discrete actions: the NaN observation gives NaN outputs, whose argmax is still a valid action.
    env = make_vec_env(
        ToyEnv, n_envs=2, env_kwargs=dict(discrete=True), wrapper_class=NaNObsWrapper, wrapper_kwargs=dict(at=3)
    )
    model = make_model(algo, env)
    with pytest.warns(UserWarning, match=r"2 of the \d+ observations .* NaN or infinite"):
        model.learn(200)
    policy = model.policy
    assert np.all(np.isfinite(policy.obs_mean.numpy())) and np.all(np.isfinite(policy.obs_var.numpy()))
    assert np.all(np.isfinite(policy.normalize(np.ones((1, 2), dtype=np.float32))))
    assert policy.obs_count.item() > 10


# ---------------------------------------------------------------------------- discrete observations
DISCRETE_SPACES = {
    "Discrete": spaces.Discrete(5),
    "MultiDiscrete": spaces.MultiDiscrete([3, 4]),
    "MultiBinary": spaces.MultiBinary(4),
    "Dict": spaces.Dict(
        {"pos": spaces.Discrete(3), "vel": spaces.Box(-1, 1, (2,)), "flags": spaces.MultiBinary([2, 2])}
    ),
}


@pytest.mark.parametrize("name", list(DISCRETE_SPACES))
def test_discrete_observations_are_one_hot_as_in_sb3(name: str) -> None:
    space = DISCRETE_SPACES[name]
    space.seed(0)
    policy = MlpPolicy(space, spaces.Box(-1, 1, (2,)), net_arch=[4])
    samples = [space.sample() for _ in range(5)]
    if isinstance(space, spaces.Dict):
        batch: Any = {key: np.stack([s[key] for s in samples]) for key in space.spaces}
        pre = preprocess_obs({k: th.as_tensor(v) for k, v in batch.items()}, space)
        assert isinstance(pre, dict)
        expected = np.concatenate([pre[k].reshape(5, -1).numpy() for k in space.spaces], axis=1)
    else:
        batch = np.stack(samples)
        expected = preprocess_obs(th.as_tensor(batch), space).reshape(5, -1).numpy()  # type: ignore[union-attr]
    flat = policy.flatten_obs(batch)
    assert flat.shape == (5, policy.obs_dim)
    np.testing.assert_array_equal(flat, expected)
    # predict() takes single and batched observations of the space.
    assert policy.predict(samples[0])[0].shape == (2,)
    assert policy.predict(batch)[0].shape == (5, 2)


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_dict_of_multi_binary_observations(algo: Algo) -> None:
    """SB3's BitFlippingEnv (a goal env: a Dict of MultiBinary entries) trains and predicts with every algorithm."""
    env = BitFlippingEnv(n_bits=4)
    model = make_model(algo, env)
    model.learn(50)
    assert model._n_updates >= 1  # (CMA-ES may stop after one: pycma sees a flat fitness)
    obs, _ = env.reset(seed=0)
    action, _ = model.predict(obs)
    assert env.action_space.contains(int(action))


@pytest.mark.parametrize("algo", POPULATION_ALGORITHMS)
@pytest.mark.parametrize("start", [0, -1])
def test_discrete_observation_task_is_solved(algo: Algo, start: int) -> None:
    """
    A Discrete(4) observation (one-hot) whose value decides the rewarded action: the learned policy is perfect, also
    for an action space that starts at -1 (the env refuses an action outside it).
    """
    env_kwargs = dict(start=start)
    env = make_vec_env(DiscreteMatchEnv, n_envs=4, seed=0, env_kwargs=env_kwargs)
    model = algo.cls(algo.policy, env, seed=0, **algo.cartpole)  # the settings that learn CartPole
    model.learn(10_000)
    eval_env = make_vec_env(DiscreteMatchEnv, seed=1, env_kwargs=env_kwargs)
    mean_reward, _ = evaluate_policy(model, eval_env, n_eval_episodes=5)
    assert mean_reward == 10.0


# ---------------------------------------------------------------------------- success rate
@pytest.mark.parametrize("algo", ALGORITHMS)
def test_success_rate_is_logged(algo: Algo, tmp_path: Any) -> None:
    env = make_vec_env(ToyEnv, n_envs=2, wrapper_class=SuccessInfoWrapper)
    model = make_model(algo, env)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    model.learn(100)
    assert model.ep_success_buffer is not None and len(model.ep_success_buffer) > 0
    successes = list(model.ep_success_buffer)
    lines = (tmp_path / "progress.csv").read_text().splitlines()
    header, last = lines[0].split(","), lines[-1].split(",")
    rate = float(last[header.index("rollout/success_rate")])
    assert rate == pytest.approx(np.mean(successes))


# ---------------------------------------------------------------------------- the learn() budget
class GenerationLog(BaseCallback):
    """Records num_timesteps at every rollout start and end, and the VecNormalize statistics at every end."""

    def __init__(self) -> None:
        super().__init__()
        self.starts: list[int] = []
        self.ends: list[tuple[int, float]] = []

    def _on_rollout_start(self) -> None:
        self.starts.append(self.model.num_timesteps)

    def _on_rollout_end(self) -> None:
        env = self.model.get_env()
        assert isinstance(env, VecNormalize)
        self.ends.append((self.model.num_timesteps, float(env.obs_rms.count)))

    def _on_step(self) -> bool:
        return True


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_learn_stops_after_the_generation_in_flight(algo: Algo, capsys: pytest.CaptureFixture[str]) -> None:
    env = VecNormalize(make_vec_env(ToyEnv, n_envs=2))
    model = make_model(algo, env, verbose=1)
    log = GenerationLog()
    model.learn(150, callback=log)
    out = capsys.readouterr().out
    assert "overshoot by up to one" in out
    if not algo.population:
        assert "an update collects 2 episodes of at most 1000 steps" in out
    else:
        assert "= 4 episodes, at most 4000 env steps of candidates" in out
        assert "those steps count in num_timesteps too" in out
    # Every generation but the last started below the budget; the last one crossed it; none started after.
    assert len(log.starts) >= 3 and all(start < 150 for start in log.starts)
    assert log.ends[-2][0] < 150 <= log.ends[-1][0] == model.num_timesteps
    # Nothing moved after the generation in flight: the env's statistics are those at its end.
    assert float(env.obs_rms.count) == log.ends[-1][1]
    if algo.population:
        assert model._n_updates == len(log.starts)  # type: ignore[attr-defined]


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_learn_zero_steps_runs_nothing_and_returns(algo: Algo) -> None:
    model = make_model(algo, make_vec_env(ToyEnv, n_envs=2))
    for trained in (False, True):  # a new model, then one that has trained (reset_num_timesteps=True)
        before = policy_vector(model)
        recorder = GenerationRecorder()
        assert model.learn(0, callback=recorder) is model  # as PPO's learn(0)
        assert model.num_timesteps == 0 and recorder.rollout_starts == []
        assert recorder.training_started == recorder.training_ended == 1  # a progress bar or a callback is closed
        np.testing.assert_array_equal(policy_vector(model), before)
        if not trained:
            model.learn(50)


# ---------------------------------------------------------------------------- callback locals
class LocalsReader(BaseCallback):
    """
    Reads ``rewards``, ``new_obs`` and ``actions`` as an SB3 callback written for PPO does, and checks them against
    ToyEnv's dynamics: ``x`` moves by the action, ``new_obs[1]`` counts the episode's steps, and the rewards of an
    episode add up to the Monitor's return.
    """

    def __init__(self) -> None:
        super().__init__()
        self.calls = 0
        self.checked_episodes = 0
        self.obs: np.ndarray | None = None
        self.returns = np.zeros(0)

    def _on_rollout_start(self) -> None:
        self.obs = None  # the env is reset at every generation / update start

    def _on_step(self) -> bool:
        n_envs = self.training_env.num_envs
        rewards, new_obs, actions = self.locals["rewards"], self.locals["new_obs"], self.locals["actions"]
        dones, infos = self.locals["dones"], self.locals["infos"]
        assert np.shape(rewards) == (n_envs,) and np.shape(new_obs) == (n_envs, 2)
        np.testing.assert_array_equal(self.locals["clipped_actions"], actions)  # PPO's name for what the env took
        assert self.locals["iteration"] >= 0  # as PPO's learn() has it
        actions = np.asarray(actions, dtype=np.float64).reshape(n_envs)
        if self.obs is None:
            self.returns = np.zeros(n_envs)
        self.returns += rewards
        for slot in range(n_envs):
            if dones[slot]:
                np.testing.assert_allclose(self.returns[slot], infos[slot]["episode"]["r"], atol=1e-4)
                np.testing.assert_allclose(new_obs[slot], [0.1, 0.0])  # the next episode's first observation
                self.returns[slot] = 0.0
                self.checked_episodes += 1
            elif self.obs is not None:
                np.testing.assert_allclose(new_obs[slot][0] - self.obs[slot][0], actions[slot], atol=1e-5)
                np.testing.assert_allclose(new_obs[slot][1] - self.obs[slot][1], 0.1, atol=1e-6)
        self.obs = np.array(new_obs)
        self.calls += 1
        return True


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_callbacks_see_rewards_new_obs_and_actions(algo: Algo) -> None:
    env = DummyVecEnv([lambda: Monitor(ToyEnv()) for _ in range(3)])
    model = make_model(algo, env)
    reader = LocalsReader()
    model.learn(100, callback=reader)
    assert reader.calls * 3 == model.num_timesteps
    assert reader.checked_episodes >= 4
    # at most 0 after learn(), as PPO's (it stayed at the last generation's start: 0.26 for ARS)
    assert model._current_progress_remaining <= 0


def test_never_ending_env_is_registered_without_limit() -> None:
    """The test env itself: gym.make adds no TimeLimit (otherwise the tests above would test nothing)."""
    env = gym.make(NEVER_ENDING_ID)
    assert env.spec is not None and env.spec.max_episode_steps is None
    assert "TimeLimit" not in str(env)
