"""Stochastic categorical policies over discretized actions, for :class:`~sb3_es.reinforce.REINFORCE`.

A continuous ``Box`` action space is discretized into ``n_bins`` evenly spaced levels per dimension,
from ``low`` to ``high`` (3 levels on BipedalWalker give the torques ``-1, 0, 1``). Two parameterizations:

* **joint**: one categorical over every combination of levels, ``n_bins ** action_dim`` actions
  (``3 ** 4 = 81`` on BipedalWalker). It can represent correlations between dimensions but grows
  exponentially, so it is refused above ``max_joint_actions``.
* **factorized** (the default): an independent categorical per dimension, ``n_bins * action_dim`` logits,
  which scales to the 6 joints of dm_control's walker or the 17 of Humanoid.

A native ``Discrete`` action space gets a plain categorical. The policy is SB3's ``ActorCriticPolicy``
over the space of these indices; ``predict()`` returns actions of the original env (the levels, inside
the ``Box``), so it works like any SB3 policy. (About 300 lines: the policy's constructor arguments, those of SB3's
``ActorCriticPolicy`` plus the discretization's, are documented for users.)
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.distributions import (
    CategoricalDistribution,
    Distribution,
    MultiCategoricalDistribution,
    make_proba_distribution,
)
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, FlattenExtractor
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule
from torch import nn

from sb3_es.common.arguments import base_arguments
from sb3_es.common.checks import check_module_class
from sb3_es.common.net_arch import layer_sizes, split_net_arch
from sb3_es.evaluation.network import flat_obs_dim
from sb3_es.evaluation.observations import counted_from_zero
from sb3_es.reinforce.legacy import upgrade_legacy_state_dict
from sb3_es.strategies.base import check_count, check_flag

#: Levels per ``Box`` action dimension when ``n_bins`` is not given (the seed document's 3).
DEFAULT_N_BINS = 3
#: Default limit on the number of joint actions (``n_bins ** action_dim``).
MAX_JOINT_ACTIONS = 100_000


class DictFlattenExtractor(BaseFeaturesExtractor):
    """
    Flatten every entry of a ``Dict`` observation and concatenate them (keys in the space's order).

    Unlike SB3's ``CombinedExtractor`` it accepts scalar entries (shape ``()``), such as the ``height``
    of dm_control's walker exposed through shimmy, and it has no parameters. ``Discrete``, ``MultiDiscrete``
    and ``MultiBinary`` entries arrive one-hot encoded (SB3's ``preprocess_obs``, applied by the policy).

    :param observation_space: A ``Dict`` of ``Box``, ``Discrete``, ``MultiDiscrete`` or ``MultiBinary`` spaces.
    """

    def __init__(self, observation_space: spaces.Dict) -> None:
        if not isinstance(observation_space, spaces.Dict):
            raise ValueError(f"DictFlattenExtractor needs a Dict observation space, got {observation_space}.")
        super().__init__(observation_space, flat_obs_dim(observation_space))
        self.keys = list(observation_space.spaces.keys())

    def forward(self, observations: dict[str, th.Tensor]) -> th.Tensor:  # type: ignore[override]
        batch_size = observations[self.keys[0]].shape[0]
        return th.cat([observations[key].reshape(batch_size, -1).float() for key in self.keys], dim=1)


class DiscretizedPolicy(ActorCriticPolicy):
    """
    SB3's ``ActorCriticPolicy`` over an *index space*: a categorical MLP policy over discretized ``Box``
    actions (or native ``Discrete`` actions), whose value network serves as an optional baseline.

    The networks, the distribution (SB3's ``CategoricalDistribution`` or ``MultiCategoricalDistribution``),
    ``get_distribution``, ``evaluate_actions`` and ``predict_values`` are SB3's; this class adds the index
    space and the map from indices to env actions. For a joint policy an index is one integer in
    ``[0, n_bins ** action_dim)`` per observation (the last dimension varies fastest, as
    ``itertools.product``), for a factorized one an integer in ``[0, n_bins)`` per dimension.
    :meth:`indices_to_actions` turns them into env actions; ``predict()`` does it for you.

    :param observation_space: Observation space: ``Box``, ``Discrete``, ``MultiDiscrete`` or ``MultiBinary`` (the
        discrete ones one-hot encoded), or a ``Dict`` of them, flattened and concatenated.
    :param action_space: ``Box`` with finite bounds (discretized) or ``Discrete``.
    :param lr_schedule: Learning rate schedule; the optimizer starts with ``lr_schedule(1)``.
    :param n_bins: Number of evenly spaced levels per ``Box`` dimension, ``low`` and ``high`` included
        (``None``: 3; rounded to the nearest integers on an integer ``Box``). ``Discrete`` actions are used as they
        are: another ``n_bins``, or ``joint=True``, is refused.
    :param joint: ``True``: one categorical over the ``n_bins ** action_dim`` combinations of levels;
        ``False``: an independent categorical per dimension.
    :param max_joint_actions: Largest number of joint actions accepted when ``joint=True``.
    :param net_arch: Hidden layer sizes of the policy network (default ``[64, 64]``), or SB3's actor-critic form
        ``dict(pi=[...], vf=[...])``: ``pi`` is the policy's, ``vf`` the baseline's (a non-empty ``vf`` needs
        ``use_baseline=True``; a missing entry is ``[]``, as in SB3).
    :param activation_fn: Activation function of the hidden layers.
    :param use_baseline: Train the value network as a state-value baseline. Without it the value head is
        a single unused linear layer (``ActorCriticPolicy`` always has one) and ``predict_values`` raises.
    :param value_net_arch: Hidden layer sizes of the value network (default: the policy's; ``[]``: a linear
        baseline). Give it here or as the ``vf`` entry of ``net_arch``, not both.
    :param ortho_init: Orthogonal initialization as in SB3's A2C/PPO (gain 0.01 on the logits, so the
        initial policy is close to uniform over the levels).
    :param features_extractor_class: Features extractor; defaults to ``FlattenExtractor`` for ``Box``
        observations and :class:`DictFlattenExtractor` for ``Dict`` observations. It is shared by the
        policy and the value network.
    :param features_extractor_kwargs: Keyword arguments for the features extractor.
    :param normalize_images: Whether to divide image observations by 255.
    :param optimizer_class: Optimizer class (Adam by default).
    :param optimizer_kwargs: Keyword arguments for the optimizer, except the learning rate (default: none,
        so Adam keeps its own ``eps``, unlike ``ActorCriticPolicy``'s ``1e-5``).
    """

    action_levels: th.Tensor
    joint_strides: th.Tensor

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        lr_schedule: Schedule,
        n_bins: int | None = None,
        joint: bool = False,
        max_joint_actions: int = MAX_JOINT_ACTIONS,
        net_arch: list[int] | dict[str, list[int]] | None = None,
        activation_fn: type[nn.Module] = nn.Tanh,
        use_baseline: bool = False,
        value_net_arch: list[int] | None = None,
        ortho_init: bool = True,
        features_extractor_class: type[BaseFeaturesExtractor] | None = None,
        features_extractor_kwargs: dict[str, Any] | None = None,
        normalize_images: bool = True,
        optimizer_class: type[th.optim.Optimizer] = th.optim.Adam,
        optimizer_kwargs: dict[str, Any] | None = None,
    ) -> None:
        check_action_space(action_space)
        flat_obs_dim(observation_space)  # a clear error for an observation space the network cannot take
        joint = check_flag("joint", joint)
        ortho_init = check_flag("ortho_init", ortho_init)
        normalize_images = check_flag("normalize_images", normalize_images)
        check_module_class("activation_fn", activation_fn, nn.Module, "torch.nn.Tanh")
        check_module_class("optimizer_class", optimizer_class, th.optim.Optimizer, "torch.optim.Adam")
        # n_bins=3 (the default) is what a saved policy's constructor parameters hold for Discrete actions
        if isinstance(action_space, spaces.Discrete) and (n_bins not in (None, DEFAULT_N_BINS) or joint):
            raise ValueError(
                f"n_bins={n_bins!r}, joint={joint!r}: they discretize a Box action space, but {action_space} is "
                "used as it is. Leave n_bins and joint out of policy_kwargs."
            )
        n_bins = DEFAULT_N_BINS if n_bins is None else check_count("n_bins", n_bins, minimum=2)
        pi_arch, vf_arch = split_net_arch(net_arch)
        if vf_arch is not None and value_net_arch is not None:
            raise ValueError(
                f"net_arch={net_arch!r} and value_net_arch={value_net_arch!r} both give the baseline's layers: give "
                "them once (value_net_arch, or the vf entry of net_arch)."
            )
        if vf_arch and not use_baseline:
            raise ValueError(
                f"net_arch={net_arch!r}: the value network (vf) of REINFORCE is its baseline, which is off: pass "
                "use_baseline=True to REINFORCE, or drop the vf entry."
            )
        self.policy_net_arch = [64, 64] if pi_arch is None else pi_arch
        self.value_net_arch = vf_arch if value_net_arch is None else layer_sizes(value_net_arch, "value_net_arch")
        # Set before ActorCriticPolicy.__init__, which calls _build.
        self.n_bins = n_bins
        self.joint = joint
        self.max_joint_actions = check_count("max_joint_actions", max_joint_actions)
        self.use_baseline = check_flag("use_baseline", use_baseline)
        self.index_space = self._make_index_space(action_space)
        if features_extractor_class is None:
            dict_obs = isinstance(observation_space, spaces.Dict)
            features_extractor_class = DictFlattenExtractor if dict_obs else FlattenExtractor
        value_arch = self.policy_net_arch if self.value_net_arch is None else self.value_net_arch
        if not self.use_baseline:
            value_arch = []
        arguments = base_arguments(super().__init__, locals())  # ActorCriticPolicy's own, as given
        arguments["net_arch"] = dict(pi=self.policy_net_arch, vf=value_arch)
        arguments["optimizer_kwargs"] = {} if optimizer_kwargs is None else optimizer_kwargs  # {}: no eps=1e-5
        if "lr" in arguments["optimizer_kwargs"]:  # the optimizer gets it from the schedule (torch: "multiple values")
            raise ValueError(
                f"optimizer_kwargs={optimizer_kwargs!r}: the learning rate is REINFORCE's learning_rate argument "
                "(a float or a schedule); leave lr out of optimizer_kwargs."
            )
        super().__init__(**arguments)
        if isinstance(action_space, spaces.Box):
            low = action_space.low.reshape(-1).astype(np.float64)
            high = action_space.high.reshape(-1).astype(np.float64)
            # linspace puts low and high exactly on the grid: actions never leave the Box.
            levels = np.linspace(low, high, self.n_bins, axis=1)
            if np.issubdtype(action_space.dtype, np.integer):  # the nearest integers, each level a distinct action
                levels = np.rint(levels)
                varying = high > low  # a constant dimension (low == high) has one action, whatever n_bins
                if np.any(np.diff(levels[varying], axis=1) == 0):
                    raise ValueError(
                        f"n_bins={self.n_bins} levels do not fit in the integer action space {action_space}: two "
                        "levels round to the same action. Use n_bins at most high - low + 1 of its narrowest "
                        f"non-constant dimension ({int(np.min((high - low)[varying])) + 1})."
                    )
            levels = levels.astype(action_space.dtype)
        else:
            levels = np.zeros((0, self.n_bins), dtype=np.float32)
        # Level values, (action_dim, n_bins): derived from the action space, so not saved in the state dict.
        self.register_buffer("action_levels", th.as_tensor(levels), persistent=False)
        # Strides that turn a joint index into per-dimension indices (last dimension fastest).
        strides = [self.n_bins ** (self.action_dim - 1 - d) for d in range(self.action_dim)] if self.joint else []
        self.register_buffer("joint_strides", th.as_tensor(strides, dtype=th.long), persistent=False)

    def _make_index_space(self, action_space: spaces.Space) -> spaces.Discrete | spaces.MultiDiscrete:
        """
        :param action_space: The env's action space.
        :return: The space of action indices: ``Discrete`` (joint or native) or ``MultiDiscrete`` (factorized).
        """
        if isinstance(action_space, spaces.Discrete):
            self.action_dim = 1
            self.n_actions = int(action_space.n)
            return spaces.Discrete(self.n_actions)
        self.action_dim = int(np.prod(action_space.shape))  # type: ignore[arg-type]
        if not self.joint:
            self.n_actions = self.n_bins * self.action_dim
            return spaces.MultiDiscrete([self.n_bins] * self.action_dim)
        self.n_actions = self.n_bins**self.action_dim
        if self.n_actions > self.max_joint_actions:
            raise ValueError(
                f"A joint categorical over {self.action_dim} action dimensions with n_bins={self.n_bins} "
                f"has {self.n_bins}**{self.action_dim} = {self.n_actions} actions, more than "
                f"max_joint_actions={self.max_joint_actions}. Use the factorized form "
                "(policy_kwargs=dict(joint=False)), fewer bins, or raise max_joint_actions."
            )
        return spaces.Discrete(self.n_actions)

    def _build(self, lr_schedule: Schedule) -> None:
        # SB3 builds the action head from ``action_dist``: make it the categorical over indices.
        self.action_dist = make_proba_distribution(self.index_space)
        super()._build(lr_schedule)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        return dict(
            observation_space=self.observation_space,
            action_space=self.action_space,
            normalize_images=self.normalize_images,
            lr_schedule=self._dummy_schedule,  # the algorithm rebuilds the real one when loading
            n_bins=self.n_bins,
            joint=self.joint,
            max_joint_actions=self.max_joint_actions,
            net_arch=self.policy_net_arch,
            activation_fn=self.activation_fn,
            use_baseline=self.use_baseline,
            value_net_arch=self.value_net_arch,
            ortho_init=self.ortho_init,
            features_extractor_class=self.features_extractor_class,
            features_extractor_kwargs=self.features_extractor_kwargs,
            optimizer_class=self.optimizer_class,
            optimizer_kwargs=self.optimizer_kwargs,
        )

    # ------------------------------------------------------------------ observations
    def _as_sb3_obs(self, obs: PyTorchObs) -> PyTorchObs:
        """
        :param obs: Batch of observations.
        :return: The observations as SB3's ``preprocess_obs`` takes them: discrete values counted from 0
            (:func:`~sb3_es.evaluation.observations.counted_from_zero`), a scalar ``Box`` as ``(batch, 1)``.
        """
        if isinstance(obs, dict):
            assert isinstance(self.observation_space, spaces.Dict)
            return {key: counted_from_zero(value, self.observation_space[key]) for key, value in obs.items()}
        obs = counted_from_zero(obs, self.observation_space)
        if isinstance(self.observation_space, spaces.Box) and self.observation_space.shape == ():
            obs = obs.reshape(-1, 1)
        return obs  # type: ignore[return-value]

    # SB3's entry points from observations to features (get_distribution and predict_values call BaseModel's
    # extract_features directly, so each takes the observations as SB3 does here).
    def extract_features(  # type: ignore[override]
        self, obs: PyTorchObs, features_extractor: BaseFeaturesExtractor | None = None
    ) -> th.Tensor | tuple[th.Tensor, th.Tensor]:
        return super().extract_features(self._as_sb3_obs(obs), features_extractor)

    def get_distribution(self, obs: PyTorchObs) -> Distribution:
        return super().get_distribution(self._as_sb3_obs(obs))

    # ------------------------------------------------------------------ actions
    def forward(  # type: ignore[override]
        self, obs: PyTorchObs, deterministic: bool = False, generator: th.Generator | None = None
    ) -> th.Tensor:
        """
        Choose action indices (use :meth:`indices_to_actions` to get env actions). Unlike
        ``ActorCriticPolicy.forward`` it returns the indices only: REINFORCE needs no value while acting.

        :param obs: Batch of observations.
        :param deterministic: Take the mode of the distribution instead of sampling.
        :param generator: Torch random generator to sample from (``None``: the global one).
        :return: Indices: ``(batch,)`` for a joint or ``Discrete`` policy, ``(batch, action_dim)`` for a
            factorized one.
        """
        distribution = self.get_distribution(obs)
        if deterministic or generator is None:
            return distribution.get_actions(deterministic=deterministic)
        if isinstance(distribution, MultiCategoricalDistribution):
            categoricals = distribution.distribution
            return th.stack([th.multinomial(d.probs, 1, generator=generator).squeeze(1) for d in categoricals], dim=1)
        assert isinstance(distribution, CategoricalDistribution)
        return th.multinomial(distribution.distribution.probs, 1, generator=generator).squeeze(1)

    def indices_to_actions(self, indices: th.Tensor) -> th.Tensor:
        """
        Map action indices to env actions.

        :param indices: Output of :meth:`forward`.
        :return: ``Box``: the levels, ``(batch, action_dim)``; ``Discrete``: the indices themselves.
        """
        if isinstance(self.action_space, spaces.Discrete):
            return indices + int(self.action_space.start)
        if self.joint:
            per_dim = (indices.long().unsqueeze(1) // self.joint_strides) % self.n_bins
        else:
            per_dim = indices.long()
        # action_levels[d, per_dim[b, d]]
        return th.gather(self.action_levels.expand(per_dim.shape[0], -1, -1), 2, per_dim.unsqueeze(2)).squeeze(2)

    def _predict(self, observation: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        return self.indices_to_actions(super()._predict(observation, deterministic))

    def predict_values(self, obs: PyTorchObs) -> th.Tensor:
        """
        :param obs: Batch of observations.
        :return: The baseline's state values ``(batch, 1)``.
        """
        if not self.use_baseline:
            raise ValueError("This policy has no value network: create it with use_baseline=True.")
        return super().predict_values(self._as_sb3_obs(obs))

    # ------------------------------------------------------------------ saves of sb3-es <= 0.x
    def _load_from_state_dict(self, state_dict: dict[str, Any], prefix: str, *args: Any) -> None:
        upgrade_legacy_state_dict(self, state_dict, prefix)
        super()._load_from_state_dict(state_dict, prefix, *args)  # type: ignore[arg-type]


def check_action_space(action_space: spaces.Space) -> None:
    """
    Raise a clear ``ValueError`` for an action space that :class:`DiscretizedPolicy` does not support.

    :param action_space: The env's action space.
    """
    if isinstance(action_space, spaces.Discrete):
        return
    if isinstance(action_space, spaces.Box):
        if not (np.all(np.isfinite(action_space.low)) and np.all(np.isfinite(action_space.high))):
            raise ValueError(
                f"Unsupported action space {action_space}: the Box bounds must be finite to be discretized."
            )
        return
    raise ValueError(
        f"Unsupported action space {action_space}: REINFORCE supports Box actions (discretized into n_bins "
        "levels per dimension) and Discrete actions. Wrap the env to expose a Box or Discrete space "
        "(MultiDiscrete, MultiBinary, Tuple and Dict action spaces are not supported)."
    )


#: Alias for SB3's policy names.
MlpPolicy = DiscretizedPolicy
#: Alias for ``Dict`` observations (they are flattened by :class:`DictFlattenExtractor`).
MultiInputPolicy = DiscretizedPolicy
