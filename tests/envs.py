"""Small environments and wrappers shared by the tests."""

from __future__ import annotations

import csv
import os
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecEnv

from sb3_es.common.policies import FlatPolicy


class ToyEnv(gym.Env):
    """
    Fully deterministic env (the reset seed is ignored) whose reward and episode length depend on the actions.

    State: position ``x`` and time ``t``; observation ``[x, t / 10]``. Each step moves ``x`` by the action
    (``Box``) or by ``+-0.15`` (``Discrete(2)``); the reward is ``1 + x - a**2`` and the episode terminates
    when ``|x| >= 1`` or is truncated after ``max_steps``. Different parameters thus give different returns
    *and* lengths, so any mix-up of which slot runs which candidate changes the results.
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, discrete: bool = False, max_steps: int = 12, nan_reward_if_positive: bool = False) -> None:
        self.observation_space = spaces.Box(-10.0, 10.0, shape=(2,), dtype=np.float32)
        if discrete:
            self.action_space: spaces.Space = spaces.Discrete(2)
        else:
            self.action_space = spaces.Box(-0.5, 0.5, shape=(1,), dtype=np.float32)
        self.discrete = discrete
        self.max_steps = max_steps
        self.nan_reward_if_positive = nan_reward_if_positive
        self.x = 0.0
        self.t = 0

    def _obs(self) -> np.ndarray:
        return np.array([self.x, self.t / 10.0], dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.x = 0.1
        self.t = 0
        return self._obs(), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self.discrete:
            a = 0.15 if int(action) == 1 else -0.15
        else:
            a = float(np.asarray(action).reshape(-1)[0])
        self.x += a
        self.t += 1
        reward = 1.0 + self.x - a * a
        if self.nan_reward_if_positive and a > 0:
            reward = float("nan")
        terminated = abs(self.x) >= 1.0
        truncated = self.t >= self.max_steps
        return self._obs(), reward, terminated, truncated, {}


class SpaceEnv(gym.Env):
    """
    An env of given observation and action spaces: observations sampled from the space, a reward that depends on the
    action, episodes of ``max_steps``. It records every action it receives in :attr:`actions`.
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, observation_space: spaces.Space, action_space: spaces.Space, max_steps: int = 5) -> None:
        self.observation_space = observation_space
        self.action_space = action_space
        self.max_steps = max_steps
        self.actions: list[Any] = []
        self.t = 0

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[Any, dict]:
        super().reset(seed=seed)
        self.observation_space.seed(seed)
        self.t = 0
        return self.observation_space.sample(), {}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]:
        self.actions.append(action)
        self.t += 1
        reward = float(np.tanh(np.sum(np.asarray(action, dtype=np.float64)) * 1e-3))
        return self.observation_space.sample(), reward, False, self.t >= self.max_steps, {}


class ConstantObsEnv(gym.Env):
    """One-dimensional env with a constant observation ``[1]`` and episodes of ``length`` steps."""

    def __init__(self, length: int = 3, nan_reward_if_positive: bool = True) -> None:
        self.observation_space = spaces.Box(-10.0, 10.0, shape=(1,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.length = length
        self.nan_reward_if_positive = nan_reward_if_positive
        self.t = 0

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.t = 0
        return np.ones(1, dtype=np.float32), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        self.t += 1
        a = float(np.asarray(action).reshape(-1)[0])
        reward = float("nan") if self.nan_reward_if_positive and a > 0 else -abs(a)
        return np.ones(1, dtype=np.float32), reward, False, self.t >= self.length, {}


class StepCounter(gym.Wrapper):
    """Counts ``step()`` calls in a shared list ``counter`` (``counter[0]``), across every wrapped env."""

    def __init__(self, env: gym.Env, counter: list[int]) -> None:
        super().__init__(env)
        self.counter = counter

    def step(self, action: Any) -> Any:
        self.counter[0] += 1
        return self.env.step(action)


class NaNRewardWrapper(gym.Wrapper):
    """Returns a NaN reward at every step."""

    def step(self, action: Any) -> Any:
        obs, _, terminated, truncated, info = self.env.step(action)
        return obs, float("nan"), terminated, truncated, info


class MultiDiscreteActionEnv(gym.Env):
    """An env with a ``MultiDiscrete`` action space (unsupported by sb3-es policies)."""

    def __init__(self) -> None:
        self.observation_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.action_space = spaces.MultiDiscrete([3, 2])

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        return np.zeros(2, dtype=np.float32), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        return np.zeros(2, dtype=np.float32), 0.0, False, True, {}


class NeverEndingEnv(gym.Env):
    """
    An env whose episodes never end (no termination, no truncation, no time limit): the reward is ``-(a - 0.5)**2``
    for the first action entry (``Box``) or ``1`` for action ``1`` (``Discrete(2)``), the observation a sawtooth.
    """

    def __init__(self, discrete: bool = False) -> None:
        self.observation_space = spaces.Box(-10.0, 10.0, shape=(2,), dtype=np.float32)
        self.action_space: spaces.Space = (
            spaces.Discrete(2) if discrete else spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        )
        self.discrete = discrete
        self.t = 0

    def _obs(self) -> np.ndarray:
        return np.array([(self.t % 7) / 7.0, 1.0], dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.t = 0
        return self._obs(), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        self.t += 1
        if self.discrete:
            reward = float(int(action) == 1)
        else:
            reward = -((float(np.asarray(action).reshape(-1)[0]) - 0.5) ** 2)
        return self._obs(), reward, False, False, {}


#: Registered without ``max_episode_steps``, so that ``gym.make`` adds no ``TimeLimit``.
NEVER_ENDING_ID = "sb3es_tests/NeverEnding-v0"
if NEVER_ENDING_ID not in gym.registry:
    gym.register(NEVER_ENDING_ID, entry_point=NeverEndingEnv)


#: Channels-last images (SB3 wraps them in ``VecTransposeImage``), episodes of 100 steps (:class:`SpaceEnv`).
IMAGE_ID = "sb3es_tests/Image-v0"
if IMAGE_ID not in gym.registry:
    gym.register(
        IMAGE_ID,
        entry_point=SpaceEnv,
        kwargs=dict(
            observation_space=spaces.Box(0, 255, (6, 6, 3), np.uint8),
            action_space=spaces.Box(-1, 1, (1,)),
            max_steps=100,
        ),
        max_episode_steps=100,
    )


class SuccessInfoWrapper(gym.Wrapper):
    """Adds ``info["is_success"]`` at the end of each episode: True when the episode terminated (not truncated)."""

    def step(self, action: Any) -> Any:
        obs, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            info["is_success"] = bool(terminated)
        return obs, reward, terminated, truncated, info


class NaNObsWrapper(gym.Wrapper):
    """Returns observations full of NaN at the ``at``-th step of the env's life (once)."""

    def __init__(self, env: gym.Env, at: int = 3) -> None:
        super().__init__(env)
        self.at = at
        self.steps = 0

    def step(self, action: Any) -> Any:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.steps += 1
        if self.steps == self.at:
            obs = np.full_like(obs, np.nan)
        return obs, reward, terminated, truncated, info


class DiscreteMatchEnv(gym.Env):
    """
    A ``Discrete(4)`` observation drawn at random each step; the reward is 1 when the ``Discrete(4, start)`` action
    is the observation's target (``start + TARGETS[obs]``), else 0; an action outside the space raises. Episodes last
    10 steps: a policy that solves it returns 10, a random one 2.5.
    """

    TARGETS = (2, 0, 3, 1)

    def __init__(self, start: int = 0) -> None:
        self.observation_space = spaces.Discrete(4)
        self.action_space = spaces.Discrete(4, start=start)
        self.state = 0
        self.t = 0

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[int, dict]:
        super().reset(seed=seed)
        self.t = 0
        self.state = int(self.np_random.integers(4))
        return self.state, {}

    def step(self, action: Any) -> tuple[int, float, bool, bool, dict]:
        if not self.action_space.contains(int(action)):
            raise ValueError(f"action {action} is not in {self.action_space}")
        reward = float(int(action) - int(self.action_space.start) == self.TARGETS[self.state])
        self.t += 1
        self.state = int(self.np_random.integers(4))
        return self.state, reward, False, self.t >= 10, {}


def rollout(
    env: gym.Env, policy: FlatPolicy, params: np.ndarray, seed: int | None = None
) -> tuple[float, int, list[np.ndarray]]:
    """
    Run one episode sequentially with ``predict()`` of ``policy`` loaded with ``params``.

    :return: The return, the length and the flattened observations the policy acted on.
    """
    policy.load_from_vector(params)
    obs, _ = env.reset(seed=seed)
    total, length, seen = 0.0, 0, []
    while True:
        seen.append(np.asarray(obs, dtype=np.float64).reshape(-1))
        action, _ = policy.predict(obs, deterministic=True)
        obs, reward, terminated, truncated, _ = env.step(action)
        total += float(np.float32(reward))  # VecEnvs store rewards as float32
        length += 1
        if terminated or truncated:
            return total, length, seen


def counting_env(env_id: str, n_envs: int, counter: list[int], **kwargs: Any) -> VecEnv:
    """A ``make_vec_env`` VecEnv whose every env step is counted in ``counter[0]`` (see :class:`StepCounter`)."""
    return make_vec_env(
        env_id, n_envs=n_envs, wrapper_class=StepCounter, wrapper_kwargs=dict(counter=counter), **kwargs
    )


def read_csv(path: Path) -> list[dict[str, str]]:
    """Rows of an SB3 ``progress.csv``."""
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


class CrashingToyEnv(ToyEnv):
    """
    ``ToyEnv`` whose process dies (``os._exit``) at its ``crash_step``-th step if ``crash_flag`` can still be
    created (so exactly one env, in one worker, dies once), and which raises ``ValueError`` while ``error_flag``
    exists. Each step takes at least ``step_seconds``. ``raise_once``: the env raises ``ValueError`` instead of dying.
    """

    def __init__(
        self,
        crash_flag: str,
        error_flag: str,
        crash_step: int = 5,
        step_seconds: float = 0.0,
        raise_once: bool = False,
    ) -> None:
        super().__init__()
        self.crash_flag = crash_flag
        self.error_flag = error_flag
        self.crash_step = crash_step
        self.step_seconds = step_seconds
        self.raise_once = raise_once
        self.steps = 0

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        self.steps += 1
        if self.step_seconds:
            time.sleep(self.step_seconds)
        if self.steps == self.crash_step:
            try:
                os.close(os.open(self.crash_flag, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            except FileExistsError:
                pass
            else:
                if self.raise_once:
                    raise ValueError("env error raised once inside a worker")
                os._exit(1)
        if os.path.exists(self.error_flag):
            raise ValueError("env error raised inside a worker")
        return super().step(action)
