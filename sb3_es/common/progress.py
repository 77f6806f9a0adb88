"""SB3's progress bar, advanced by the env steps each callback call stands for."""

from __future__ import annotations

from stable_baselines3.common.callbacks import ProgressBarCallback


class StepsProgressBarCallback(ProgressBarCallback):
    """
    SB3's ``ProgressBarCallback``, advanced by ``n_envs`` of the step it is called for: with worker processes, Ray
    actors or an evaluator with its own envs, a generation's last call can stand for fewer env steps than the model
    env's ``num_envs`` that SB3's bar counts (see :class:`~sb3_es.common.step_calls.StepCalls`).
    """

    def _on_step(self) -> bool:
        self.pbar.update(self.locals.get("n_envs", self.training_env.num_envs))
        return True
