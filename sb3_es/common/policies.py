"""Deterministic policies with a flat parameter vector, shared by every population algorithm.

A :class:`FlatPolicy` is an ordinary SB3 :class:`~stable_baselines3.common.policies.BasePolicy`
(``predict()``, ``state_dict()``, save/load) with two additions that population methods need:

* its trainable parameters can be read and written as one flat vector
  (:meth:`FlatPolicy.parameters_to_vector`, :meth:`FlatPolicy.load_from_vector`);
* :meth:`FlatPolicy.network_spec` describes the network as a picklable
  :class:`~sb3_es.evaluation.network.NetworkSpec` (layout, activations, action bounds, observation statistics),
  which the evaluators run: one batched NumPy forward pass in which row ``k`` of the observations goes through
  the network of parameter row ``k``. ``predict()`` runs the same spec, so both give identical actions.

Observation normalization (ARS-V2) lives inside the policy: running mean and variance are buffers,
saved with the model and applied by ``predict()``. They are frozen while a generation is evaluated
and updated between generations by the algorithm (:meth:`FlatPolicy.update_obs_rms`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.running_mean_std import RunningMeanStd
from stable_baselines3.common.torch_layers import create_mlp
from stable_baselines3.common.type_aliases import PyTorchObs
from torch import nn

from sb3_es.common.checks import check_module_class
from sb3_es.common.net_arch import split_net_arch
from sb3_es.common.network_layout import network_layers
from sb3_es.evaluation.network import OBS_NORM_EPS, NetworkSpec, box_actions
from sb3_es.evaluation.observations import flat_obs_dim
from sb3_es.strategies.base import check_flag

__all__ = ["OBS_NORM_EPS", "FlatPolicy", "LinearPolicy", "MlpPolicy", "flat_obs_dim"]


def check_action_space(action_space: spaces.Space) -> None:
    """
    Raise a clear ``ValueError`` for an action space that :class:`FlatPolicy` does not support.

    :param action_space: The env's action space.
    """
    if isinstance(action_space, spaces.Box):
        if not np.all(np.isfinite(action_space.low)) or not np.all(np.isfinite(action_space.high)):
            raise ValueError(
                f"Unsupported action space {action_space}: Box bounds must be finite (a policy's actions are squashed "
                "or clipped into them). Give the env the bounds of the actions it accepts, e.g. with a "
                "gymnasium.ActionWrapper that sets action_space = Box(low, high)."
            )
    elif not isinstance(action_space, spaces.Discrete):
        raise ValueError(
            f"Unsupported action space {action_space}: sb3-es policies support Box and Discrete actions. "
            "For MultiDiscrete or MultiBinary actions, wrap the env to expose a Discrete or Box space."
        )


class FlatPolicy(BasePolicy):
    """
    Deterministic MLP (or linear) policy whose parameters form one flat vector.

    :param observation_space: Observation space: ``Box``, ``Discrete``, ``MultiDiscrete``, ``MultiBinary`` (one-hot,
        as SB3's ``preprocess_obs``) or a ``Dict`` of them (flattened and concatenated).
    :param action_space: Action space: ``Box`` (continuous) or ``Discrete`` (argmax of the outputs).
    :param net_arch: Sizes of the hidden layers; ``[]`` gives a linear policy. Defaults to ``[64, 64]``. SB3's
        actor-critic form ``dict(pi=[...])`` gives the same layers (``pi``); a non-empty ``vf`` is an error, as
        there is no value network.
    :param activation_fn: Activation function after each hidden layer.
    :param with_bias: Whether the linear layers have an additive bias.
    :param squash_output: For ``Box`` actions, squash the outputs with ``tanh`` and rescale them to the
        action bounds; otherwise the outputs are clipped to the bounds.
    :param layer_norm: Apply ``LayerNorm`` after each hidden linear layer (before the activation).
    :param normalize_observations: Normalize observations with running statistics (ARS-V2). Turn off
        for ARS-V1 or when the env is already wrapped in ``VecNormalize``.
    """

    obs_mean: th.Tensor
    obs_var: th.Tensor
    obs_count: th.Tensor

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        net_arch: list[int] | dict[str, list[int]] | None = None,
        activation_fn: type[nn.Module] = nn.ReLU,
        with_bias: bool = True,
        squash_output: bool = True,
        layer_norm: bool = False,
        normalize_observations: bool = True,
    ) -> None:
        check_action_space(action_space)
        is_box = isinstance(action_space, spaces.Box)
        if isinstance(action_space, spaces.Box):
            action_dim = int(np.prod(action_space.shape))
        else:
            assert isinstance(action_space, spaces.Discrete)
            action_dim = int(action_space.n)
        obs_dim = flat_obs_dim(observation_space)
        with_bias = check_flag("with_bias", with_bias)
        squash_output = check_flag("squash_output", squash_output)
        pi_arch, vf_arch = split_net_arch(net_arch)
        if vf_arch:
            raise ValueError(
                f"net_arch={net_arch!r}: sb3-es population policies have no value network, so vf={vf_arch} would "
                f"build nothing. Give the policy's hidden layers only: net_arch=dict(pi={pi_arch}) or "
                f"net_arch={pi_arch} (the default is [64, 64])."
            )
        layer_norm = check_flag("layer_norm", layer_norm)
        if layer_norm and pi_arch == []:
            raise ValueError(
                f"layer_norm=True with net_arch={net_arch!r}: a network without hidden layers has nothing to "
                "normalize. Give hidden layers (e.g. net_arch=[64, 64]) or leave layer_norm=False."
            )
        super().__init__(observation_space, action_space, squash_output=is_box and squash_output)
        self.obs_dim = obs_dim
        self.action_dim = action_dim
        self.net_arch = [64, 64] if pi_arch is None else pi_arch
        check_module_class("activation_fn", activation_fn, nn.Module, "torch.nn.Tanh")
        self.activation_fn = activation_fn
        self.with_bias = with_bias
        self.layer_norm = layer_norm
        self.normalize_observations = check_flag("normalize_observations", normalize_observations)
        layers = create_mlp(
            obs_dim,
            action_dim,
            self.net_arch,
            activation_fn,
            squash_output=self.squash_output,
            with_bias=with_bias,
            post_linear_modules=[nn.LayerNorm] if layer_norm else None,
        )
        self.action_net = nn.Sequential(*layers)
        # Observation statistics (float64 like SB3's RunningMeanStd), saved in the state dict.
        self.register_buffer("obs_mean", th.zeros(obs_dim, dtype=th.float64))
        self.register_buffer("obs_var", th.ones(obs_dim, dtype=th.float64))
        self.register_buffer("obs_count", th.tensor(1e-4, dtype=th.float64))
        self._layers, self.num_params = network_layers(self.action_net)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        # BasePolicy's version adds normalize_images, which these policies do not take.
        return dict(
            observation_space=self.observation_space,
            action_space=self.action_space,
            net_arch=self.net_arch,
            activation_fn=self.activation_fn,
            with_bias=self.with_bias,
            squash_output=self.squash_output,
            layer_norm=self.layer_norm,
            normalize_observations=self.normalize_observations,
        )

    # ------------------------------------------------------------------ flat parameters
    def parameters_to_vector(self) -> np.ndarray:
        """:return: The trainable parameters as one float64 vector."""
        return th.nn.utils.parameters_to_vector(self.parameters()).detach().cpu().double().numpy()

    def output_layer_slice(self) -> slice:
        """:return: Where the output layer's weight and bias lie in the flat vector (all of it for a linear policy)."""
        return self.network_spec().output_layer_slice()

    def load_from_vector(self, vector: np.ndarray) -> None:
        """
        Write a flat vector into the trainable parameters.

        :param vector: Vector of length ``num_params``.
        """
        vector = np.asarray(vector)
        if vector.shape != (self.num_params,):
            raise ValueError(f"Expected a parameter vector of shape ({self.num_params},), got {vector.shape}.")
        tensor = th.as_tensor(vector, dtype=th.float32, device=self.device)
        th.nn.utils.vector_to_parameters(tensor, self.parameters())

    # ------------------------------------------------------------------ the network evaluators run
    def network_spec(self) -> NetworkSpec:
        """:return: The network (architecture, action bounds, current observation statistics) as a picklable spec."""
        mean = var = None
        if self.normalize_observations:
            mean, var = self.obs_mean.cpu().numpy().copy(), self.obs_var.cpu().numpy().copy()
        return NetworkSpec(
            self.observation_space,
            self.action_space,
            self._layers,
            self.num_params,
            squash_output=self.squash_output,
            obs_mean=mean,
            obs_var=var,
        )

    def population_forward(self) -> NetworkSpec:
        """:return: The batched forward pass, observation statistics frozen (see :meth:`network_spec`)."""
        return self.network_spec()

    def flatten_obs(self, obs: np.ndarray | dict[str, np.ndarray]) -> np.ndarray:
        """
        Flatten a batch of observations to ``(n, obs_dim)`` float32 (discrete ones one-hot, as SB3 does).

        :param obs: Array, or dict of arrays for ``Dict`` spaces, with a leading batch dimension.
        :return: Flattened observations.
        """
        return self.network_spec().flatten_obs(obs)

    def normalize(self, flat_obs: np.ndarray) -> np.ndarray:
        """
        Apply the running observation statistics (as the population pass does).

        :param flat_obs: Flattened observations ``(n, obs_dim)``.
        :return: Normalized observations, float32.
        """
        return self.network_spec().normalize(flat_obs)

    def population_actions(self, params: np.ndarray, flat_obs: np.ndarray) -> np.ndarray:
        """
        One batched forward pass where observation row ``k`` goes through the network of parameter row ``k``.

        Gives exactly the actions ``predict()`` gives for each (parameters, observation) pair.

        :param params: Population parameters ``(k, num_params)``, float32.
        :param flat_obs: Flattened raw observations of the ``k`` slots (see :meth:`flatten_obs`).
        :return: Env actions ``(k, *action_shape)``.
        """
        return self.network_spec()(params, flat_obs)

    # ------------------------------------------------------------------ observation statistics
    def obs_rms(self) -> RunningMeanStd:
        """:return: A copy of the observation statistics as an SB3 ``RunningMeanStd``."""
        rms = RunningMeanStd(shape=(self.obs_dim,))
        rms.mean = self.obs_mean.cpu().numpy().copy()
        rms.var = self.obs_var.cpu().numpy().copy()
        rms.count = float(self.obs_count.item())
        return rms

    def update_obs_rms(self, batch_mean: np.ndarray, batch_var: np.ndarray, batch_count: float) -> None:
        """
        Merge the moments of a generation's observations into the running statistics.

        :param batch_mean: Mean of the new observations.
        :param batch_var: Variance of the new observations.
        :param batch_count: Number of new observations.
        """
        if batch_count <= 0:
            return
        rms = self.obs_rms()
        rms.update_from_moments(batch_mean, batch_var, batch_count)
        self.obs_mean.copy_(th.as_tensor(rms.mean))
        self.obs_var.copy_(th.as_tensor(rms.var))
        self.obs_count.fill_(rms.count)

    # ------------------------------------------------------------------ SB3 predict
    def forward(self, obs: PyTorchObs, deterministic: bool = True) -> th.Tensor:
        return self._predict(obs, deterministic)

    def _predict(self, observation: PyTorchObs, deterministic: bool = True) -> th.Tensor:
        # Population policies are deterministic: ``deterministic`` is accepted for API compatibility.
        if isinstance(observation, dict):
            obs: np.ndarray | dict[str, np.ndarray] = {k: v.cpu().numpy() for k, v in observation.items()}
        else:
            obs = observation.cpu().numpy()
        network = self.network_spec()
        params = self.parameters_to_vector().astype(np.float32)[None]
        # The raw outputs: SB3's predict() then rescales (squash) or clips them as the spec's actions do.
        flat = network.flatten_obs(obs)
        if not np.isfinite(flat).all():  # a NaN would give a silent NaN or arbitrary action (PPO's policy raises too)
            raise ValueError(
                "predict(): the observation holds NaN or infinite values; check the env or wrapper that produced it."
            )
        out = network.forward(params, network.normalize(flat))
        if isinstance(self.action_space, spaces.Discrete):
            return th.as_tensor(out.argmax(axis=1) + int(self.action_space.start))
        return th.as_tensor(out)

    def predict(
        self,
        observation: np.ndarray | dict[str, np.ndarray],
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """SB3's ``predict``, with the actions of the population's networks (:func:`box_actions`)."""
        actions, state = super().predict(observation, state, episode_start, deterministic)
        if isinstance(self.action_space, spaces.Box) and not self.squash_output:
            actions = box_actions(actions, self.action_space, squash_output=False)  # an integer Box: rounded
        return actions, state

    def unscale_action(self, scaled_action: np.ndarray) -> np.ndarray:
        assert isinstance(self.action_space, spaces.Box)
        return box_actions(scaled_action, self.action_space, squash_output=True)


class MlpPolicy(FlatPolicy):
    """
    MLP policy (defaults as sb3-contrib's ARS ``MlpPolicy``: ``[64, 64]``, ReLU, bias, tanh squashing).

    :param observation_space: Observation space.
    :param action_space: Action space.
    :param net_arch: Hidden layer sizes.
    :param activation_fn: Activation function.
    :param with_bias: Whether the layers have a bias.
    :param squash_output: ``tanh`` squashing for Box actions (else clipping).
    :param layer_norm: ``LayerNorm`` after each hidden layer.
    :param normalize_observations: Running observation normalization (ARS-V2).
    """


class LinearPolicy(FlatPolicy):
    """
    Linear policy ``a = W (o - mu) / sigma``, as in the ARS paper (no bias, outputs clipped to the bounds).

    :param observation_space: Observation space.
    :param action_space: Action space.
    :param with_bias: Whether to add a bias.
    :param squash_output: ``tanh`` squashing for Box actions (else clipping).
    :param normalize_observations: Running observation normalization (ARS-V2); ``False`` gives ARS-V1.
    :param net_arch: Accepted only as ``None`` (no hidden layer: use ``MlpPolicy`` for one); so are
        ``activation_fn`` (``nn.ReLU``) and ``layer_norm`` (``False``), which a linear policy has no use for.
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        with_bias: bool = False,
        squash_output: bool = False,
        normalize_observations: bool = True,
        net_arch: list[int] | None = None,
        activation_fn: type[nn.Module] = nn.ReLU,
        layer_norm: bool = False,
    ) -> None:
        if split_net_arch(net_arch)[0]:  # [] and SB3's dict(pi=[]) are the linear network
            raise ValueError(f"LinearPolicy has no hidden layers (got net_arch={net_arch}); use MlpPolicy instead.")
        given = [f"layer_norm={layer_norm!r}"] if layer_norm else []
        if activation_fn is not nn.ReLU:
            given.append(f"activation_fn={getattr(activation_fn, '__name__', activation_fn)}")
        if given:
            raise ValueError(
                f"LinearPolicy has no hidden layers, so {' and '.join(given)} would do nothing: use MlpPolicy for "
                "hidden layers."
            )
        super().__init__(
            observation_space,
            action_space,
            net_arch=net_arch if isinstance(net_arch, dict) else [],  # a vf entry is refused there
            activation_fn=activation_fn,
            with_bias=with_bias,
            squash_output=squash_output,
            layer_norm=False,
            normalize_observations=normalize_observations,
        )
