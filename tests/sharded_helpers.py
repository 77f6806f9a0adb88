"""Helpers for the tests of the sharded evaluators (worker processes, Ray actors)."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from envs import ToyEnv
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv

from sb3_es import ARS
from sb3_es.common.policies import MlpPolicy
from sb3_es.evaluation import PopulationResult
from sb3_es.evaluation.sharded import ShardedEvaluator

ENVS_PER_WORKER = 2
POLICY_KWARGS = dict(net_arch=[8])


def remote_steps(evaluator: ShardedEvaluator) -> int:
    """:return: Env steps counted by the workers' ``StepCounter`` wrappers since the last call (then reset)."""

    def read_and_reset(venv: VecEnv) -> int:
        counter = venv.get_attr("counter")[0]
        count, counter[0] = counter[0], 0
        return count

    return sum(evaluator.call_workers(read_and_reset))


def toy_policy() -> MlpPolicy:
    env = ToyEnv()
    policy = MlpPolicy(env.observation_space, env.action_space, **POLICY_KWARGS)
    # Non-trivial observation statistics, so that the workers must receive them to act as locally.
    policy.update_obs_rms(np.array([0.2, 0.3]), np.array([0.5, 0.2]), 10)
    return policy


def toy_population(policy: MlpPolicy, n: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(scale=0.5, size=(n, policy.num_params))


def assert_same_candidates(remote: PopulationResult, local: PopulationResult) -> None:
    np.testing.assert_array_equal(remote.returns, local.returns)
    np.testing.assert_array_equal(remote.lengths, local.lengths)
    assert remote.obs_stats.count == local.obs_stats.count
    # The same moments; only the order of the float64 merges differs.
    np.testing.assert_allclose(remote.obs_stats.mean, local.obs_stats.mean, rtol=1e-12)
    np.testing.assert_allclose(remote.obs_stats.var, local.obs_stats.var, rtol=1e-10)
    assert len(remote.ep_infos) == len(local.ep_infos)
    assert not remote.stopped


class ReplayCounter(BaseCallback):
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


def make_ars(env: Any, **kwargs: Any) -> ARS:
    return ARS("MlpPolicy", env, n_delta=3, seed=1, policy_kwargs=POLICY_KWARGS, **kwargs)


def learn_generations(model: ARS, n: int, callback: BaseCallback | None = None) -> None:
    for i in range(n):
        model.learn(1, callback=callback, reset_num_timesteps=i == 0)


def gone(pid: int) -> bool:
    """:return: Whether process ``pid`` has ended (a zombie waiting for its parent to read its status counts)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] == "Z"
    except FileNotFoundError:
        return True


def wait_gone(pids: list[int], timeout: float = 30.0) -> bool:
    """:return: Whether every process of ``pids`` ended within ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if all(gone(pid) for pid in pids):
            return True
        time.sleep(0.1)
    return False
