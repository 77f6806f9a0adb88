"""Deterministic policies with a flat parameter vector, shared by every population algorithm.

A :class:`FlatPolicy` is an ordinary SB3 :class:`~stable_baselines3.common.policies.BasePolicy`
(``predict()``, ``state_dict()``, save/load) with two additions that population methods need:

* its trainable parameters can be read and written as one flat vector
  (:meth:`FlatPolicy.parameters_to_vector`, :meth:`FlatPolicy.load_from_vector`);
* :meth:`FlatPolicy.population_actions` runs *one batched forward pass* in which row ``k`` of the
  observations is fed through the network whose parameters are row ``k`` of a population matrix,
  so that every env slot of a VecEnv can evaluate a different candidate in the same step. The
  forward pass is NumPy (much faster than torch for these sizes) and ``predict()`` uses the same code.

Observation normalization (ARS-V2) lives inside the policy: running mean and variance are buffers,
saved with the model and applied by ``predict()``. They are frozen while a generation is evaluated
and updated between generations by the algorithm (:meth:`FlatPolicy.update_obs_rms`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.preprocessing import get_flattened_obs_dim, preprocess_obs
from stable_baselines3.common.running_mean_std import RunningMeanStd
from stable_baselines3.common.torch_layers import create_mlp
from stable_baselines3.common.type_aliases import PyTorchObs
from torch import nn

#: Variance floor used when normalizing observations (same as SB3's ``VecNormalize``).
OBS_NORM_EPS = 1e-8


#: Observation spaces a policy takes, alone or as the entries of a ``Dict``.
FLAT_OBS_SPACES = (spaces.Box, spaces.Discrete, spaces.MultiDiscrete, spaces.MultiBinary)


def flat_obs_dim(observation_space: spaces.Space) -> int:
    """
    Size of the flattened observation vector, or a clear error for a space that cannot be flattened.

    :param observation_space: A ``Box``, ``Discrete``, ``MultiDiscrete`` or ``MultiBinary`` space, or a ``Dict`` of
        them (e.g. dm_control through shimmy). Discrete entries count one input per value (one-hot).
    :return: Number of scalars in one flattened observation.
    """
    if isinstance(observation_space, spaces.Dict):
        bad = {k: type(s).__name__ for k, s in observation_space.spaces.items() if not isinstance(s, FLAT_OBS_SPACES)}
        if bad:
            raise ValueError(
                f"Unsupported observation space: Dict entries {bad} are not Box, Discrete, MultiDiscrete or "
                "MultiBinary spaces; wrap the env with gymnasium.wrappers.FlattenObservation."
            )
        return sum(int(get_flattened_obs_dim(s)) for s in observation_space.spaces.values())
    if isinstance(observation_space, FLAT_OBS_SPACES):
        return int(get_flattened_obs_dim(observation_space))
    raise ValueError(
        f"Unsupported observation space {observation_space}: sb3-es policies take Box, Discrete, MultiDiscrete and "
        "MultiBinary observations, or a Dict of them. Wrap the env with gymnasium.wrappers.FlattenObservation "
        "(Tuple, ...) or a TransformObservation that produces a Box."
    )


def _flatten_entry(obs: np.ndarray, space: spaces.Space) -> np.ndarray:
    """
    :param obs: A batch of observations of ``space``.
    :param space: The space: a ``Box`` is flattened; other spaces go through SB3's ``preprocess_obs`` (one-hot).
    :return: ``(n, flat_dim)`` observations.
    """
    obs = np.asarray(obs)
    if not isinstance(space, spaces.Box):
        obs = preprocess_obs(th.as_tensor(obs), space, normalize_images=False).numpy()  # type: ignore[union-attr]
    return obs.reshape(obs.shape[0], -1)


class FlatPolicy(BasePolicy):
    """
    Deterministic MLP (or linear) policy whose parameters form one flat vector.

    :param observation_space: Observation space: ``Box``, ``Discrete``, ``MultiDiscrete``, ``MultiBinary`` (one-hot,
        as SB3's ``preprocess_obs``) or a ``Dict`` of them (flattened and concatenated).
    :param action_space: Action space: ``Box`` (continuous) or ``Discrete`` (argmax of the outputs).
    :param net_arch: Sizes of the hidden layers; ``[]`` gives a linear policy. Defaults to ``[64, 64]``.
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
        net_arch: list[int] | None = None,
        activation_fn: type[nn.Module] = nn.ReLU,
        with_bias: bool = True,
        squash_output: bool = True,
        layer_norm: bool = False,
        normalize_observations: bool = True,
    ) -> None:
        if isinstance(action_space, spaces.Box):
            if not np.all(np.isfinite(action_space.low)) or not np.all(np.isfinite(action_space.high)):
                raise ValueError(f"Unsupported action space {action_space}: Box bounds must be finite.")
            action_dim = int(np.prod(action_space.shape))
        elif isinstance(action_space, spaces.Discrete):
            action_dim = int(action_space.n)
        else:
            raise ValueError(
                f"Unsupported action space {action_space}: sb3-es policies support Box and Discrete actions. "
                "For MultiDiscrete or MultiBinary actions, wrap the env to expose a Discrete or Box space."
            )
        obs_dim = flat_obs_dim(observation_space)
        is_box = isinstance(action_space, spaces.Box)
        if isinstance(net_arch, dict):
            raise ValueError(
                f"net_arch={net_arch!r}: sb3-es population policies have no value network, so there is no "
                "dict(pi=..., vf=...) to give. Pass the hidden layer sizes of the policy as a list, e.g. "
                "net_arch=[64, 64]."
            )
        super().__init__(observation_space, action_space, squash_output=is_box and squash_output)
        self.net_arch = [64, 64] if net_arch is None else list(net_arch)
        if any(int(n) <= 0 for n in self.net_arch):
            raise ValueError(f"net_arch={self.net_arch}: every hidden layer size must be a positive integer.")
        self.activation_fn = activation_fn
        self.with_bias = with_bias
        self.layer_norm = layer_norm
        self.normalize_observations = normalize_observations
        self.obs_dim = obs_dim
        self.action_dim = action_dim
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
        self._build_layout()

    def _build_layout(self) -> None:
        """Record where each module's parameters lie in the flat vector (order of ``parameters()``)."""
        self._layout: list[tuple[str, nn.Module, list[tuple[int, int, tuple[int, ...]]]]] = []
        offset = 0
        for module in self.action_net:
            slices = []
            for param in module.parameters(recurse=False):
                size = param.numel()
                slices.append((offset, offset + size, tuple(param.shape)))
                offset += size
            if isinstance(module, nn.Linear):
                kind = "linear"
            elif isinstance(module, nn.LayerNorm):
                kind = "layer_norm"
            elif slices:
                raise ValueError(f"Module {module} has parameters but no batched forward pass.")
            else:
                kind = "elementwise"
            self._layout.append((kind, module, slices))
        self.num_params = offset

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
        linear = [slices for kind, _, slices in self._layout if kind == "linear"]
        last = linear[-1]
        return slice(last[0][0], last[-1][1])

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

    # ------------------------------------------------------------------ observations
    def flatten_obs(self, obs: np.ndarray | dict[str, np.ndarray]) -> np.ndarray:
        """
        Flatten a batch of observations to ``(n, obs_dim)`` float32 (discrete ones one-hot, as SB3 does).

        :param obs: Array, or dict of arrays for ``Dict`` spaces, with a leading batch dimension.
        :return: Flattened observations.
        """
        space = self.observation_space
        if isinstance(space, spaces.Dict):
            assert isinstance(obs, dict)
            parts = [_flatten_entry(obs[key], subspace) for key, subspace in space.spaces.items()]
            return np.concatenate(parts, axis=1).astype(np.float32, copy=False)
        return _flatten_entry(obs, space).astype(np.float32, copy=False)  # type: ignore[arg-type]

    def normalize(self, flat_obs: np.ndarray) -> np.ndarray:
        """
        Apply the running observation statistics (as :meth:`population_forward` does).

        :param flat_obs: Flattened observations ``(n, obs_dim)``.
        :return: Normalized observations, float32.
        """
        return self.population_forward().normalize(flat_obs)

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

    # ------------------------------------------------------------------ forward passes
    def _forward_numpy(self, params: np.ndarray, x: np.ndarray) -> np.ndarray:
        """
        Network outputs where row ``k`` of ``x`` goes through the network of parameter row ``k``.

        NumPy's batched matrix-vector product is much faster than torch's for these small networks, and
        ``predict()`` uses this same code (broadcasting one parameter row), so both give identical actions.

        :param params: Parameters ``(k, num_params)`` or ``(1, num_params)`` (broadcast), float32.
        :param x: Normalized observations ``(k, obs_dim)``, float32.
        :return: Raw outputs ``(k, output_dim)``.
        """
        x = x[:, :, None]  # (k, features, 1)
        for kind, module, slices in self._layout:
            if kind == "linear":
                (w0, w1, w_shape), *bias = slices
                x = np.matmul(params[:, w0:w1].reshape(-1, *w_shape), x)
                if bias:
                    x = x + params[:, bias[0][0] : bias[0][1], None]
            elif kind == "layer_norm":
                assert isinstance(module, nn.LayerNorm)
                mean = x.mean(axis=1, keepdims=True)
                var = x.var(axis=1, keepdims=True)
                (g0, g1, _), (b0, b1, _) = slices
                x = (x - mean) / np.sqrt(var + module.eps) * params[:, g0:g1, None] + params[:, b0:b1, None]
            else:
                x = _apply_elementwise(module, x)
        return x[:, :, 0]

    def population_forward(self) -> PopulationForward:
        """
        The batched forward pass with the current observation statistics frozen (one per generation).

        :return: A callable ``(params, flat_obs) -> env actions``.
        """
        return PopulationForward(self)

    def population_actions(self, params: np.ndarray, flat_obs: np.ndarray) -> np.ndarray:
        """
        One batched forward pass where observation row ``k`` goes through the network of parameter row ``k``.

        Gives exactly the actions ``predict()`` gives for each (parameters, observation) pair.

        :param params: Population parameters ``(k, num_params)``, float32.
        :param flat_obs: Flattened raw observations of the ``k`` slots (see :meth:`flatten_obs`).
        :return: Env actions ``(k, *action_shape)``.
        """
        return self.population_forward()(params, flat_obs)

    def forward(self, obs: PyTorchObs, deterministic: bool = True) -> th.Tensor:
        return self._predict(obs, deterministic)

    def _predict(self, observation: PyTorchObs, deterministic: bool = True) -> th.Tensor:
        # Population policies are deterministic: ``deterministic`` is accepted for API compatibility.
        if isinstance(observation, dict):
            obs: np.ndarray | dict[str, np.ndarray] = {k: v.cpu().numpy() for k, v in observation.items()}
        else:
            obs = observation.cpu().numpy()
        params = self.parameters_to_vector().astype(np.float32)[None]
        out = self._forward_numpy(params, self.normalize(self.flatten_obs(obs)))
        if isinstance(self.action_space, spaces.Discrete):
            return th.as_tensor(out.argmax(axis=1))
        return th.as_tensor(out)


class PopulationForward:
    """
    A policy's batched forward pass with its observation statistics and action scaling computed once.

    The statistics are frozen while a generation is evaluated, so the evaluator builds one of these
    per generation; ``predict()`` builds one per call. Both therefore compute identical actions.

    :param policy: The policy.
    """

    def __init__(self, policy: FlatPolicy) -> None:
        self.policy = policy
        self.mean: np.ndarray | None = None
        self.inv_std: np.ndarray | None = None
        if policy.normalize_observations:
            self.mean = policy.obs_mean.cpu().numpy().astype(np.float32)
            self.inv_std = (1.0 / np.sqrt(policy.obs_var.cpu().numpy() + OBS_NORM_EPS)).astype(np.float32)
        self.discrete = isinstance(policy.action_space, spaces.Discrete)
        if not self.discrete:
            assert isinstance(policy.action_space, spaces.Box)
            self.shape = policy.action_space.shape
            self.low = policy.action_space.low
            self.high = policy.action_space.high
            self.span = self.high - self.low

    def normalize(self, flat_obs: np.ndarray) -> np.ndarray:
        """
        :param flat_obs: Flattened observations ``(n, obs_dim)``.
        :return: Normalized observations, float32.
        """
        if self.mean is None or self.inv_std is None:
            return flat_obs
        return (flat_obs - self.mean) * self.inv_std

    def __call__(self, params: np.ndarray, flat_obs: np.ndarray) -> np.ndarray:
        """
        :param params: Parameters ``(k, num_params)`` (or one row, broadcast), float32.
        :param flat_obs: Flattened raw observations ``(k, obs_dim)``.
        :return: Env actions: argmax for Discrete; for Box, tanh outputs rescaled to the bounds
            (as SB3's ``unscale_action``) or raw outputs clipped to them.
        """
        out = self.policy._forward_numpy(params, self.normalize(flat_obs))
        if self.discrete:
            return out.argmax(axis=1)
        actions = out.reshape((-1, *self.shape))
        if self.policy.squash_output:
            return self.low + (0.5 * (actions + 1.0) * self.span)
        return np.clip(actions, self.low, self.high)


_ELEMENTWISE: dict[type[nn.Module], Callable[[np.ndarray], np.ndarray]] = {
    nn.ReLU: lambda x: np.maximum(x, 0),
    nn.Tanh: np.tanh,
    nn.Sigmoid: lambda x: 1 / (1 + np.exp(-x)),
    nn.Identity: lambda x: x,
}


def _apply_elementwise(module: nn.Module, x: np.ndarray) -> np.ndarray:
    """
    Apply an activation module to a NumPy array (fast paths for common ones, torch for the rest).

    :param module: Activation module.
    :param x: Input.
    :return: Output, same shape and dtype.
    """
    fast = _ELEMENTWISE.get(type(module))
    if fast is not None:
        return fast(x).astype(x.dtype, copy=False)
    with th.no_grad():
        return module(th.from_numpy(np.ascontiguousarray(x))).numpy()


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
        if net_arch:
            raise ValueError(f"LinearPolicy has no hidden layers (got net_arch={net_arch}); use MlpPolicy instead.")
        super().__init__(
            observation_space,
            action_space,
            net_arch=[],
            activation_fn=activation_fn,
            with_bias=with_bias,
            squash_output=squash_output,
            layer_norm=False,
            normalize_observations=normalize_observations,
        )
