"""What every sb3-es algorithm adds to SB3's ``BaseAlgorithm``: alias resolution, a name in the save, safe load."""

from __future__ import annotations

import io
import pathlib
from typing import Any, TypeVar

import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, Schedule

from sb3_es.common.save_util import check_save_file

SelfESBaseAlgorithm = TypeVar("SelfESBaseAlgorithm", bound="ESBaseAlgorithm")


class ESBaseAlgorithm(BaseAlgorithm):
    """
    Base class of the sb3-es algorithms.

    - Policy aliases are resolved before SB3 sees them: SB3 rejects the alias ``"MlpPolicy"`` for Dict
      observations, which sb3-es policies flatten.
    - The algorithm's name is saved (``_algorithm_name``), so ``load()`` can tell a foreign or mismatched
      file apart and say which class wrote it.
    - ``load()`` first checks the file (:func:`~sb3_es.common.save_util.check_save_file`) and raises
      ``ValueError`` for a corrupt file or another algorithm's save; subclasses check their own state in
      :meth:`_check_save_data`.

    :param policy: Policy class or alias.
    :param env: Environment, env id or VecEnv.
    :param learning_rate: Learning rate or schedule (``None`` for algorithms without one).
    :param policy_kwargs: Keyword arguments for the policy.
    :param stats_window_size: Episodes averaged in ``rollout/ep_rew_mean``.
    :param tensorboard_log: TensorBoard log directory.
    :param verbose: Verbosity.
    :param device: Torch device.
    :param seed: Random seed.
    """

    def __init__(
        self,
        policy: str | type[BasePolicy],
        env: GymEnv | str | None,
        learning_rate: float | Schedule | None,
        policy_kwargs: dict[str, Any] | None,
        stats_window_size: int,
        tensorboard_log: str | None,
        verbose: int,
        device: th.device | str,
        seed: int | None,
    ) -> None:
        if isinstance(policy, str):
            policy = self._get_policy_from_name(policy)
        super().__init__(
            policy,
            env,
            learning_rate=learning_rate,  # type: ignore[arg-type]  # None: the algorithm has no learning rate
            policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            device=device,
            support_multi_env=True,
            seed=seed,
        )
        self._algorithm_name = type(self).__name__

    @classmethod
    def _check_save_data(cls, path: str | pathlib.Path | io.BufferedIOBase, data: dict[str, Any]) -> None:
        """
        Check the algorithm-specific state of a save before loading it (override to add checks).

        :param path: The file, for error messages.
        :param data: The save's data dictionary.
        """

    @classmethod
    def load(  # type: ignore[override]
        cls: type[SelfESBaseAlgorithm],
        path: str | pathlib.Path | io.BufferedIOBase,
        env: GymEnv | None = None,
        device: th.device | str = "auto",
        custom_objects: dict[str, Any] | None = None,
        print_system_info: bool = False,
        force_reset: bool = True,
        **kwargs: Any,
    ) -> SelfESBaseAlgorithm:
        """
        Load a model saved by ``save()``, with everything needed to continue training where it stopped.

        Raises ``ValueError`` for a corrupt file or one saved by another algorithm.

        :param path: Path or file-like object of the zip archive.
        :param env: Environment to continue training on (optional for ``predict()``).
        :param device: Torch device.
        :param custom_objects: Objects replacing saved ones, as in SB3.
        :param print_system_info: Print the system info of the save and of this machine.
        :param force_reset: Reset the env before training.
        :param kwargs: Attributes to override.
        :return: The loaded model.
        """
        data = check_save_file(path, cls.__name__)
        cls._check_save_data(path, data)
        return super().load(path, env, device, custom_objects, print_system_info, force_reset, **kwargs)
