"""The layers of a torch ``nn.Sequential`` as the NumPy network the evaluators run (the layers of a
:class:`~sb3_es.evaluation.network.NetworkSpec`)."""

from __future__ import annotations

from torch import nn

from sb3_es.evaluation.network import Layer, LayerNorm, Linear, ParamSlice, activation_for


def network_layers(net: nn.Sequential) -> tuple[tuple[Layer, ...], int]:
    """
    Describe each module of ``net`` as a layer of a spec, with where its parameters lie in the flat vector (offsets
    in the order of ``net.parameters()``, as ``parameters_to_vector`` lays them out).

    :param net: Linear layers, ``LayerNorm`` and parameter-free activations.
    :return: The layers, and the length of the flat parameter vector.
    """
    layers: list[Layer] = []
    offset = 0
    for module in net:
        slices: list[ParamSlice] = []
        for param in module.parameters(recurse=False):
            size = param.numel()
            slices.append((offset, offset + size, tuple(param.shape)))
            offset += size
        if isinstance(module, nn.Linear):
            layers.append(Linear(slices[0], slices[1] if len(slices) > 1 else None))
        elif isinstance(module, nn.LayerNorm):
            layers.append(LayerNorm(slices[0], slices[1], float(module.eps)))
        elif slices:
            raise ValueError(f"Module {module} has parameters but no batched forward pass.")
        else:
            layers.append(activation_for(module))
    return tuple(layers), offset
