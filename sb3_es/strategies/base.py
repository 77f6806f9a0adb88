"""The ask/tell interface of a strategy: pure array math, no environment."""

from __future__ import annotations

import math
import numbers
from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np

from sb3_es.strategies.fitness import FitnessShaping, shape_fitness
from sb3_es.strategies.noise import NoiseTablePopulation, SharedNoiseTable

Population = np.ndarray | NoiseTablePopulation


class Strategy(ABC):
    """
    A search distribution over flat parameter vectors, driven by ``ask`` and ``tell``.

    ``ask()`` returns the candidates of a generation, ``tell(fitness)`` moves the distribution using
    their fitness (higher is better). As evosax's ``tell`` does, the steps every strategy shares happen
    here, once: the fitness is checked, the best candidate is tracked (``best_params``, ``best_fitness``;
    with ``forget_best``, the best of the latest generation), the fitness is shaped (``fitness_shaping``),
    and only then does the strategy's own update (``_tell``) run. A strategy's hyperparameters are
    constructor arguments and attributes; nothing outside the strategy changes them, except an SB3
    schedule that the algorithm evaluates before each generation.

    The strategy owns its random generator, so pickling it (as ``save()`` does) stores everything needed to
    continue exactly.

    :param center: Initial center (mean) of the search distribution.
    :param seed: Seed of the strategy's random generator.
    """

    #: Fitness shaping applied before ``_tell`` (see :func:`~sb3_es.strategies.fitness.shape_fitness`).
    fitness_shaping: FitnessShaping = "raw"
    #: Track only the latest generation's best candidate.
    forget_best: bool = False
    #: The shared table the candidates' noise is read from (ARS, OpenES, SimpleES take one; ``None``: drawn fresh).
    noise_table: SharedNoiseTable | None = None
    #: Version of the pickled state: files from before version 2 are upgraded on load (see ``__setstate__``).
    STATE_VERSION = 2
    #: Attributes that hold the generation in progress: what ``ask()`` made and ``tell()`` needs of it.
    pending_attributes: ClassVar[tuple[str, ...]] = ("_asked",)

    def __init__(self, center: np.ndarray, seed: int | np.random.SeedSequence | None = None) -> None:
        self.center = checked_center(center)
        self.rng = np.random.default_rng(seed)
        self.best_params = self.center.copy()
        self.best_fitness = -np.inf
        self.state_version = self.STATE_VERSION
        self._asked: Population | None = None

    def reseed(self, seed: int | np.random.SeedSequence) -> None:
        """
        Restart the random stream from ``seed``, as the constructor starts it.

        :param seed: Seed of the strategy's random generator.
        """
        self.rng = np.random.default_rng(seed)

    @property
    def num_params(self) -> int:
        """:return: Dimension of the search space."""
        return int(self.center.shape[0])

    def ask(self) -> Population:
        """
        :return: The candidates to evaluate, ``(population_size, num_params)``: an array, or a
            :class:`~sb3_es.strategies.noise.NoiseTablePopulation` that behaves as one.
        """
        self._asked = self._ask()
        return self._asked

    def tell(self, fitness: np.ndarray) -> dict[str, float]:
        """
        Update the distribution from the fitness of the candidates of the last ``ask()``.

        :param fitness: One value per candidate, higher is better, all finite.
        :return: Scalars worth logging (logged under ``train/``), ``best_fitness`` included.
        """
        if self._asked is None:
            raise RuntimeError(
                "tell() needs the generation of an ask(): none is pending (ask() not called yet, or "
                "this generation was already told)."
            )
        fitness = check_fitness(fitness, len(self._asked))
        best = int(np.argmax(fitness))
        if self.forget_best or fitness[best] > self.best_fitness:
            self.best_fitness = float(fitness[best])
            self.best_params = candidate(self._asked, best)
        stats = self._tell(shape_fitness(fitness, self.fitness_shaping))
        self._asked = None
        return {**stats, "best_fitness": self.best_fitness}

    @abstractmethod
    def _ask(self) -> Population:
        """:return: The candidates of a new generation."""

    @abstractmethod
    def _tell(self, fitness: np.ndarray) -> dict[str, float]:
        """
        The strategy's own update, from the checked and shaped fitness of the candidates just asked.

        :param fitness: Shaped fitness, one value per candidate.
        :return: Scalars worth logging.
        """

    def seed_groups(self, n_candidates: int) -> np.ndarray:
        """
        Which candidates start their episodes from the same states under common random numbers (the algorithms'
        ``common_seeds``): candidates the update compares with each other. Default: one group, the whole population.

        :param n_candidates: Size of the population asked.
        :return: The group of each candidate, ``(n_candidates,)`` integers from 0.
        """
        return np.zeros(n_candidates, dtype=np.int64)

    def check_settings(self) -> None:  # noqa: B027  (optional hook: most strategies have settings to check)
        """
        Raise a clear ``ValueError`` for settings (attributes such as ``population_size``) that the strategy cannot
        use; called when it is built and when a loaded model is given new hyperparameters. None to check here.
        """

    def _check_noise_table(self, n: int) -> None:
        """
        :param n: Number of table slices a generation draws.
        :raises ValueError: Naming ``noise_table_size`` when the shared table holds fewer (now, not at ``ask()``).
        """
        if self.noise_table is not None:
            self.noise_table.check_fits(self.num_params, n)

    def set_center(self, center: np.ndarray) -> None:
        """
        Move the center, e.g. after ``set_parameters()`` wrote new weights into the policy.

        :param center: The new center.
        """
        center = checked_center(center)
        if center.shape != self.center.shape:
            raise ValueError(f"Center of shape {center.shape} does not match the strategy's {self.center.shape}.")
        self.center = center

    def without_pending(self) -> Strategy:
        """
        :return: A shallow copy that forgets the generation in progress (its candidates, their noise), which is
            what a saved model keeps: a loaded model asks its next generation afresh, and on a large network the
            asked candidates are most of a mid-generation strategy's size.
        """
        snapshot = type(self).__new__(type(self))  # not copy.copy: __setstate__ may rewrite the state it is given
        snapshot.__dict__.update({**self.__dict__, **dict.fromkeys(self.pending_attributes)})
        return snapshot

    @property
    def restored_legacy_state(self) -> bool:
        """:return: Whether this strategy was unpickled from a file written before ``STATE_VERSION`` 2."""
        return self.state_version < 2

    def __setstate__(self, state: dict[str, Any]) -> None:
        # Files written before version 2 lack the attributes added since: fill them with their defaults.
        state.setdefault("state_version", 1)
        state.setdefault("best_params", np.asarray(state["center"], dtype=np.float64).copy())
        state.setdefault("best_fitness", -np.inf)
        state.setdefault("_asked", None)
        self.__dict__.update(state)


def mirrored_groups(n_candidates: int) -> np.ndarray:
    """
    :param n_candidates: Size of a population laid out as ``center + d_1 .. center + d_k``, then
        ``center - d_1 .. center - d_k``.
    :return: The seed groups of its mirrored pairs (``i`` and ``i + k`` in group ``i``), as estool gives both
        members of an antithetic pair the same env seed.
    """
    return np.tile(np.arange(n_candidates // 2, dtype=np.int64), 2)


def is_number(value: Any) -> bool:
    """:return: Whether ``value`` is a real number (a bool is not, nor is a string that reads as one)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def check_count(name: str, value: Any, minimum: int = 1) -> int:
    """
    :param name: Hyperparameter name, for the message.
    :param value: A count: an integer, or a float with a whole value (as YAML files and rl-zoo's ``-params`` give).
    :param minimum: Its smallest valid value.
    :return: The count as an ``int``.
    :raises ValueError: Naming ``name`` when ``value`` is not a whole number of at least ``minimum``.
    """
    number = float(value) if is_number(value) else math.nan
    if not number.is_integer():
        raise ValueError(f"{name}={value!r}: it must be a whole number (at least {minimum}).")
    if number < minimum:
        raise ValueError(f"{name}={value!r}: it must be at least {minimum}.")
    return int(number)


def check_number(name: str, value: Any) -> float:
    """
    :param name: Hyperparameter name, for the message.
    :param value: A number (not a bool).
    :return: ``value`` as a float.
    :raises TypeError: Naming ``name`` when ``value`` is not a number: a string (as YAML reads ``1e-2``), or a
        schedule given where none is taken.
    """
    if is_number(value):
        return float(value)
    hint = yaml_string_hint(value) or (" (a string)" if isinstance(value, str) else "")
    if callable(value):
        hint = f" ({name} takes no schedule)"
    raise TypeError(f"{name}={value!r}: it must be a number{hint}.")


def yaml_string_hint(value: Any) -> str:
    """:return: For a string that reads as a number (as YAML reads ``1e-2``), a hint for the message; else ``""``."""
    if isinstance(value, str) and parse_number(value) is not None:
        return " (a string; a YAML file reads a number without a dot, such as 1e-2, as one: write 1.0e-2)"
    return ""


def parse_number(text: str) -> float | None:
    """:return: The number ``float`` reads in ``text`` (``"1e-2"``), or None (``"lin_0.02"``, ``"auto"``)."""
    try:
        return float(text)
    except ValueError:
        return None


def check_flag(name: str, value: Any) -> bool:
    """
    :return: ``value`` as a bool.
    :raises TypeError: Naming ``name`` when ``value`` is not True or False (a string such as ``"False"`` would
        count as true).
    """
    if isinstance(value, bool | np.bool_):
        return bool(value)
    raise TypeError(f"{name}={value!r}: it must be True or False.")


def check_positive_number(name: str, value: Any) -> float:
    """
    :return: ``value`` as a float.
    :raises ValueError: Naming ``name`` when ``value`` is not a finite number above 0 (TypeError: no number).
    """
    number = check_number(name, value)
    if not (np.isfinite(number) and number > 0):
        raise ValueError(f"{name}={value}: it must be a positive number{' (a finite one)' if number > 0 else ''}.")
    return number


def check_non_negative(name: str, value: Any) -> float:
    """
    :return: ``value`` as a float.
    :raises ValueError: Naming ``name`` when ``value`` is negative or not finite (TypeError: no number).
    """
    number = check_number(name, value)
    if not (np.isfinite(number) and number >= 0):
        raise ValueError(f"{name}={value!r}: it must be a finite number >= 0.")
    return number


def candidate(population: Population, index: int) -> np.ndarray:
    """
    :param population: The candidates, dense or read from a noise table.
    :param index: Which candidate.
    :return: A float64 copy of that candidate (only that row is computed for a noise-table population).
    """
    if isinstance(population, NoiseTablePopulation):
        return population.row(index)
    return np.array(population[index], dtype=np.float64)


def check_fitness(fitness: np.ndarray, expected: int) -> np.ndarray:
    """
    Validate a fitness vector before a strategy uses it.

    :param fitness: Fitness of each candidate.
    :param expected: Number of candidates asked.
    :return: The fitness as a float64 array.
    """
    fitness = np.asarray(fitness, dtype=np.float64)
    if fitness.shape != (expected,):
        raise ValueError(f"Expected {expected} fitness values, got shape {fitness.shape}.")
    bad = np.flatnonzero(~np.isfinite(fitness))
    if bad.size:
        raise ValueError(
            f"Non-finite fitness for candidate(s) {bad.tolist()} (values {fitness[bad].tolist()}); "
            "the update was not applied. Check the environment's rewards (NaN/inf) or lower the noise."
        )
    return fitness


def checked_center(center: np.ndarray) -> np.ndarray:
    """
    Validate a center (the search distribution's mean) given to a strategy.

    :param center: The center: a non-empty 1-D array of finite numbers.
    :return: A float64 copy.
    """
    array = np.array(center, dtype=np.float64)
    if array.ndim != 1 or array.size == 0:
        raise ValueError(f"center: give a non-empty 1-D array of parameters, got shape {array.shape}.")
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise ValueError(f"center: entries {bad[:5].tolist()} are NaN or infinite; give finite parameters.")
    return array
