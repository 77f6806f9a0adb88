"""What is specific to REINFORCE with discretized actions: discretization, logged keys, save/load of the policy,
resumption with discarded episodes, Dict observations, errors, saves of older versions, non-finite rewards.

What every algorithm does (learning, step accounting, callbacks, logging, save/load) is in ``test_algorithms.py``
and ``test_save_load.py``.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from algorithms import assert_identical, check_resume, policy_state
from envs import StepCounter
from gymnasium import spaces
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_es.reinforce import REINFORCE, DiscretizedPolicy, MlpPolicy
from sb3_es.reinforce.episodes import EpisodeCollector

pytestmark = pytest.mark.usefixtures("one_torch_thread")


class BoxActionEnv(gym.Env):
    """Tiny env with a 4-dim Box action space, deterministic once seeded; records the actions it receives."""

    def __init__(self, low: np.ndarray | float = -1.0, high: np.ndarray | float = 1.0, episode_length: int = 5) -> None:
        self.observation_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        self.action_space = spaces.Box(low, high, shape=(4,), dtype=np.float32)
        self.episode_length = episode_length
        self.actions: list[np.ndarray] = []
        self._t = 0

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self._t = 0
        return self.np_random.uniform(-1, 1, size=3).astype(np.float32), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        self.actions.append(np.array(action, copy=True))
        self._t += 1
        obs = self.np_random.uniform(-1, 1, size=3).astype(np.float32)
        return obs, float(-np.sum(np.square(action))), self._t >= self.episode_length, False, {}


def counted_cartpole(n_envs: int, counter: list[int]) -> DummyVecEnv:
    return DummyVecEnv([lambda: Monitor(StepCounter(gym.make("CartPole-v1"), counter)) for _ in range(n_envs)])


def test_joint_discretization_matches_product_grid() -> None:
    model = REINFORCE("MlpPolicy", BoxActionEnv(), policy_kwargs=dict(n_bins=3, joint=True), seed=0)
    policy = model.policy
    assert policy.n_actions == 81
    assert policy.action_net.out_features == 81
    actions = policy.indices_to_actions(th.arange(81)).numpy()
    expected = np.array(list(itertools.product([-1.0, 0.0, 1.0], repeat=4)), dtype=np.float32)
    np.testing.assert_array_equal(actions, expected)


def test_integer_box_levels_are_the_nearest_distinct_integers() -> None:
    action_space = spaces.Box(np.array([0, -2]), np.array([10, 2]), dtype=np.int64)
    policy = DiscretizedPolicy(spaces.Box(-1, 1, (3,)), action_space, lambda _: 1e-3, n_bins=4)
    assert policy.action_levels.tolist() == [[0, 3, 7, 10], [-2, -1, 1, 2]]  # truncation gave [-2, 0, 0, 2]
    with pytest.raises(ValueError, match=r"n_bins=6 levels do not fit .* at most high - low \+ 1 .* \(5\)"):
        DiscretizedPolicy(spaces.Box(-1, 1, (3,)), action_space, lambda _: 1e-3, n_bins=6)
    # a constant dimension (low == high) has one action whatever n_bins: every n_bins was refused, naming 1
    constant = spaces.Box(np.array([0, 0]), np.array([0, 4]), dtype=np.int64)
    policy = DiscretizedPolicy(spaces.Box(-1, 1, (3,)), constant, lambda _: 1e-3, n_bins=3)
    assert policy.action_levels.tolist() == [[0, 0, 0], [0, 2, 4]]
    with pytest.raises(ValueError, match=r"n_bins=6 .* narrowest non-constant dimension \(5\)"):
        DiscretizedPolicy(spaces.Box(-1, 1, (3,)), constant, lambda _: 1e-3, n_bins=6)


def test_the_learning_rate_in_optimizer_kwargs_is_refused_by_name() -> None:
    # it failed in torch: "Adam() got multiple values for keyword argument 'lr'"
    with pytest.raises(ValueError, match=r"REINFORCE's learning_rate argument .* leave lr out of optimizer_kwargs"):
        REINFORCE("MlpPolicy", "Pendulum-v1", policy_kwargs=dict(optimizer_kwargs=dict(lr=1e-3)))


def test_factorized_discretization_and_actions_on_grid() -> None:
    low = np.array([-2.0, 0.0, -1.0, 3.0], dtype=np.float32)
    high = np.array([2.0, 1.0, 0.0, 5.0], dtype=np.float32)
    env = BoxActionEnv(low, high)
    model = REINFORCE("MlpPolicy", env, n_episodes=2, policy_kwargs=dict(n_bins=5, joint=False), seed=0)
    policy = model.policy
    assert policy.action_net.out_features == 5 * 4
    levels = np.linspace(low, high, 5, axis=1)
    np.testing.assert_allclose(policy.action_levels.numpy(), levels)

    model.learn(50)
    obs = np.random.default_rng(0).uniform(-1, 1, size=(200, 3)).astype(np.float32)
    for deterministic in (True, False):
        actions, _ = model.predict(obs, deterministic=deterministic)
        assert actions.shape == (200, 4)
        for d in range(4):
            assert set(np.unique(actions[:, d])) <= set(levels[d].astype(np.float32))
    # The actions the env received during training are on the grid too, and inside the Box.
    received = np.array(env.actions)
    assert all(env.action_space.contains(a) for a in received)
    for d in range(4):
        assert set(np.unique(received[:, d])) <= set(levels[d].astype(np.float32))
    # Stochastic predictions use several levels of each dimension (near-uniform initial policy).
    sampled, _ = model.predict(obs, deterministic=False)
    assert all(len(np.unique(sampled[:, d])) >= 3 for d in range(4))


def test_joint_predict_on_grid_single_observation() -> None:
    env = BoxActionEnv()
    model = REINFORCE("MlpPolicy", env, policy_kwargs=dict(joint=True), seed=1)
    obs, _ = env.reset(seed=0)
    action, _ = model.predict(obs, deterministic=True)
    assert action.shape == (4,)
    assert set(np.unique(action)) <= {-1.0, 0.0, 1.0}


def test_native_discrete_actions() -> None:
    model = REINFORCE("MlpPolicy", "CartPole-v1", n_episodes=2, seed=0)
    assert model.policy.n_actions == 2
    model.learn(100)
    obs = np.zeros((10, 4), dtype=np.float32)
    actions, _ = model.predict(obs, deterministic=False)
    assert actions.shape == (10,)
    assert set(np.unique(actions)) <= {0, 1}

    policy = DiscretizedPolicy(spaces.Box(-1, 1, (2,)), spaces.Discrete(3, start=-1), lambda _: 1e-3)
    actions, _ = policy.predict(np.zeros((50, 2), dtype=np.float32))
    assert set(np.unique(actions)) <= {-1, 0, 1}


def test_save_load_round_trip(tmp_path: Path) -> None:
    kwargs = dict(n_bins=3, joint=True, net_arch=[32])
    model = REINFORCE("MlpPolicy", BoxActionEnv(), n_episodes=2, use_baseline=True, policy_kwargs=kwargs, seed=0)
    model.learn(40)
    path = tmp_path / "reinforce.zip"
    model.save(path)
    loaded = REINFORCE.load(path)
    assert loaded.policy.joint and loaded.policy.use_baseline and loaded.policy.n_actions == 81
    obs = np.random.default_rng(0).uniform(-1, 1, size=(64, 3)).astype(np.float32)
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])
    th.manual_seed(7)
    stochastic = model.predict(obs, deterministic=False)[0]
    th.manual_seed(7)
    np.testing.assert_array_equal(stochastic, loaded.predict(obs, deterministic=False)[0])
    for a, b in zip(model.policy.state_dict().values(), loaded.policy.state_dict().values()):
        assert th.equal(a, b)


@pytest.mark.parametrize("use_baseline", [False, True])
def test_resume_with_discarded_episodes_and_a_baseline(tmp_path: Path, use_baseline: bool) -> None:
    """The generic check (``test_save_load.py``) with 3 env slots (episodes discarded), gradient clipping, entropy."""
    kwargs: dict[str, Any] = dict(n_episodes=4, use_baseline=use_baseline, max_grad_norm=0.5, ent_coef=0.01, seed=3)
    check_resume(
        lambda env: REINFORCE("MlpPolicy", env, **kwargs), lambda: counted_cartpole(3, [0]), 1_500, tmp_path / "a.zip"
    )


def value_layers(model: REINFORCE) -> list[int]:
    """:return: The output sizes of the value network's linear layers (hidden layers, then the value head)."""
    modules = [*model.policy.mlp_extractor.value_net, model.policy.value_net]
    return [m.out_features for m in modules if isinstance(m, th.nn.Linear)]


def value_parameters(model: REINFORCE) -> list[np.ndarray]:
    """:return: Copies of the value network's parameters (hidden layers, then the value head)."""
    modules = [model.policy.mlp_extractor.value_net, model.policy.value_net]
    return [p.detach().cpu().numpy().copy() for module in modules for p in module.parameters()]


@pytest.mark.parametrize(
    "policy_kwargs, expected",
    [
        (dict(net_arch=dict(pi=[8], vf=[5, 4])), [5, 4, 1]),
        (dict(net_arch=dict(pi=[8])), [1]),  # no vf entry: [] as in SB3 (a linear baseline)
        (dict(net_arch=[8], value_net_arch=[5]), [5, 1]),
        (dict(net_arch=[8], value_net_arch=[]), [1]),
        (dict(net_arch=[8]), [8, 1]),  # default: the policy's layers
    ],
)
def test_baseline_layers_from_net_arch(policy_kwargs: dict[str, Any], expected: list[int]) -> None:
    model = REINFORCE("MlpPolicy", BoxActionEnv(), use_baseline=True, policy_kwargs=policy_kwargs, seed=0)
    assert value_layers(model) == expected
    assert model.policy.policy_net_arch == [8]
    # A2C's actor-critic form trains the baseline as A2C trains its critic: every value parameter moves.
    before = value_parameters(model)
    model.learn(20)
    assert model._n_updates >= 1
    after = value_parameters(model)
    assert len(after) == 2 * len(expected)  # a weight and a bias per layer
    assert all(not np.array_equal(a, b) for a, b in zip(before, after))


def test_dict_observations_with_a_baseline_and_discretized_actions() -> None:
    """
    What the generic check (``test_algorithms.py``, dm_control's walker-walk) leaves to REINFORCE: the baseline
    trains on Dict observations, actions are the bins' levels, and the alias "MlpPolicy" takes Dict observations.
    """
    import shimmy  # noqa: F401  (registers the dm_control/ envs)

    env = gym.make("dm_control/walker-walk-v0", max_episode_steps=50)
    model = REINFORCE("MultiInputPolicy", env, n_episodes=2, use_baseline=True, seed=0)
    before = value_parameters(model)
    model.learn(100)
    assert all(not np.array_equal(a, b) for a, b in zip(before, value_parameters(model)))
    obs, _ = env.reset(seed=0)
    action, _ = model.predict(obs, deterministic=True)
    assert action.shape == (6,)
    assert set(np.unique(action)) <= {-1.0, 0.0, 1.0}
    # The alias "MlpPolicy" works with Dict observations too (they are flattened).
    assert REINFORCE("MlpPolicy", env, policy_kwargs=dict(joint=True)).policy.n_actions == 3**6
    env.close()


class _MultiDiscreteEnv(BoxActionEnv):
    def __init__(self, action_space: spaces.Space) -> None:
        super().__init__()
        self.action_space = action_space  # type: ignore[assignment]


@pytest.mark.parametrize("action_space", [spaces.MultiDiscrete([3, 3]), spaces.MultiBinary(4)])
def test_unsupported_action_spaces(action_space: spaces.Space) -> None:
    with pytest.raises(ValueError, match="Unsupported action space"):
        REINFORCE("MlpPolicy", _MultiDiscreteEnv(action_space))
    with pytest.raises(ValueError, match="Unsupported action space"):
        MlpPolicy(spaces.Box(-1, 1, (3,)), action_space, lambda _: 1e-3)


def test_joint_action_space_too_large_suggests_factorized() -> None:
    box17 = spaces.Box(-1, 1, (17,), dtype=np.float32)
    with pytest.raises(ValueError, match=r"3\*\*17 = 129140163 actions.*factorized"):
        DiscretizedPolicy(spaces.Box(-1, 1, (3,)), box17, lambda _: 1e-3, joint=True)
    factorized = DiscretizedPolicy(spaces.Box(-1, 1, (3,)), box17, lambda _: 1e-3, joint=False)
    assert factorized.action_net.out_features == 3 * 17


# ---------------------------------------------------------------------------- saves of older versions
FIXTURES = Path(__file__).parent / "fixtures"


@pytest.mark.parametrize("name", ["joint_baseline", "factorized"])
def test_loads_zip_saved_before_the_actor_critic_policy(name: str) -> None:
    """
    ``reinforce_*_v0.zip`` were saved by main at fcb4e90, when the policy had its own ``policy_net`` /
    ``value_net`` MLPs; the expected outputs, and the weights after 30 more steps, were recorded by that code.
    """
    expected = np.load(FIXTURES / "reinforce_v0_expected.npz")
    obs = expected["obs"]
    model = REINFORCE.load(FIXTURES / f"reinforce_{name}_v0.zip", env=BoxActionEnv(), device="cpu")
    assert isinstance(model.policy, ActorCriticPolicy)
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], expected[f"{name}_actions"])
    with th.no_grad():
        obs_tensor = th.as_tensor(obs)
        indices = model.policy(obs_tensor, deterministic=True)
        log_prob = model.policy.get_distribution(obs_tensor).log_prob(indices)
        np.testing.assert_allclose(log_prob.numpy(), expected[f"{name}_log_prob"], rtol=1e-5)
        if model.policy.use_baseline:
            values = model.policy.predict_values(obs_tensor).flatten()
            np.testing.assert_allclose(values.numpy(), expected[f"{name}_values"], rtol=1e-5)
    # Training continues exactly as the old code did: Adam's moments went to the right parameters.
    model.learn(30, reset_num_timesteps=False)
    assert model.num_timesteps == int(expected[f"{name}_resumed_num_timesteps"])
    np.testing.assert_allclose(
        model.policy.action_net.weight.detach().numpy(), expected[f"{name}_resumed_action_net_weight"], atol=1e-6
    )


# ---------------------------------------------------------------------------- non-finite rewards
class NaNRewardAt(BoxActionEnv):
    """Rewards NaN at the ``nan_step``-th step since the env was created."""

    def __init__(self, nan_step: int) -> None:
        super().__init__()
        self.nan_step = nan_step
        self.steps = 0

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        obs, reward, terminated, truncated, info = super().step(action)
        self.steps += 1
        return obs, float("nan") if self.steps == self.nan_step else reward, terminated, truncated, info


@pytest.mark.parametrize("use_baseline", [False, True])
def test_nan_reward_refused_naming_step_and_episode(use_baseline: bool) -> None:
    """Episodes of 5 steps, 2 per update: the 18th step is step 3 of episode 2 of the second update."""
    kwargs: dict[str, Any] = dict(n_episodes=2, use_baseline=use_baseline, seed=0)
    reference = REINFORCE("MlpPolicy", DummyVecEnv([BoxActionEnv]), **kwargs).learn(10)
    model = REINFORCE("MlpPolicy", DummyVecEnv([lambda: NaNRewardAt(18)]), **kwargs)
    with pytest.raises(ValueError, match=r"reward nan at step 3 of episode 2 \(env slot 0\) in update 2"):
        model.learn(100)
    # The first update was applied, the second refused: the weights are finite, those of one update.
    assert model._n_updates == 1
    assert_identical(policy_state(model), policy_state(reference))


@pytest.mark.parametrize("discarded_reward", [float("nan"), float("inf")])
def test_a_non_finite_reward_in_a_discarded_episode_leaves_the_kept_returns(discarded_reward: float) -> None:
    """Slot 0 ends its kept episode at step 2, then plays a discarded one while slot 1 ends its kept episode."""
    returns = []
    for reward in (1.0, discarded_reward):
        collector = EpisodeCollector(n_episodes=2, n_envs=2)
        steps = [([1.0, 1.0], [False, False]), ([1.0, 1.0], [True, False]), ([reward, 1.0], [False, True])]
        for rewards, dones in steps:
            collector.add(np.zeros((2, 1)), np.zeros(2, dtype=int), np.array(rewards), np.array(dones), [{}, {}])
        returns.append(collector.batch(0.5, update=1).returns)
    np.testing.assert_array_equal(returns[1], returns[0])
    np.testing.assert_array_equal(returns[0], [1.5, 1.75, 1.0, 1.5, 1.0])


@pytest.mark.parametrize("env_id", ["CartPole-v1", "Pendulum-v1"])
def test_a_policy_saved_alone_loads_and_acts_the_same(env_id: str, tmp_path: Path) -> None:
    # SB3's policy.save() / Policy.load() rebuild the policy from its constructor parameters (Discrete actions: the
    # default n_bins, which the policy accepts there)
    model = REINFORCE("MlpPolicy", env_id, n_episodes=2, seed=0)
    model.learn(400)
    model.policy.save(tmp_path / "policy.zip")
    loaded = DiscretizedPolicy.load(tmp_path / "policy.zip")
    obs = np.stack([model.observation_space.sample() for _ in range(8)])
    np.testing.assert_array_equal(loaded.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0])


@pytest.mark.parametrize(
    "space, obs, one_hot",
    [
        (spaces.Discrete(3, start=2), [2, 3, 4], np.eye(3)),
        (spaces.MultiDiscrete([2, 3], start=[1, -1]), [[1, -1], [2, 1]], [[1, 0, 1, 0, 0], [0, 1, 0, 0, 1]]),
    ],
)
def test_discrete_observations_with_a_start_are_one_hot_from_their_start(
    space: spaces.Space, obs: Any, one_hot: Any
) -> None:
    """The lowest value is the first class, as for the population policies (SB3 alone fails on it)."""
    policy = MlpPolicy(space, spaces.Discrete(2), lambda _: 1e-3)
    features = policy.extract_features(th.as_tensor(np.asarray(obs)))
    np.testing.assert_array_equal(features.numpy(), np.asarray(one_hot, dtype=np.float32))
