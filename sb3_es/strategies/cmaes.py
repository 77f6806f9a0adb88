"""CMA-ES through pycma (``cma``): ask/tell, maximization by negation, optional IPOP/BIPOP restarts."""

from __future__ import annotations

import contextlib
import math
import os
import warnings
from collections.abc import Iterator, Mapping
from types import ModuleType
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from sb3_es.strategies.base import Strategy, check_count, check_flag, check_positive_number, parse_number

if TYPE_CHECKING:
    import cma

Restarts = Literal["ipop", "bipop"] | None


def _import_cma() -> ModuleType:
    """
    Import pycma on first use: it imports SciPy and matplotlib (about 2 s), which ``import sb3_es`` and the
    evaluation workers, who never build a CMA-ES, should not pay for.

    :return: The ``cma`` module.
    """
    with warnings.catch_warnings():  # pycma warns at import when matplotlib (only used for its plots) is absent
        warnings.simplefilter("ignore")
        import cma

    return cma


def _global_randn(*shape: int) -> np.ndarray:
    """
    Standard normal samples from NumPy's global random state (which the strategy swaps for its own).

    :param shape: Shape of the sample.
    :return: The samples.
    """
    return np.random.randn(*shape)


#: pycma's full covariance needs about this many ``n x n`` float64 matrices at its peak (C, B and the
#: eigendecomposition's work arrays; measured with pycma 4.5 on 1,500 parameters).
FULL_COVARIANCE_MATRICES = 5
#: pycma options that make it search a transformed space: its mean would not be the policy's parameters.
REMAPPING_OPTIONS = ("bounds", "fixed_variables", "scaling_of_variables", "typical_x", "transformation")
#: Stop conditions that end the search, as in pycma's ``fmin``: no restart follows them.
FINAL_STOPS = frozenset({"ftarget", "maxfevals"})


def check_full_covariance_memory(num_params: int) -> None:
    """
    Refuse, before pycma allocates it, a full covariance matrix larger than this machine's memory.

    :param num_params: Dimension of the search space.
    """
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):  # no sysconf (Windows): let pycma try
        return
    needed = FULL_COVARIANCE_MATRICES * 8 * num_params**2
    if needed > memory:
        raise MemoryError(
            f"Full-covariance CMA-ES on {num_params} parameters needs about {needed / 2**30:,.1f} GiB "
            f"({FULL_COVARIANCE_MATRICES} matrices of {num_params} x {num_params} float64), more than this machine's "
            f"{memory / 2**30:,.1f} GiB. Use diagonal=True (separable CMA-ES, memory linear in the number of "
            "parameters), or a smaller policy."
        )


class CMAESStrategy(Strategy):
    """
    Covariance Matrix Adaptation ES, delegated to pycma's ``CMAEvolutionStrategy``.

    pycma draws from NumPy's global random state; this wrapper gives it a private state (swapped in
    around every pycma call) so that runs are reproducible and a pickled strategy resumes exactly,
    whatever else uses ``np.random``.

    :param center: Initial mean ``x0``.
    :param sigma: Initial step size ``sigma0``.
    :param population_size: Candidates per generation; ``None`` for pycma's default ``4 + 3 ln(n)``.
    :param diagonal: Separable CMA-ES (diagonal covariance, pycma's ``CMA_diagonal=True``), for large policies.
    :param restarts: ``None``, ``"ipop"`` (population doubles at each restart) or ``"bipop"`` (alternates
        large-population restarts with small-population, small-step ones, Hansen 2009).
    :param max_restarts: Maximum number of restarts (with BIPOP, of large-population ones: as in pycma's ``fmin``,
        the small-population runs between them, each capped at half the evaluations of the large ones so far, do
        not count).
    :param cma_options: Other pycma options, passed through (e.g. ``{"tolfun": 1e-3}``).
    :param seed: Seed of the private random state.
    """

    # pycma's ask() uses up state (TPA's mean-shift samples), so the candidates asked and not told are kept, in a save
    # too, and asked again: a generation cut short (a callback, a mid-generation checkpoint) is run again with the same
    # candidates (their episodes start anew, and the steps already run stay counted).
    pending_attributes = Strategy.pending_attributes

    def __init__(
        self,
        center: np.ndarray,
        sigma: float,
        population_size: int | None = None,
        diagonal: bool = False,
        restarts: Restarts = None,
        max_restarts: int = 9,
        cma_options: dict[str, Any] | None = None,
        seed: int | np.random.SeedSequence | None = None,
    ) -> None:
        super().__init__(center, seed)
        check_positive_number("sigma", sigma)
        if population_size is not None:
            population_size = check_count("population_size", population_size, 2)
        if restarts not in (None, "ipop", "bipop"):
            raise ValueError(f"restarts={restarts!r}: choose None, 'ipop' or 'bipop'.")
        self.sigma0 = float(sigma)
        self.diagonal = check_flag("diagonal", diagonal)  # the CMAES algorithm resolves its "auto"
        self.restarts = restarts
        self.max_restarts = max_restarts
        self.check_settings()
        if not isinstance(cma_options, Mapping | None):
            raise TypeError(
                f"cma_options={cma_options!r}: it must be a dict of pycma options, such as dict(tolfun=1e-3) (in a "
                "YAML file, a mapping: cma_options: {tolfun: 1.0e-3})."
            )
        self.cma_options = dict(cma_options or {})
        for key in ("popsize", "seed", "CMA_diagonal", "randn"):
            if key in self.cma_options:
                raise ValueError(f"cma_options[{key!r}] is set by sb3-es; use the matching CMAES argument instead.")
        for key in REMAPPING_OPTIONS:
            if key in self.cma_options:
                raise ValueError(
                    f"cma_options[{key!r}]: this option makes pycma search a transformed space, whose mean is not the "
                    "policy's parameters, so sb3-es does not take it. Leave it out (the policy normalizes its "
                    "observations; sigma sets the step size of every parameter)."
                )
        self.default_population_size = int(4 + math.floor(3 * math.log(self.num_params)))
        self.base_population_size = population_size or self.default_population_size
        self.n_restarts = 0
        self.last_stop: dict[str, Any] = {}
        self._budget = {"large": 0, "small": 0}
        self._regime = "small"  # the first run counts on the small budget, as in pycma's fmin and Hansen's code
        self._large_restarts = 0
        self._small_restarts = 0
        self._solutions: list[np.ndarray] | None = None  # pycma's own list of the candidates asked
        self._exhausted = False
        self._np_state = self._sampling_state()
        if not diagonal:
            check_full_covariance_memory(self.num_params)
        self.es = self._new_es(self.center, self.sigma0, self.base_population_size)
        self._check_cma_options()
        if self.base_population_size < self.min_population_size:
            raise ValueError(
                f"population_size={self.base_population_size} is too small for CMA-ES on {self.num_params} "
                "parameters: pycma adapts the step size with two-point adaptation (TPA, its default from "
                f"{_import_cma().evolution_strategy.TPA_dimension} parameters), which spends 2 candidates of every "
                "generation on the last mean shift, and it adds a mirrored candidate. Use population_size >= "
                f"{self.min_population_size}, or None for pycma's default ({self.default_population_size})."
            )

    def _check_cma_options(self) -> None:
        """Refuse a string that pycma could not read as the number an option needs: pycma keeps it and fails later."""
        unread = {key: value for key, value in self.cma_options.items() if isinstance(self.es.opts.get(key), str)}
        if not unread:  # the usual case: nothing more to build
            return
        cma = _import_cma()
        defaults = cma.CMAOptions(cma.CMAOptions().defaults())
        names = {"N": self.num_params, "dim": self.num_params, "popsize": self.base_population_size}
        for key, value in unread.items():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:
                    default = defaults.eval(key, loc=names)
                except Exception:  # an option whose default needs more than these names: left to pycma
                    continue
            if isinstance(default, int | float) and not isinstance(default, bool):
                raise ValueError(
                    f"cma_options[{key!r}]={value!r}: pycma cannot read it as a number, which this option needs "
                    f"(pycma's default here: {default!r}); give a number."
                )

    def _sampling_state(self) -> Any:
        """:return: A NumPy random state drawn from ``rng``, for pycma's samples (it draws from NumPy's global one)."""
        return np.random.RandomState(int(self.rng.integers(2**31 - 1))).get_state()

    def reseed(self, seed: int | np.random.SeedSequence) -> None:
        super().reseed(seed)
        self._np_state = self._sampling_state()

    def check_settings(self) -> None:
        self.max_restarts = check_count("max_restarts", self.max_restarts, 0)

    @contextlib.contextmanager
    def _private_random(self) -> Iterator[None]:
        outer = np.random.get_state()
        np.random.set_state(self._np_state)
        try:
            yield
        finally:
            self._np_state = np.random.get_state()
            np.random.set_state(outer)

    def _new_es(
        self, x0: np.ndarray, sigma0: float, popsize: int, maxiter: int | None = None
    ) -> cma.CMAEvolutionStrategy:
        # pycma's default sampler is the bound method ``np.random.randn``, which pickles with a *copy* of the
        # global random state; a module-level function always reads the current (private, swapped-in) state.
        options = {"popsize": popsize, "CMA_diagonal": self.diagonal, "verbose": -9, "randn": _global_randn}
        options.update(self.cma_options)
        maxfevals = self._user_number("maxfevals")
        if maxfevals is not None:  # counted over every run, as in pycma's fmin: what the earlier runs left
            options["maxfevals"] = max(1, int(maxfevals) - sum(self._budget.values()))
        if maxiter is not None:  # a BIPOP small-population run's cap, below the user's own
            user = self._user_number("maxiter")
            options["maxiter"] = maxiter if user is None else min(maxiter, int(user))
        with self._private_random():
            return _import_cma().CMAEvolutionStrategy(x0, sigma0, options)

    def _user_number(self, name: str) -> float | None:
        """:return: The number given for a pycma option in ``cma_options``, or ``None`` (not given, or a pycma
        expression such as ``"100 * N"``, left to pycma)."""
        given = self.cma_options.get(name)
        return parse_number(given) if isinstance(given, str) else given

    @property
    def min_population_size(self) -> int:
        """
        :return: Smallest population pycma can run with these options. It injects candidates into every
            generation: with two-point step-size adaptation (TPA, its default from 300 parameters) 2 along the
            last mean shift, plus a mirrored one, and they must fit in the population.
        """
        return 3 if self.es.mean_shift_samples else 2

    @property
    def population_size(self) -> int:
        """:return: Candidates in the current generation."""
        return int(self.es.popsize)

    @property
    def sigma(self) -> float:
        """:return: Current overall step size."""
        return float(self.es.sigma)

    def _restart_left(self) -> bool:
        # As in pycma's fmin, BIPOP's small-population runs do not count against max_restarts.
        return self.restarts is not None and self.n_restarts - self._small_restarts < self.max_restarts

    def _ask(self) -> np.ndarray:
        if self._exhausted and self._restart_left() and not self.reached_an_end:  # max_restarts was raised since
            self._exhausted = False
            self._restart()
        if self._solutions is None:  # else the generation asked and not told yet, asked again
            with self._private_random():
                self._solutions = self.es.ask()
        return np.asarray(self._solutions, dtype=np.float64)

    def _tell(self, fitness: np.ndarray) -> dict[str, float]:
        assert self._solutions is not None
        with self._private_random():
            self.es.tell(self._solutions, (-fitness).tolist())  # pycma minimizes
        self._solutions = None
        self.center = np.asarray(self.es.mean, dtype=np.float64).copy()
        stats = {"sigma": self.sigma, "population_size": float(self.population_size), "restarts": self.n_restarts}
        self.last_stop = dict(self.es.stop())
        # As in pycma's fmin, reaching ftarget or using up maxfevals ends the search: no restart.
        restart = bool(self.last_stop) and not self.reached_an_end and self._restart_left()
        self._exhausted = bool(self.last_stop) and not restart
        if restart:
            self._restart()
        return stats

    @property
    def reached_an_end(self) -> bool:
        """:return: Whether the last stop was ``ftarget`` or ``maxfevals`` (``cma_options``): no restart follows."""
        return bool(self.last_stop.keys() & FINAL_STOPS)

    @property
    def stopped(self) -> bool:
        """:return: Whether pycma's stop conditions fired and no restart is left to run."""
        return self._exhausted and (self.reached_an_end or not self._restart_left())

    def _restart(self) -> None:
        """Start a new pycma run from the best candidate found, with the population size of the restart scheme."""
        self.n_restarts += 1
        self._budget[self._regime] += int(self.es.countevals)
        base = self.base_population_size
        maxiter: int | None = None
        if self.restarts == "ipop":
            popsize, sigma0, regime = 2 * self.population_size, self.sigma0, "large"
        else:  # BIPOP: run the regime that has used less of the evaluation budget so far
            regime = "large" if self._budget["large"] <= self._budget["small"] else "small"
            if regime == "large":
                self._large_restarts += 1
                popsize, sigma0 = base * 2**self._large_restarts, self.sigma0
            else:
                self._small_restarts += 1
                ratio = 0.5 * 2**self._large_restarts
                popsize = max(self.min_population_size, int(base * ratio ** (self.rng.uniform() ** 2)))
                sigma0 = self.sigma0 * 10 ** (-2 * self.rng.uniform())
                # At most half the evaluations of the large runs so far, as in pycma's fmin: a local search whose
                # stop conditions never fire (noisy returns) cannot use up the training budget.
                maxiter = max(1, int(0.5 * self._budget["large"] / popsize))
        self._regime = regime
        self.es = self._new_es(self.best_params, sigma0, popsize, maxiter)
        self._solutions = None
        self.center = np.asarray(self.es.mean, dtype=np.float64).copy()

    def set_center(self, center: np.ndarray) -> None:
        """A new pycma run from ``center`` with the current step size and population size (the covariance, the
        evolution paths and the stop conditions start afresh)."""
        super().set_center(center)
        self._budget[self._regime] += int(self.es.countevals)  # the interrupted run's evaluations still count
        maxiter = None
        if self._regime == "small" and self.n_restarts:  # a BIPOP small run keeps what is left of its cap
            maxiter = max(1, int(self.es.opts["maxiter"]) - int(self.es.countiter))
        self.es, self._solutions = self._new_es(self.center, self.sigma, self.population_size, maxiter), None
        self._exhausted = False
        self.last_stop = {}

    def __setstate__(self, state: dict[str, Any]) -> None:
        if "_solutions" not in state:  # before version 2, pycma's list was "_asked" (now the base class's own)
            state["_solutions"] = state.pop("_asked", None)
        state.setdefault("_small_restarts", 0)  # saved before small restarts were counted apart
        super().__setstate__(state)
