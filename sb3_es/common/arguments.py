"""Passing a typed ``__init__``'s arguments on to the base class without writing each name twice."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any


def base_arguments(base_init: Callable[..., Any], namespace: dict[str, Any]) -> dict[str, Any]:
    """
    The arguments of a subclass's ``__init__`` that its base class's ``__init__`` takes.

    Every algorithm repeats the typed signature it shares with its base class, as SB3's algorithms do (so that
    users and rl-zoo see every hyperparameter with its type and default); this passes those arguments on by name:
    ``super().__init__(**base_arguments(super().__init__, locals()))``, called before any other local variable
    is given the name of one of the base class's parameters.

    :param base_init: The base class's ``__init__`` (bound, e.g. ``super().__init__``).
    :param namespace: The subclass's ``locals()``: its parameters, possibly converted or checked.
    :return: ``name -> value`` for each parameter of ``base_init`` found in ``namespace`` (the others keep their
        defaults).
    """
    names = inspect.signature(base_init).parameters
    return {name: namespace[name] for name in names if name != "self" and name in namespace}
