"""The optimizers that move a strategy's center along an estimated gradient: Adam, SGD and ClipUp.

Adam and SGD are PyTorch's. ClipUp (Toklu, Liskowski and Srivastava, 2020, "ClipUp: a simple and powerful
optimizer for distribution-based policy evolution") is written here as a PyTorch optimizer: a step of fixed
length along the normalized gradient, heavy-ball momentum, and a cap on the norm of the velocity. The
strategies that use them (OpenES, PGPE) share :class:`GradientStrategy`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any, Literal

import numpy as np
import torch as th

from sb3_es.strategies.base import Strategy, check_number, check_positive_number

OptimizerName = Literal["adam", "sgd", "clipup"]
#: The optimizer names, for validation messages.
OPTIMIZERS: tuple[OptimizerName, ...] = ("adam", "sgd", "clipup")
#: SGD's and ClipUp's momentum when none is given.
DEFAULT_MOMENTUM = 0.9


def check_optimizer_name(name: Any) -> None:
    """:raises ValueError: For a name that is not one of :data:`OPTIMIZERS` (lower case)."""
    if name not in OPTIMIZERS:
        raise ValueError(f"optimizer={name!r}: choose one of {', '.join(map(repr, OPTIMIZERS))} (lower case).")


class ClipUp(th.optim.Optimizer):
    """
    ClipUp (Toklu et al., 2020): ``v <- momentum * v + lr * g / ||g||``, then ``v`` is scaled down to norm
    ``max_speed`` if it is longer, and the parameters move by ``-v`` (a PyTorch optimizer minimizes).

    The step length does not depend on the scale of the gradient, so ``lr`` and ``max_speed`` are distances in
    parameter space; the paper recommends ``lr = max_speed / 2`` and momentum 0.9. The gradient norm is that of
    each parameter tensor (a strategy optimizes one flat vector, so it is the whole gradient's).

    :param params: Parameters to optimize.
    :param lr: Step length ``alpha`` of one normalized gradient.
    :param max_speed: Largest norm of the velocity (``None``: ``2 * lr``).
    :param momentum: Momentum of the velocity.
    """

    def __init__(
        self, params: Iterable[th.Tensor], lr: float, max_speed: float | None = None, momentum: float = 0.9
    ) -> None:
        max_speed = 2 * lr if max_speed is None else max_speed
        for name, value in (("lr", lr), ("max_speed", max_speed)):
            check_positive_number(f"ClipUp {name}", value)
        if not 0 <= check_number("ClipUp momentum", momentum) < 1:
            raise ValueError(f"ClipUp momentum={momentum}: it must be in [0, 1).")
        super().__init__(params, dict(lr=lr, max_speed=max_speed, momentum=momentum))

    @th.no_grad()
    def step(self, closure: Callable[[], float] | None = None) -> float | None:  # type: ignore[override]
        """
        One ClipUp step.

        :param closure: Re-evaluates the loss (optional, as in PyTorch).
        :return: The loss returned by ``closure``, if given.
        """
        loss = None
        if closure is not None:
            with th.enable_grad():
                loss = closure()
        for group in self.param_groups:
            for param in group["params"]:
                if param.grad is None:
                    continue
                state = self.state[param]
                velocity = state.get("velocity", th.zeros_like(param))
                norm = th.linalg.vector_norm(param.grad)
                direction = param.grad / norm if norm > 0 else th.zeros_like(param)
                velocity = group["momentum"] * velocity + group["lr"] * direction
                speed = th.linalg.vector_norm(velocity)
                if speed > group["max_speed"]:
                    velocity = velocity * (group["max_speed"] / speed)
                state["velocity"] = velocity
                param.sub_(velocity)
        return loss


def make_optimizer(
    name: OptimizerName,
    params: Iterable[th.Tensor],
    learning_rate: float,
    momentum: float = 0.9,
    betas: tuple[float, float] = (0.9, 0.999),
    max_speed: float | None = None,
) -> th.optim.Optimizer:
    """
    Build one of the optimizers by name.

    :param name: ``"adam"``, ``"sgd"`` or ``"clipup"``.
    :param params: Parameters to optimize.
    :param learning_rate: Step size (for ClipUp, the step length of one normalized gradient).
    :param momentum: SGD's and ClipUp's momentum.
    :param betas: Adam's betas.
    :param max_speed: ClipUp's largest step (``None``: ``2 * learning_rate``); only for ClipUp.
    :return: The optimizer.
    """
    check_optimizer_name(name)
    # checked whichever optimizer, as a value that is not used is still a mistake
    if not 0 <= check_number("momentum", momentum) < 1:
        raise ValueError(f"momentum={momentum}: the SGD and ClipUp momentum must be in [0, 1).")
    if max_speed is not None and name != "clipup":
        raise ValueError(f"max_speed={max_speed} is a ClipUp setting; it has no effect with optimizer={name!r}.")
    if name == "adam" and momentum != DEFAULT_MOMENTUM:
        raise ValueError(
            f"momentum={momentum} is an SGD and ClipUp setting; it has no effect with optimizer='adam' (Adam's "
            "moments follow betas). Leave momentum out, or choose optimizer='sgd' or 'clipup'."
        )
    if name == "adam":
        return th.optim.Adam(params, lr=learning_rate, betas=betas)
    if name == "sgd":
        return th.optim.SGD(params, lr=learning_rate, momentum=momentum)
    return ClipUp(params, lr=learning_rate, max_speed=max_speed, momentum=momentum)


class GradientStrategy(Strategy):
    """
    A strategy whose center follows an estimated gradient with one of the optimizers above (OpenES, PGPE).

    The center is also held as a float64 ``torch`` parameter (``_theta``) that the optimizer updates; the
    optimizer's state (Adam's moments, ClipUp's velocity) is pickled with the strategy.

    :param center: Initial center.
    :param learning_rate: Optimizer step size (an attribute; an SB3 schedule may overwrite it each generation).
    :param optimizer: ``"adam"``, ``"sgd"`` or ``"clipup"``.
    :param momentum: SGD's and ClipUp's momentum.
    :param betas: Adam's betas.
    :param max_speed: ClipUp's largest step (``None``: twice the initial ``learning_rate``).
    :param seed: Seed of the random generator.
    """

    def __init__(
        self,
        center: np.ndarray,
        learning_rate: float,
        optimizer: OptimizerName = "adam",
        momentum: float = 0.9,
        betas: tuple[float, float] = (0.9, 0.999),
        max_speed: float | None = None,
        seed: int | np.random.SeedSequence | None = None,
    ) -> None:
        super().__init__(center, seed)
        check_positive_number("learning_rate", learning_rate)
        self.learning_rate = float(learning_rate)
        self._theta = th.nn.Parameter(th.as_tensor(self.center, dtype=th.float64).clone())
        self.optimizer = make_optimizer(optimizer, [self._theta], self.learning_rate, momentum, betas, max_speed)

    def _ascend(self, gradient: np.ndarray) -> None:
        """
        One optimizer step up ``gradient`` (the optimizers minimize, so they are given ``-gradient``).

        :param gradient: Ascent direction for the center (estimated gradient, minus any decay term).
        """
        self._theta.grad = th.as_tensor(-gradient, dtype=th.float64)
        for group in self.optimizer.param_groups:
            group["lr"] = self.learning_rate
        self.optimizer.step()
        self.center = self._theta.detach().numpy().copy()

    @property
    def max_speed(self) -> float | None:
        """:return: ClipUp's largest step; ``None`` with another optimizer."""
        return self.optimizer.param_groups[0]["max_speed"] if isinstance(self.optimizer, ClipUp) else None

    @max_speed.setter
    def max_speed(self, value: float | None) -> None:
        """
        Change ClipUp's largest step from the next update on (a velocity above it is cut then).

        :param value: A positive number with ClipUp, ``None`` with another optimizer.
        """
        if not isinstance(self.optimizer, ClipUp):
            if value is not None:
                raise ValueError(f"max_speed={value} is a ClipUp setting; this strategy's optimizer is not ClipUp.")
            return
        if value is None:
            raise ValueError("max_speed=None: ClipUp needs a largest step, a positive number.")
        check_positive_number("max_speed", value)
        for group in self.optimizer.param_groups:
            group["max_speed"] = float(value)

    def optimizer_stats(self) -> dict[str, Any]:
        """:return: ``{"speed": |velocity|}`` for ClipUp (how far the last step went), else nothing."""
        if isinstance(self.optimizer, ClipUp):
            velocity = self.optimizer.state[self._theta].get("velocity")
            return {"speed": float(th.linalg.vector_norm(velocity)) if velocity is not None else 0.0}
        return {}

    def set_center(self, center: np.ndarray) -> None:
        super().set_center(center)
        with th.no_grad():
            self._theta.copy_(th.as_tensor(self.center))
