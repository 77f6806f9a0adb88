"""SB3's ``net_arch`` forms, read as SB3's ``ActorCriticPolicy`` reads them, for every sb3-es policy."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np


def layer_sizes(layers: Any, name: str) -> list[int]:
    """
    :param layers: Hidden layer sizes given by the user.
    :param name: How to name them in an error (e.g. ``"value_net_arch"``).
    :return: The sizes as integers; a clear error if they are not a list of positive integers.
    """
    if not isinstance(layers, (list, tuple)) or any(
        isinstance(n, bool) or not isinstance(n, (int, float, np.integer)) or int(n) != n or n <= 0 for n in layers
    ):
        raise ValueError(f"{name}={layers!r}: give a list of positive integer hidden layer sizes.")
    return [int(n) for n in layers]


def split_net_arch(net_arch: Any) -> tuple[list[int] | None, list[int] | None]:
    """
    Read ``net_arch`` in any form SB3's ``ActorCriticPolicy`` takes.

    * a list of hidden layer sizes: the policy's layers (``[]``: no hidden layer);
    * ``dict(pi=[...], vf=[...])``: the policy's and the value network's layers; a missing entry is ``[]``, as in
      SB3 (``dict(pi=[64])`` has a value network without hidden layers);
    * SB3's old form ``[dict(pi=..., vf=...)]``: read as the dict, with SB3's warning.

    :param net_arch: The ``net_arch`` policy keyword argument (``None``: the policy's default).
    :return: The policy's layers and the value network's layers, each ``None`` when ``net_arch`` does not give them
        (``None``, or a list: no ``vf`` entry).
    """
    if net_arch is None:
        return None, None
    if isinstance(net_arch, (list, tuple)) and len(net_arch) > 0 and isinstance(net_arch[0], dict):
        if len(net_arch) > 1:
            raise ValueError(
                f"net_arch={net_arch!r}: shared layers before a dict are not supported (nor by SB3 since 1.8): "
                "pass net_arch=dict(pi=[...], vf=[...])."
            )
        warnings.warn(
            "As shared layers in the mlp_extractor are removed since SB3 v1.8.0, you should now pass directly a "
            "dictionary and not a list (net_arch=dict(pi=..., vf=...) instead of net_arch=[dict(pi=..., vf=...)])",
            UserWarning,
            stacklevel=3,
        )
        net_arch = net_arch[0]
    if isinstance(net_arch, dict):
        unknown = sorted(set(net_arch) - {"pi", "vf"})
        if unknown:
            raise ValueError(
                f"net_arch={net_arch!r}: unknown entr{'ies' if len(unknown) > 1 else 'y'} {unknown}; an actor-critic "
                "net_arch has 'pi' (the policy's hidden layers) and 'vf' (the value network's)."
            )
        pi, vf = net_arch.get("pi", []), net_arch.get("vf", [])
        return layer_sizes(pi, "net_arch['pi']"), layer_sizes(vf, "net_arch['vf']")
    return layer_sizes(net_arch, "net_arch"), None
