"""Callback calls of the model env's num_envs steps, whatever the evaluator's vec steps (``StepCalls``)."""

from __future__ import annotations

from typing import Any

import numpy as np
from envs import ToyEnv
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env

from sb3_es import ARS
from sb3_es.common.step_calls import StepCalls
from sb3_es.evaluation import VecEnvEvaluator


def vec_step(first: int, n: int) -> tuple[Any, ...]:
    """A vec step of ``n`` slots numbered from ``first``, with dict observations."""
    ids = np.arange(first, first + n)
    infos = [{"id": int(i)} for i in ids]
    return n, infos, ids % 2 == 0, ids.astype(float), {"x": ids[:, None] * 1.0}, ids[:, None] * -1.0


class Recorder:
    def __init__(self, stop_at: int | None = None) -> None:
        self.calls: list[tuple[Any, ...]] = []
        self.stop_at = stop_at

    def __call__(self, *call: Any) -> bool:
        self.calls.append(call)
        return len(self.calls) != self.stop_at


def test_vec_steps_are_cut_and_joined_in_order() -> None:
    recorder = Recorder()
    calls = StepCalls(recorder, 3)
    for first, n in [(0, 4), (4, 4), (8, 2)]:
        assert calls(*vec_step(first, n))
    assert calls.flush()
    assert [call[0] for call in recorder.calls] == [3, 3, 3, 1]
    for k, (n, infos, dones, rewards, new_obs, actions) in enumerate(recorder.calls):
        ids = np.arange(3 * k, 3 * k + n)
        assert [info["id"] for info in infos] == ids.tolist()
        np.testing.assert_array_equal(dones, ids % 2 == 0)
        np.testing.assert_array_equal(rewards, ids)
        np.testing.assert_array_equal(new_obs["x"][:, 0], ids)
        np.testing.assert_array_equal(actions[:, 0], -ids)
    assert not calls.dropped


def test_a_stop_leaves_the_rest_unshown() -> None:
    recorder = Recorder(stop_at=2)
    calls = StepCalls(recorder, 1)
    assert not calls(*vec_step(0, 4))
    assert len(recorder.calls) == 2 and calls.dropped
    # A stop at the last step of a vec step leaves nothing unshown.
    recorder = Recorder(stop_at=4)
    calls = StepCalls(recorder, 1)
    assert not calls(*vec_step(0, 4))
    assert len(recorder.calls) == 4 and not calls.dropped


class Sizes(BaseCallback):
    def __init__(self) -> None:
        super().__init__()
        self.sizes: list[int] = []
        self.obs_rows: list[int] = []

    def _on_step(self) -> bool:
        self.sizes.append(self.locals["n_envs"])
        self.obs_rows.append(len(self.locals["new_obs"]))
        return True


def test_an_evaluator_with_its_own_slots_reaches_callbacks_in_model_env_steps() -> None:
    """An evaluator instance with 4 slots on a model env of one: one call per env step, with that step's
    observation, as SB3's callbacks expect of a one-env model."""
    evaluator = VecEnvEvaluator(make_vec_env(ToyEnv, n_envs=4))
    model = ARS("LinearPolicy", ToyEnv(), n_delta=3, seed=0, evaluator=evaluator)
    callback = Sizes()
    model.learn(50, callback=callback)
    assert set(callback.sizes) == set(callback.obs_rows) == {1}
    assert callback.n_calls == model.num_timesteps >= 50
