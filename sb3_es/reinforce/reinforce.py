"""
REINFORCE (Williams, 1992) with discretized actions, as an SB3 algorithm.

(About 300 lines, one class: as in SB3's algorithms, its typed ``__init__`` and the documentation of its parameters
take more than a third of them; the episode collection is in :mod:`~sb3_es.reinforce.episodes`.)
"""

from __future__ import annotations

import warnings
from typing import Any, ClassVar, TypeVar

import numpy as np
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from stable_baselines3.common.utils import obs_as_tensor
from stable_baselines3.common.vec_env import VecEnv
from torch.nn import functional as F

from sb3_es.common.arguments import base_arguments
from sb3_es.common.base_class import ESBaseAlgorithm, constant_value, python_number
from sb3_es.common.checks import (
    check_policy_class,
    check_policy_kwarg_names,
    check_policy_kwargs,
    check_scheduled_value,
)
from sb3_es.evaluation.time_limit import end_capped_episodes
from sb3_es.reinforce.episodes import EpisodeBatch, EpisodeCollector, check_rewards
from sb3_es.reinforce.legacy import upgrade_legacy_optimizer_state
from sb3_es.reinforce.policies import DiscretizedPolicy, MlpPolicy, MultiInputPolicy, check_action_space
from sb3_es.strategies.base import check_count, check_flag, check_number

SelfREINFORCE = TypeVar("SelfREINFORCE", bound="REINFORCE")

#: Added to the standard deviation when normalizing returns.
RETURN_NORM_EPS = 1e-8

__all__ = ["RETURN_NORM_EPS", "REINFORCE", "EpisodeBatch", "check_rewards"]


class REINFORCE(ESBaseAlgorithm):
    """
    REINFORCE, the Monte-Carlo policy gradient (Williams, 1992), with discretized actions.

    Each update collects ``n_episodes`` complete episodes with the current stochastic policy, computes
    the discounted returns-to-go ``G_t``, normalizes them across the batch (``normalize_returns``), and
    takes one optimizer step on ``-mean_t[(G_t - b(s_t)) log pi(a_t | s_t)]`` over all the steps of the
    batch. ``Box`` actions are discretized by :class:`~sb3_es.reinforce.policies.DiscretizedPolicy`
    into ``n_bins`` levels per dimension (joint or factorized categorical, see ``policy_kwargs``).

    Episode collection (:class:`~sb3_es.reinforce.episodes.EpisodeCollector`): the ``n_episodes`` episodes are
    split in advance between the VecEnv's slots, which play them in parallel; a slot done with its share keeps
    stepping (a VecEnv steps all slots together) and the episodes it plays then are *discarded*, as is any episode
    still running when the last needed one ends: fixing the episodes in advance avoids the bias towards short
    episodes of "the first ``n_episodes`` to finish". Every env step counts in ``num_timesteps``, discarded ones
    included, and their Monitor statistics still go to ``rollout/ep_rew_mean``. Use ``n_episodes`` a multiple of
    ``n_envs`` to waste few steps.

    Each update starts with ``env.seed(s)`` and ``env.reset()``, and samples its actions from a torch
    generator seeded with ``s'``, where ``s, s'`` come from a random generator stored in the model
    (seeded by ``seed``) and saved with it. Training is therefore reproducible for a fixed ``seed``
    (with ``DummyVecEnv``), and ``learn(n)``, ``save``, ``load``, then
    ``learn(total - model.num_timesteps, reset_num_timesteps=False)`` ends with the same parameters as
    ``learn(total)`` (updates end at episode boundaries, so ask the second call for what is left). Episodes
    cut by a time limit are treated like terminated ones (no bootstrapping), as in the original algorithm.

    :param policy: ``"MlpPolicy"``, ``"MultiInputPolicy"`` or a :class:`DiscretizedPolicy` class.
    :param env: Environment, env id or VecEnv (its slots collect episodes in parallel).
    :param learning_rate: Adam learning rate, a float or a schedule of the remaining progress.
    :param n_episodes: Complete episodes per update.
    :param gamma: Discount factor in ``[0, 1]``.
    :param normalize_returns: Normalize the discounted returns to zero mean and unit standard deviation
        across all the steps of the batch (as in the classic REINFORCE/CartPole recipe). With
        ``use_baseline``, the value network learns the (normalized) returns and is subtracted from them.
    :param use_baseline: Subtract a learned state value ``b(s_t)`` (a separate MLP, trained jointly by
        regression on the returns) from the returns.
    :param ent_coef: Entropy bonus coefficient (0 is plain REINFORCE).
    :param max_grad_norm: Clip the gradient norm to this value (``None``: no clipping).
    :param policy_kwargs: Keyword arguments for the policy: ``n_bins`` (levels per dimension, default 3),
        ``joint`` (joint categorical over all combinations instead of one per dimension), ``net_arch``,
        ``activation_fn``, ``value_net_arch``, ``optimizer_class``, ...
    :param stats_window_size: Number of episodes averaged in ``rollout/ep_rew_mean``.
    :param tensorboard_log: TensorBoard log directory.
    :param seed: Seed for the policy initialization, the environments and the action sampling.
    :param verbose: 0 none, 1 training information, 2 debug.
    :param device: Torch device (``"auto"``: CUDA if available). Small MLPs run best on the CPU.
    :param max_episode_steps: Longest episode training runs, in env steps (an episode reaching it is truncated);
        ``None``: the env's ``TimeLimit``, or 1000 steps, with a warning, for an env without one.
    :param _init_setup_model: Whether to build the model at construction.
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {
        "MlpPolicy": MlpPolicy,
        "MultiInputPolicy": MultiInputPolicy,
    }
    policy: DiscretizedPolicy
    _check_action_space = staticmethod(check_action_space)
    _live_hyperparameters: ClassVar[tuple[str, ...]] = (
        *ESBaseAlgorithm._live_hyperparameters,
        "learning_rate",  # SB3's load() rebuilds lr_schedule; the optimizer takes it at every update
        "n_episodes",
        "gamma",
        "normalize_returns",
        "ent_coef",
        "max_grad_norm",
    )

    @classmethod
    def _check_live_values(cls, values: dict[str, Any]) -> None:
        check_count("n_episodes", values.get("n_episodes", 1))
        check_flag("normalize_returns", values.get("normalize_returns", True))
        if not 0.0 <= check_number("gamma", values.get("gamma", 0.0)) <= 1.0:
            raise ValueError(f"gamma={values['gamma']}: the discount factor must be in [0, 1].")
        max_grad_norm = values.get("max_grad_norm")
        if max_grad_norm is not None and not check_number("max_grad_norm", max_grad_norm) > 0:
            raise ValueError(f"max_grad_norm={max_grad_norm}: it must be a positive number or None.")
        if not np.isfinite(check_number("ent_coef", values.get("ent_coef", 0.0))):
            raise ValueError(f"ent_coef={values['ent_coef']}: it must be a finite number.")
        super()._check_live_values(values)

    def __init__(
        self,
        policy: str | type[DiscretizedPolicy],
        env: GymEnv | str | None,
        learning_rate: float | Schedule = 1e-2,
        n_episodes: int = 10,
        gamma: float = 0.99,
        normalize_returns: bool = True,
        use_baseline: bool = False,
        ent_coef: float = 0.0,
        max_grad_norm: float | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        seed: int | None = None,
        verbose: int = 0,
        device: th.device | str = "auto",
        max_episode_steps: int | None = None,
        _init_setup_model: bool = True,
    ) -> None:
        learning_rate = constant_value(learning_rate)  # rl-zoo's constant schedule or "lin_X", a NumPy number
        self._check_live_values(
            dict(
                n_episodes=n_episodes,
                gamma=gamma,
                max_grad_norm=max_grad_norm,
                ent_coef=ent_coef,
                learning_rate=learning_rate,
            )
        )
        check_policy_kwargs(policy_kwargs)
        if policy_kwargs is not None and "use_baseline" in policy_kwargs:
            raise ValueError("Pass use_baseline to REINFORCE, not in policy_kwargs.")
        value_net_arch = (policy_kwargs or {}).get("value_net_arch")
        if value_net_arch and not use_baseline:  # checked here, not in the policy: saves from before still load
            raise ValueError(
                f"value_net_arch={value_net_arch!r} gives the layers of REINFORCE's baseline, which is off: pass "
                "use_baseline=True to REINFORCE, or drop value_net_arch."
            )
        super().__init__(**base_arguments(super().__init__, locals()))
        self.n_episodes = int(n_episodes)
        self.gamma = float(gamma)
        self.normalize_returns = check_flag("normalize_returns", normalize_returns)
        self.use_baseline = check_flag("use_baseline", use_baseline)
        self.ent_coef = float(ent_coef)
        self.max_grad_norm = python_number(max_grad_norm)
        #: Random generator of the per-update env and sampling seeds (saved with the model).
        self._rng: np.random.Generator | None = None
        if _init_setup_model:
            self._setup_model()

    # ------------------------------------------------------------------ model
    def _setup_model(self) -> None:
        self._setup_lr_schedule()
        BaseAlgorithm.set_random_seed(self, self.seed)  # not _reseed_streams: a loaded model continues its own
        check_policy_class("REINFORCE", self.policy_class, DiscretizedPolicy, self.policy_aliases)
        check_policy_kwarg_names(self.policy_class, self.policy_kwargs)
        self.policy = self.policy_class(  # type: ignore[assignment]
            self.observation_space,
            self.action_space,
            self.lr_schedule,
            use_baseline=self.use_baseline,
            **self.policy_kwargs,
        ).to(self.device)
        if self._rng is None:  # a loaded model brings its own generator (and its state)
            self._rng = np.random.default_rng(self.seed)

    def _reseed_streams(self, seed: int) -> None:
        if self._rng is not None:
            self._rng = np.random.default_rng(seed)  # as _setup_model starts it

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        return ["policy", "policy.optimizer"], []

    def _upgrade_saved_params(self, params: dict[str, Any]) -> dict[str, Any]:
        # The policy renames old keys itself; the optimizer state must follow its new parameter order.
        if "policy" in params and "policy.optimizer" in params:
            optimizer = upgrade_legacy_optimizer_state(self.policy, params["policy"], params["policy.optimizer"])
            params = {**params, "policy.optimizer": optimizer}
        return params

    # ------------------------------------------------------------------ training
    def learn(
        self: SelfREINFORCE,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 1,
        tb_log_name: str = "REINFORCE",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfREINFORCE:
        """
        Train for at least ``total_timesteps`` env steps.

        Training stops at an update's end: the update during which ``num_timesteps`` reaches ``total_timesteps``
        completes its episodes and is applied (so the run can overshoot by up to one update), and no further one
        is started. With ``verbose >= 1`` the size of an update is printed at the start.

        :param total_timesteps: Env steps to train for.
        :param callback: Callback(s) called at every vec step; returning False stops training at once
            (the episodes of the interrupted update are discarded, the parameters are those of the last update).
        :param log_interval: Number of updates between two log dumps.
        :param tb_log_name: Name of the TensorBoard run.
        :param reset_num_timesteps: Whether to reset ``num_timesteps`` (False to continue a run).
        :param progress_bar: Display a progress bar (tqdm and rich).
        :return: The trained model.
        """
        iteration = 0
        if self.env is None:
            raise ValueError("This model has no environment: pass env= to load() or call set_env() before learn().")
        total_timesteps, callback = self._setup_learn(
            total_timesteps, callback, reset_num_timesteps, tb_log_name, progress_bar
        )
        callback.on_training_start(locals(), globals())
        if self.n_episodes < self.env.num_envs:
            warnings.warn(
                f"n_episodes={self.n_episodes} < n_envs={self.env.num_envs}: some env slots collect no episode "
                "and their steps are wasted (they still count in num_timesteps).",
                stacklevel=2,
            )
        if self.verbose >= 1:
            max_steps = self.episode_step_limit()
            print(
                f"REINFORCE: an update collects {self.n_episodes} episodes of at most {max_steps} steps (up to "
                f"{self.n_episodes * max_steps} kept env steps, plus the steps of env slots done with their share). "
                f"learn() stops at the end of the update during which num_timesteps reaches {total_timesteps}, so "
                "it can overshoot by up to one update."
            )
        while self.num_timesteps < total_timesteps:
            batch = self.collect_episodes(self.env, callback)
            if batch is None:
                break
            iteration += 1
            # The last update may end past total_timesteps: the progress stops at 0 (a learning rate schedule
            # that ends at 0 gives 0, not a negative step).
            self._update_current_progress_remaining(min(self.num_timesteps, total_timesteps), total_timesteps)
            progress = self._current_progress_remaining
            # The given schedule, not SB3's lr_schedule (which converts its value with float(): "1e-3" passes).
            value = self.learning_rate(progress) if callable(self.learning_rate) else self.learning_rate
            check_scheduled_value("learning_rate", value, progress, allow_zero=True)
            self.train(batch)
            if log_interval is not None and iteration % log_interval == 0:
                self.dump_logs(iteration)
        callback.on_training_end()
        return self

    def collect_episodes(self, env: VecEnv, callback: BaseCallback) -> EpisodeBatch | None:
        """
        Collect ``n_episodes`` complete episodes with the current policy (see the class docstring).

        :param env: The training VecEnv.
        :param callback: Callback called once per vec step.
        :return: The batch, or ``None`` if a callback stopped training.
        """
        assert self._rng is not None
        n_envs = env.num_envs
        max_steps = self.episode_step_limit()
        episodes = EpisodeCollector(self.n_episodes, n_envs)
        env_seed, sample_seed = (int(s) for s in self._rng.integers(2**31 - 1 - n_envs, size=2))
        generator = th.Generator(device=self.device)
        generator.manual_seed(sample_seed)
        env.seed(env_seed)
        obs = env.reset()
        self.policy.set_training_mode(False)
        callback.on_rollout_start()
        while not episodes.complete:
            with th.no_grad():
                indices = self.policy(obs_as_tensor(obs, self.device), generator=generator)  # type: ignore[arg-type]
                actions = self.policy.indices_to_actions(indices).cpu().numpy()
            actions = actions.reshape((n_envs, *self.action_space.shape))  # type: ignore[misc]
            clipped_actions = actions  # noqa: F841  (PPO's local for what the env took: the levels lie in the bounds)
            new_obs, rewards, dones, infos = env.step(actions)
            end_capped_episodes(env, max_steps, episodes.ep_length + 1, new_obs, dones, infos)  # type: ignore[arg-type]
            self.num_timesteps += n_envs
            callback.update_locals(locals())
            if not callback.on_step():
                return None
            self._update_info_buffer(infos, dones)
            unmonitored = episodes.add(obs, indices.cpu().numpy(), rewards, dones, infos)
            if unmonitored:  # no Monitor: report what was measured here
                self._update_info_buffer(unmonitored)
            obs = new_obs
        callback.on_rollout_end()
        return episodes.batch(self.gamma, self._n_updates + 1)

    def train(self, batch: EpisodeBatch) -> None:
        """
        One policy-gradient step (and value regression with a baseline) on a batch of episodes.

        :param batch: Episodes from :meth:`collect_episodes`.
        """
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        obs = obs_as_tensor(batch.observations, self.device)
        indices = th.as_tensor(batch.indices, device=self.device)
        returns = th.as_tensor(batch.returns, dtype=th.float32, device=self.device)
        if self.normalize_returns:
            returns = (returns - returns.mean()) / (returns.std(unbiased=False) + RETURN_NORM_EPS)

        values, log_prob, entropy = self.policy.evaluate_actions(obs, indices)  # type: ignore[arg-type]
        assert entropy is not None  # categorical distributions have an exact entropy
        values = values.flatten()
        advantages = returns - values.detach() if self.policy.use_baseline else returns
        policy_loss = -(advantages * log_prob).mean()
        entropy_mean = entropy.mean()
        loss = policy_loss - self.ent_coef * entropy_mean
        if self.policy.use_baseline:
            value_loss = F.mse_loss(values, returns)
            loss = loss + value_loss
            self.logger.record("train/value_loss", value_loss.item())

        self.policy.optimizer.zero_grad()
        loss.backward()
        if self.max_grad_norm is not None:
            grad_norm = th.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
            self.logger.record("train/grad_norm", grad_norm.item())
        self.policy.optimizer.step()
        self._n_updates += 1

        self.logger.record("train/policy_loss", policy_loss.item())
        self.logger.record("train/entropy", entropy_mean.item())
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/n_steps", len(batch.returns))
        self.logger.record("rollout/batch_ep_rew_mean", float(np.mean(batch.episode_returns)))
