"""The NumPy network that evaluators run: a small picklable spec, and its batched forward pass.

A :class:`NetworkSpec` holds everything needed to turn observations into actions for any parameter vector: the
observation and action spaces, where each layer's parameters lie in the flat vector, the activations, and a
snapshot of the observation statistics (observations are flattened by :mod:`~sb3_es.evaluation.observations`). It
holds no parameters and no SB3 policy: the policy (:class:`sb3_es.common.policies.FlatPolicy`) builds one,
``predict()`` runs it, and evaluators (in this process, in worker processes, on Ray actors) receive it, so every
path computes the same actions with the same code.

Its forward pass is batched over candidates: row ``k`` of the observations goes through the network whose
parameters are row ``k`` of a population matrix (NumPy's batched matrix-vector product, much faster than torch
for these small networks).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Protocol, runtime_checkable

import numpy as np
import torch as th
from gymnasium import spaces

from sb3_es.evaluation.observations import flat_obs_dim, flatten_obs

#: Variance floor used when normalizing observations (same as SB3's ``VecNormalize``).
OBS_NORM_EPS = 1e-8

#: A layer's parameters in the flat vector: ``(start, stop, shape)``.
ParamSlice = tuple[int, int, tuple[int, ...]]


# ---------------------------------------------------------------------------------------------------- layers
@dataclass(frozen=True)
class Linear:
    """
    ``x -> W x + b`` for each row's own ``W`` and ``b``.

    :param weight: Where ``W`` lies in the flat vector.
    :param bias: Where ``b`` lies, or ``None`` for no bias.
    """

    weight: ParamSlice
    bias: ParamSlice | None = None


@dataclass(frozen=True)
class LayerNorm:
    """
    Layer normalization over the features, with each row's own gain and bias (as ``torch.nn.LayerNorm``).

    :param gain: Where the gain lies in the flat vector.
    :param bias: Where the bias lies.
    :param eps: Variance floor.
    """

    gain: ParamSlice
    bias: ParamSlice
    eps: float


def relu(x: np.ndarray) -> np.ndarray:
    """:return: ``max(x, 0)``."""
    return np.maximum(x, 0)


def sigmoid(x: np.ndarray) -> np.ndarray:
    """:return: ``1 / (1 + exp(-x))``."""
    return 1 / (1 + np.exp(-x))


def identity(x: np.ndarray) -> np.ndarray:
    """:return: ``x``."""
    return x


@dataclass(frozen=True)
class Activation:
    """
    An element-wise function without parameters.

    :param fn: A picklable function of a NumPy array (:func:`relu`, ``np.tanh``, ..., or a
        :class:`TorchActivation` for other torch activation modules).
    """

    fn: Callable[[np.ndarray], np.ndarray]

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return self.fn(x).astype(x.dtype, copy=False)


class TorchActivation:
    """
    A torch activation module applied to a NumPy array, for activations without a NumPy version here.

    :param module: The module (e.g. ``torch.nn.ELU()``); it must be picklable.
    """

    def __init__(self, module: object) -> None:
        self.module = module

    def __call__(self, x: np.ndarray) -> np.ndarray:
        # Rows of features (axis 1 here), as the torch policy gives them: an activation that is not element-wise,
        # such as Softmax, then acts within each row, never across candidates or observations.
        rows = np.ascontiguousarray(np.moveaxis(x, 1, -1))
        with th.no_grad():
            out = self.module(th.from_numpy(rows.reshape(-1, rows.shape[-1]))).numpy()  # type: ignore[operator]
        return np.moveaxis(out.reshape(rows.shape), -1, 1)


Layer = Linear | LayerNorm | Activation

#: NumPy versions of torch activation modules, by class name (``nn.ReLU`` -> ``"ReLU"``).
NUMPY_ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "ReLU": relu,
    "Tanh": np.tanh,
    "Sigmoid": sigmoid,
    "Identity": identity,
}


def activation_for(module: object) -> Activation:
    """
    :param module: A torch activation module without parameters.
    :return: Its NumPy version when there is one, else a :class:`TorchActivation` around it.
    """
    fast = NUMPY_ACTIVATIONS.get(type(module).__name__) if type(module).__module__.startswith("torch.") else None
    return Activation(fast if fast is not None else TorchActivation(module))


# ---------------------------------------------------------------------------------------------------- the spec
@dataclass(frozen=True, eq=False)
class NetworkSpec:
    """
    A deterministic network over flat parameter vectors, with frozen observation statistics (picklable).

    Actions: for ``Discrete`` spaces the argmax of the outputs; for ``Box`` spaces the outputs rescaled from
    ``[-1, 1]`` to the bounds when ``squash_output`` (the last layer is then a ``tanh``), else clipped to them
    (:func:`box_actions`).

    :param observation_space: The observation space (``Box``, ``Discrete``, ``MultiDiscrete``, ``MultiBinary``, or a
        ``Dict`` of them).
    :param action_space: The action space (``Box`` with finite bounds, or ``Discrete``).
    :param layers: The layers, in order.
    :param num_params: Length of a parameter vector.
    :param squash_output: Whether ``Box`` outputs are in ``[-1, 1]`` and rescaled (else clipped).
    :param obs_mean: Mean of the observations (float64), or ``None`` for no normalization.
    :param obs_var: Their variance (float64), or ``None``.
    """

    observation_space: spaces.Space
    action_space: spaces.Space
    layers: tuple[Layer, ...]
    num_params: int
    squash_output: bool = False
    obs_mean: np.ndarray | None = None
    obs_var: np.ndarray | None = None

    @property
    def obs_dim(self) -> int:
        """:return: Size of a flattened observation."""
        return flat_obs_dim(self.observation_space)

    @property
    def normalizes(self) -> bool:
        """:return: Whether observations are normalized with the statistics."""
        return self.obs_mean is not None

    def with_obs_stats(self, mean: np.ndarray | None, var: np.ndarray | None) -> NetworkSpec:
        """
        :param mean: Observation mean, or ``None`` for no normalization.
        :param var: Observation variance.
        :return: The same network with these statistics.
        """
        return dataclasses.replace(self, obs_mean=mean, obs_var=var)

    def output_layer_slice(self) -> slice:
        """:return: Where the last linear layer's weight and bias lie in the flat vector."""
        last = [layer for layer in self.layers if isinstance(layer, Linear)][-1]
        stop = last.bias[1] if last.bias is not None else last.weight[1]
        return slice(last.weight[0], stop)

    def flatten_obs(self, obs: np.ndarray | dict[str, np.ndarray]) -> np.ndarray:
        """
        :param obs: A batch of observations (array, or dict of arrays for ``Dict`` spaces).
        :return: Flattened observations ``(n, obs_dim)``, float32.
        """
        return flatten_obs(self.observation_space, obs)

    @cached_property
    def _normalizer(self) -> tuple[np.ndarray, np.ndarray] | None:
        if self.obs_mean is None or self.obs_var is None:
            return None
        mean = np.asarray(self.obs_mean).astype(np.float32)
        inv_std = (1.0 / np.sqrt(np.asarray(self.obs_var) + OBS_NORM_EPS)).astype(np.float32)
        return mean, inv_std

    def normalize(self, flat_obs: np.ndarray) -> np.ndarray:
        """
        :param flat_obs: Flattened observations ``(n, obs_dim)``.
        :return: Normalized observations, float32 (unchanged without statistics).
        """
        if self._normalizer is None:
            return flat_obs
        mean, inv_std = self._normalizer
        return (flat_obs - mean) * inv_std

    def forward(self, params: np.ndarray, x: np.ndarray) -> np.ndarray:
        """
        Raw outputs, where row ``k`` of ``x`` goes through the network of parameter row ``k``.

        :param params: Parameters ``(k, num_params)`` or ``(1, num_params)`` (broadcast), float32.
        :param x: Normalized observations ``(k, obs_dim)``, float32.
        :return: Outputs ``(k, output_dim)``.
        """
        x = x[:, :, None]  # (k, features, 1)
        for layer in self.layers:
            if isinstance(layer, Linear):
                w0, w1, w_shape = layer.weight
                x = np.matmul(params[:, w0:w1].reshape(-1, *w_shape), x)
                if layer.bias is not None:
                    x = x + params[:, layer.bias[0] : layer.bias[1], None]
            elif isinstance(layer, LayerNorm):
                mean = x.mean(axis=1, keepdims=True)
                var = x.var(axis=1, keepdims=True)
                (g0, g1, _), (b0, b1, _) = layer.gain, layer.bias
                x = (x - mean) / np.sqrt(var + layer.eps) * params[:, g0:g1, None] + params[:, b0:b1, None]
            else:
                x = layer(x)
        return x[:, :, 0]

    def __call__(self, params: np.ndarray, flat_obs: np.ndarray) -> np.ndarray:
        """
        Env actions of a population: row ``k`` of ``flat_obs`` through the network of parameter row ``k``.

        :param params: Parameters ``(k, num_params)`` (or one row, broadcast), float32.
        :param flat_obs: Flattened raw observations ``(k, obs_dim)`` (see :meth:`flatten_obs`).
        :return: Env actions: argmax (plus the space's ``start``) for ``Discrete``; for ``Box``, outputs rescaled
            to the bounds (as SB3's ``unscale_action``) or clipped to them.
        """
        out = self.forward(params, self.normalize(flat_obs))
        if isinstance(self.action_space, spaces.Discrete):
            return out.argmax(axis=1) + int(self.action_space.start)
        assert isinstance(self.action_space, spaces.Box)
        return box_actions(out.reshape((-1, *self.action_space.shape)), self.action_space, self.squash_output)


def box_actions(outputs: np.ndarray, action_space: spaces.Box, squash_output: bool) -> np.ndarray:
    """
    Env actions from a network's outputs, in the space's dtype: rescaled from ``[-1, 1]`` to the bounds (as SB3's
    ``unscale_action``) or clipped to them, in float64 (bounds near the float32 limit would overflow ``high - low``),
    and rounded to the nearest integer for an integer ``Box``.

    :param outputs: Outputs ``(n, *action_space.shape)``.
    :param action_space: A ``Box`` with finite bounds.
    :param squash_output: Whether the outputs are in ``[-1, 1]`` (a ``tanh`` last layer) and rescaled.
    :return: Actions ``(n, *action_space.shape)`` inside the space.
    """
    low, high = action_space.low.astype(np.float64), action_space.high.astype(np.float64)
    if squash_output:
        actions = low + 0.5 * (np.asarray(outputs, dtype=np.float64) + 1.0) * (high - low)
    else:
        actions = np.clip(np.asarray(outputs, dtype=np.float64), low, high)
    if np.issubdtype(action_space.dtype, np.integer):
        actions = np.clip(np.rint(actions), low, high)
    return actions.astype(action_space.dtype, copy=False)


@runtime_checkable
class HasNetworkSpec(Protocol):
    """Anything that can give its network spec (e.g. a :class:`~sb3_es.common.policies.FlatPolicy`)."""

    def network_spec(self) -> NetworkSpec:
        """:return: The network with its current observation statistics."""
        ...


def as_network(network: NetworkSpec | HasNetworkSpec) -> NetworkSpec:
    """
    :param network: A spec, or an object with a ``network_spec()`` method (a policy).
    :return: The spec.
    """
    return network if isinstance(network, NetworkSpec) else network.network_spec()
