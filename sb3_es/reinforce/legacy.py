"""Reading REINFORCE saves written before :class:`~sb3_es.reinforce.DiscretizedPolicy` became an ``ActorCriticPolicy``.

The old policy had ``policy_net`` (hidden layers), ``action_net`` and, with a baseline only, a
``value_net`` MLP whose last layer was the value head. ``ActorCriticPolicy`` names the hidden layers
``mlp_extractor.policy_net`` / ``mlp_extractor.value_net``, the value head ``value_net``, and always has
one. The tensors are the same; only their names and the order of the optimizer's parameters differ.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from typing import Any

from torch import nn

_OLD_VALUE_LAYER = re.compile(r"value_net\.(\d+)\.(.+)")


def is_legacy_state_dict(state_dict: Iterable[str], prefix: str = "") -> bool:
    """
    :param state_dict: A policy's state dict (or its keys).
    :param prefix: Prefix of the policy's keys.
    :return: Whether it was written by the old policy (every current one has the value head ``value_net.weight``).
    """
    return prefix + "value_net.weight" not in state_dict


def legacy_key_map(names: Iterable[str]) -> dict[str, str]:
    """
    :param names: Keys of an old policy state dict (without prefix).
    :return: Old key -> current key.
    """
    names = list(names)
    value_layers = [int(m[1]) for m in map(_OLD_VALUE_LAYER.fullmatch, names) if m]
    head = max(value_layers, default=-1)
    mapping = {}
    for name in names:
        match = _OLD_VALUE_LAYER.fullmatch(name)
        if name.startswith("policy_net.") or (match and int(match[1]) != head):
            mapping[name] = "mlp_extractor." + name
        elif match:
            mapping[name] = "value_net." + match[2]
        else:
            mapping[name] = name
    return mapping


def upgrade_legacy_state_dict(policy: nn.Module, state_dict: dict[str, Any], prefix: str) -> None:
    """
    Rename, in place, the keys of an old state dict loaded into ``policy`` (a no-op for a current one).

    Keys the old policy did not have are filled in: the aliases of a shared features extractor, and
    the value head of a policy without baseline (unused, so it keeps its current values).

    :param policy: The policy being loaded.
    :param state_dict: The state dict given to ``load_state_dict``.
    :param prefix: Prefix of the policy's keys in it.
    """
    if not is_legacy_state_dict(state_dict, prefix):
        return
    names = [key[len(prefix) :] for key in state_dict if key.startswith(prefix)]
    tensors = {new: state_dict.pop(prefix + old) for old, new in legacy_key_map(names).items()}
    for name, value in policy.state_dict().items():
        if name in tensors:
            continue
        extractor, _, rest = name.partition(".")
        if extractor in ("pi_features_extractor", "vf_features_extractor") and f"features_extractor.{rest}" in tensors:
            tensors[name] = tensors[f"features_extractor.{rest}"]
        elif not getattr(policy, "use_baseline", True) and name.startswith(("value_net.", "mlp_extractor.value_net.")):
            tensors[name] = value
    state_dict.update({prefix + name: value for name, value in tensors.items()})


def upgrade_legacy_optimizer_state(
    policy: nn.Module, policy_state: dict[str, Any], optimizer_state: dict[str, Any]
) -> dict[str, Any]:
    """
    Re-index an old optimizer state for the current policy's parameter order (a no-op for a current save).

    :param policy: The policy the optimizer belongs to.
    :param policy_state: The policy state dict saved with the optimizer state.
    :param optimizer_state: The saved optimizer state dict.
    :return: The optimizer state dict to load.
    """
    if not is_legacy_state_dict(policy_state):
        return optimizer_state
    mapping = legacy_key_map(policy_state)
    new_index = {name: i for i, (name, _) in enumerate(policy.named_parameters())}
    old_params = [mapping[key] for key in policy_state if mapping[key] in new_index]  # the old parameter order
    groups = optimizer_state["param_groups"]
    if len(groups) != 1 or len(groups[0]["params"]) != len(old_params):
        raise ValueError(
            f"The saved optimizer state has {[len(g['params']) for g in groups]} parameters in its groups, but the "
            f"saved policy has {len(old_params)}: the save is damaged or was not written by sb3-es REINFORCE."
        )
    position = {param_id: j for j, param_id in enumerate(groups[0]["params"])}
    state = {new_index[old_params[position[i]]]: value for i, value in optimizer_state["state"].items()}
    return {"state": state, "param_groups": [dict(groups[0], params=list(range(len(new_index))))]}
