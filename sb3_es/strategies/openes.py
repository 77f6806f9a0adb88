"""OpenAI's evolution strategy (Salimans et al., 2017), in the extended form of estool."""

from __future__ import annotations

from typing import Literal

import numpy as np
import torch as th

from sb3_es.strategies.base import Strategy, check_fitness
from sb3_es.strategies.noise import NoiseTablePopulation, SharedNoiseTable

FitnessShaping = Literal["centered_rank", "zscore", "raw"]


def centered_ranks(x: np.ndarray) -> np.ndarray:
    """
    Rank transform to ``[-0.5, 0.5]`` (lowest fitness -0.5, highest +0.5; ties get distinct ranks).

    :param x: Fitness values.
    :return: Centered ranks, float64.
    """
    ranks = np.empty(len(x))
    ranks[np.argsort(x, kind="stable")] = np.arange(len(x))
    return ranks / max(len(x) - 1, 1) - 0.5


def shape_fitness(fitness: np.ndarray, shaping: FitnessShaping) -> np.ndarray:
    """
    Fitness shaping before the gradient estimate.

    :param fitness: Raw fitness.
    :param shaping: ``"centered_rank"``, ``"zscore"`` (standardized) or ``"raw"``.
    :return: Shaped fitness.
    """
    if shaping == "centered_rank":
        return centered_ranks(fitness)
    if shaping == "zscore":
        std = fitness.std()
        return (fitness - fitness.mean()) / std if std > 0 else np.zeros_like(fitness)
    if shaping == "raw":
        return fitness
    raise ValueError(f"fitness_shaping={shaping!r}: choose 'centered_rank', 'zscore' or 'raw'.")


class OpenESStrategy(Strategy):
    """
    OpenAI-ES: isotropic Gaussian perturbations (optionally mirrored), shaped fitness, and a gradient step
    on the mean with Adam or SGD (torch optimizers on the flat vector); L2 weight decay as in OpenAI's code.

    The best candidate seen is tracked (``best_params``, ``best_fitness``); with ``forget_best`` it is the
    best of the latest generation only.

    :param center: Initial mean.
    :param population_size: Candidates per generation (even when ``antithetic``).
    :param antithetic: Mirrored sampling ``theta +/- sigma * eps``.
    :param fitness_shaping: ``"centered_rank"`` (default), ``"zscore"`` or ``"raw"``.
    :param optimizer: ``"adam"`` or ``"sgd"``.
    :param momentum: SGD momentum.
    :param betas: Adam's betas.
    :param weight_decay: L2 coefficient added to the gradient.
    :param forget_best: Keep only the latest generation's best candidate.
    :param seed: Seed of the random generator.
    :param noise_table: Read the perturbations from this shared table (``ask()`` then returns a
        :class:`~sb3_es.strategies.noise.NoiseTablePopulation`, which Ray ships as offsets).
    """

    def __init__(
        self,
        center: np.ndarray,
        population_size: int,
        antithetic: bool = True,
        fitness_shaping: FitnessShaping = "centered_rank",
        optimizer: Literal["adam", "sgd"] = "adam",
        momentum: float = 0.9,
        betas: tuple[float, float] = (0.9, 0.999),
        weight_decay: float = 0.0,
        forget_best: bool = False,
        seed: int | np.random.SeedSequence | None = None,
        noise_table: SharedNoiseTable | None = None,
    ) -> None:
        super().__init__(center, seed)  # type: ignore[arg-type]
        self.noise_table = noise_table
        if population_size < 2 or (antithetic and population_size % 2):
            raise ValueError(
                f"population_size={population_size}: it must be at least 2, and even with antithetic sampling."
            )
        if weight_decay < 0:
            raise ValueError(f"weight_decay={weight_decay}: it must be >= 0.")
        shape_fitness(np.zeros(2), fitness_shaping)  # validates the name
        self.population_size = population_size
        self.antithetic = antithetic
        self.fitness_shaping: FitnessShaping = fitness_shaping
        self.weight_decay = weight_decay
        self.forget_best = forget_best
        self.sigma = 0.1
        self.learning_rate = 0.01
        self._theta = th.nn.Parameter(th.as_tensor(self.center, dtype=th.float64).clone())
        if optimizer == "adam":
            self.optimizer: th.optim.Optimizer = th.optim.Adam([self._theta], lr=self.learning_rate, betas=betas)
        elif optimizer == "sgd":
            self.optimizer = th.optim.SGD([self._theta], lr=self.learning_rate, momentum=momentum)
        else:
            raise ValueError(f"optimizer={optimizer!r}: choose 'adam' or 'sgd'.")
        self.best_params = self.center.copy()
        self.best_fitness = -np.inf
        self._noise: np.ndarray | None = None
        self._candidates: np.ndarray | None = None

    def ask(self) -> np.ndarray | NoiseTablePopulation:
        half = self.population_size // 2 if self.antithetic else self.population_size
        if self.noise_table is None:
            eps = self.rng.standard_normal((half, self.num_params))
            self._noise = np.concatenate([eps, -eps]) if self.antithetic else eps
            self._candidates = self.center + self.sigma * self._noise
            return self._candidates
        offsets = self.noise_table.sample_offsets(self.rng, self.num_params, half)
        eps = np.stack([self.noise_table.get(o, self.num_params) for o in offsets]).astype(np.float64)
        signs = np.repeat([1.0, -1.0], half) if self.antithetic else np.ones(half)
        self._noise = np.concatenate([eps, -eps]) if self.antithetic else eps
        population = NoiseTablePopulation(
            self.noise_table,
            self.center.copy(),
            np.tile(offsets, 2) if self.antithetic else offsets,
            self.sigma * signs,
        )
        self._candidates = population.dense()
        return population

    def tell(self, fitness: np.ndarray) -> dict[str, float]:
        if self._noise is None or self._candidates is None:
            raise RuntimeError("tell() called before ask().")
        fitness = check_fitness(fitness, self.population_size)
        best = int(np.argmax(fitness))
        if self.forget_best or fitness[best] > self.best_fitness:
            self.best_fitness = float(fitness[best])
            self.best_params = self._candidates[best].copy()
        shaped = shape_fitness(fitness, self.fitness_shaping)
        grad = self._noise.T @ shaped / (self.population_size * self.sigma)
        # Optimizers minimize: descend on -grad (+ L2 decay, as OpenAI-ES adds l2coeff * theta).
        self._theta.grad = th.as_tensor(-grad + self.weight_decay * self.center, dtype=th.float64)
        for group in self.optimizer.param_groups:
            group["lr"] = self.learning_rate
        self.optimizer.step()
        self.center = self._theta.detach().numpy().copy()
        self._noise = self._candidates = None
        return {
            "sigma": self.sigma,
            "learning_rate": self.learning_rate,
            "grad_norm": float(np.linalg.norm(grad)),
            "best_fitness": self.best_fitness,
        }

    def set_center(self, center: np.ndarray) -> None:
        super().set_center(center)
        with th.no_grad():
            self._theta.copy_(th.as_tensor(self.center))
