"""Fitness shaping: the transforms a strategy applies to the fitness before its update (pure array math)."""

from __future__ import annotations

from typing import Literal

import numpy as np

FitnessShaping = Literal["centered_rank", "zscore", "raw"]
#: The fitness shaping names, for validation messages.
FITNESS_SHAPINGS: tuple[FitnessShaping, ...] = ("centered_rank", "zscore", "raw")


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
    Fitness shaping before the update.

    :param fitness: Raw fitness.
    :param shaping: ``"centered_rank"``, ``"zscore"`` (standardized) or ``"raw"``.
    :return: Shaped fitness.
    """
    if shaping == "centered_rank":
        return centered_ranks(fitness)
    if shaping == "zscore":
        if np.ptp(fitness) == 0:  # equal values: std() can round to about 1e-17 and give +-1
            return np.zeros_like(fitness)
        return (fitness - fitness.mean()) / fitness.std()
    if shaping == "raw":
        return fitness
    raise ValueError(f"fitness_shaping={shaping!r}: choose one of {', '.join(map(repr, FITNESS_SHAPINGS))}.")
