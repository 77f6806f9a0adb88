"""The strategy layer's shared steps (checked once for every strategy) and the optimizers module (ClipUp)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
import torch as th

from sb3_es.strategies import (
    ARSStrategy,
    ClipUp,
    CMAESStrategy,
    OpenESStrategy,
    PGPEStrategy,
    SimpleESStrategy,
    Strategy,
)
from sb3_es.strategies.noise import SharedNoiseTable
from sb3_es.strategies.optimizers import make_optimizer

STRATEGIES: dict[str, Callable[..., Strategy]] = {
    "ars": lambda center, **kw: ARSStrategy(center, 3, 3, delta_std=0.1, learning_rate=0.05, **kw),
    "openes": lambda center, **kw: OpenESStrategy(center, 6, sigma=0.1, learning_rate=0.05, **kw),
    "cmaes": lambda center, **kw: CMAESStrategy(center, 0.1, population_size=6, **kw),
    "pgpe": lambda center, **kw: PGPEStrategy(center, 6, stdev_init=0.1, center_learning_rate=0.05, **kw),
    "simple_es": lambda center, **kw: SimpleESStrategy(center, 6, sigma=0.1, n_elite=2, **kw),
}


@pytest.mark.parametrize("name", STRATEGIES)
def test_best_candidate_is_tracked_by_every_strategy(name: str) -> None:
    strategy = STRATEGIES[name](np.zeros(4), seed=0)
    assert strategy.best_fitness == -np.inf
    first = np.asarray(strategy.ask()).copy()
    info = strategy.tell(np.array([1.0, 9.0, 3.0, 2.0, 0.0, -1.0]))
    assert strategy.best_fitness == info["best_fitness"] == 9.0
    np.testing.assert_array_equal(strategy.best_params, first[1])
    strategy.ask()
    strategy.tell(np.array([4.0, 0.0, 5.0, 1.0, 2.0, 3.0]))  # worse: the best stays
    assert strategy.best_fitness == 9.0
    np.testing.assert_array_equal(strategy.best_params, first[1])


@pytest.mark.parametrize("name", STRATEGIES)
def test_tell_checks_the_fitness_before_changing_anything(name: str) -> None:
    strategy = STRATEGIES[name](np.ones(4), seed=0)
    with pytest.raises(RuntimeError, match=r"none is pending \(ask\(\) not called yet, or .* already told\)"):
        strategy.tell(np.zeros(6))
    strategy.ask()
    center = strategy.center.copy()
    with pytest.raises(ValueError, match="Expected 6 fitness values"):
        strategy.tell(np.zeros(5))
    with pytest.raises(ValueError, match=r"candidate\(s\) \[2\]"):
        strategy.tell(np.array([0.0, 1.0, np.nan, 0.0, 0.0, 0.0]))
    np.testing.assert_array_equal(strategy.center, center)
    assert strategy.best_fitness == -np.inf
    strategy.tell(np.arange(6.0))  # the asked population is still there
    assert not np.array_equal(strategy.center, center)
    with pytest.raises(RuntimeError, match="already told"):  # it said "called before ask()"
        strategy.tell(np.arange(6.0))


@pytest.mark.parametrize("name", STRATEGIES)
@pytest.mark.parametrize(
    ("center", "match"),
    [
        (np.zeros((2, 3)), r"1-D array of parameters, got shape \(2, 3\)"),
        (np.zeros(0), r"non-empty 1-D array of parameters, got shape \(0,\)"),
        (np.array([0.0, np.nan, 1.0]), r"entries \[1\] are NaN or infinite"),
    ],
    ids=["2-D", "empty", "nan"],
)
def test_a_bad_center_is_refused_by_name(name: str, center: np.ndarray, match: str) -> None:
    # a 2-D center failed later with a broadcast error, an empty one was accepted, and a NaN one was blamed on the
    # environment's rewards at the first tell()
    with pytest.raises(ValueError, match=match):
        STRATEGIES[name](center, seed=0)
    strategy = STRATEGIES[name](np.zeros(3), seed=0)
    with pytest.raises(ValueError, match=match):
        strategy.set_center(center)
    np.testing.assert_array_equal(strategy.center, 0.0)


@pytest.mark.parametrize(
    ("make", "name"),
    [
        (lambda **kw: ARSStrategy(np.zeros(3), 3, 3, **{"delta_std": 0.1, "learning_rate": 0.1, **kw}), "delta_std"),
        (
            lambda **kw: ARSStrategy(np.zeros(3), 3, 3, **{"delta_std": 0.1, "learning_rate": 0.1, **kw}),
            "learning_rate",
        ),
        (lambda **kw: OpenESStrategy(np.zeros(3), 6, **{"sigma": 0.1, "learning_rate": 0.05, **kw}), "sigma"),
        (lambda **kw: SimpleESStrategy(np.zeros(3), 6, **{"sigma": 0.1, **kw}), "sigma"),
    ],
    ids=["ars-delta_std", "ars-learning_rate", "openes-sigma", "simple_es-sigma"],
)
@pytest.mark.parametrize(
    ("value", "match"),
    [
        ("0.05", r"a number \(a string; a YAML"),
        (None, "a number"),
        (lambda progress: 0.1, r"a number \(\w+ takes no schedule"),
    ],
    ids=["string", "None", "schedule"],
)
def test_a_step_size_that_is_no_number_is_refused_by_name(
    make: Callable[..., Strategy], name: str, value: object, match: str
) -> None:
    # the strategies converted it with float(): a string was accepted, None or a function failed without the name
    with pytest.raises(TypeError, match=rf"^{name}=.*it must be {match}"):
        make(**{name: value})


def test_simple_es_weights_follow_a_new_n_elite() -> None:
    # check_settings() (run when load() changes a setting) accepted a new n_elite and kept the old weights: the next
    # tell() failed in a matrix product; a bad weights name passed
    strategy = SimpleESStrategy(np.zeros(3), 6, sigma=0.1, n_elite=2, seed=0)
    strategy.n_elite = 4
    strategy.check_settings()
    assert strategy.elite_weights.shape == (4,) and strategy.elite_weights.sum() == pytest.approx(1.0)
    strategy.ask()
    strategy.tell(np.arange(6.0))
    strategy.weights = "bogus"  # type: ignore[assignment]
    with pytest.raises(ValueError, match="weights='bogus'"):
        strategy.check_settings()


def test_best_params_of_a_noise_table_population_are_its_row() -> None:
    table = SharedNoiseTable(10_000, seed=1)
    strategy = OpenESStrategy(np.arange(4.0), 6, sigma=0.3, learning_rate=0.05, noise_table=table, seed=0)
    population = strategy.ask()
    dense = np.asarray(population).copy()
    strategy.tell(np.array([0.0, 1.0, 2.0, 7.0, 3.0, 4.0]))
    np.testing.assert_array_equal(strategy.best_params, dense[3])


#: Every strategy (a key of :data:`STRATEGIES`): a new one from 0 in 5 dimensions, the generations it runs on
#: -||x - 1||^2, and the distance to the optimum (sqrt(5) = 2.2 at the start) and the best fitness it must reach,
#: as precise as each gets (CMA-ES's adapted step size homes in; the others keep a step or noise scale).
CONVERGENCE: dict[str, tuple[Callable[[], Strategy], int, float, float]] = {
    "ars": (lambda: ARSStrategy(np.zeros(5), 8, 4, delta_std=0.02, learning_rate=0.02, seed=0), 100, 0.1, -0.01),
    "openes": (lambda: OpenESStrategy(np.zeros(5), 20, sigma=0.1, learning_rate=0.05, seed=0), 150, 0.05, -0.01),
    "cmaes": (lambda: CMAESStrategy(np.zeros(5), sigma=0.5, seed=0), 150, 1e-4, -1e-8),
    "pgpe": (  # ClipUp's steps bring the center within a few max_speed
        lambda: PGPEStrategy(np.zeros(5), 20, stdev_init=0.5, center_learning_rate=0.025, max_speed=0.05, seed=0),
        300,
        0.15,
        -0.01,
    ),
    "simple_es": (lambda: SimpleESStrategy(np.zeros(5), 20, sigma=0.05, n_elite=5, seed=0), 100, 0.1, -0.01),
}


@pytest.mark.parametrize("name", STRATEGIES)
def test_strategy_alone_converges(name: str) -> None:
    """Ask/tell on a pure function, no env, until the strategy stops or the generations run out."""
    make, generations, distance, best_fitness = CONVERGENCE[name]
    strategy = make()
    for _ in range(generations):
        population = np.asarray(strategy.ask())
        strategy.tell(-np.sum((population - 1.0) ** 2, axis=1))
        if getattr(strategy, "stopped", False):
            break
    assert np.linalg.norm(strategy.center - 1.0) < distance
    assert strategy.best_fitness > best_fitness


# ---------------------------------------------------------------------------- ClipUp
def clipup_steps(grads: list[np.ndarray], lr: float, max_speed: float, momentum: float = 0.9) -> list[np.ndarray]:
    """Positions after each ClipUp step from 0 (the optimizer minimizes: it moves against the gradient)."""
    theta = th.nn.Parameter(th.zeros(len(grads[0]), dtype=th.float64))
    optimizer = ClipUp([theta], lr=lr, max_speed=max_speed, momentum=momentum)
    positions = []
    for grad in grads:
        theta.grad = th.as_tensor(grad, dtype=th.float64)
        optimizer.step()
        positions.append(theta.detach().numpy().copy())
    return positions


def test_clipup_steps_along_the_normalized_gradient_with_momentum() -> None:
    g1, g2 = np.array([3.0, 4.0]), np.array([0.0, -10.0])
    first, second = clipup_steps([g1, g2], lr=0.1, max_speed=1.0)
    v1 = 0.1 * g1 / 5.0  # the step length does not depend on the gradient's scale
    np.testing.assert_allclose(first, -v1, rtol=1e-12)
    v2 = 0.9 * v1 + 0.1 * g2 / 10.0
    np.testing.assert_allclose(second, -v1 - v2, rtol=1e-12)
    # Scaling the gradients changes nothing.
    np.testing.assert_allclose(clipup_steps([1e6 * g1, 1e-6 * g2], lr=0.1, max_speed=1.0)[1], second, rtol=1e-12)


def test_clipup_caps_the_speed() -> None:
    grad = np.array([1.0, 2.0, 2.0])
    positions = clipup_steps([grad] * 30, lr=0.1, max_speed=0.25)
    steps = np.diff(np.vstack([np.zeros(3), *positions]), axis=0)
    speeds = np.linalg.norm(steps, axis=1)
    assert np.all(speeds <= 0.25 + 1e-12)
    # Momentum builds the velocity up to lr / (1 - momentum) = 1.0, so the cap is reached and held.
    np.testing.assert_allclose(speeds[-10:], 0.25, rtol=1e-12)
    assert speeds[0] == pytest.approx(0.1)


def test_clipup_zero_gradient_keeps_coasting() -> None:
    first, second = clipup_steps([np.array([0.0, 2.0]), np.zeros(2)], lr=0.1, max_speed=1.0)
    np.testing.assert_allclose(second - first, 0.9 * first, rtol=1e-12)


def test_clipup_default_max_speed_is_twice_the_learning_rate() -> None:
    theta = th.nn.Parameter(th.zeros(2, dtype=th.float64))
    assert ClipUp([theta], lr=0.15).param_groups[0]["max_speed"] == pytest.approx(0.3)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [(dict(lr=0.0), "lr"), (dict(lr=0.1, max_speed=-1.0), "max_speed"), (dict(lr=0.1, momentum=1.0), "momentum")],
)
def test_clipup_rejects_bad_settings(kwargs: dict, match: str) -> None:
    theta = th.nn.Parameter(th.zeros(2, dtype=th.float64))
    with pytest.raises(ValueError, match=match):
        ClipUp([theta], **kwargs)


@pytest.mark.parametrize(
    ("name", "kwargs", "match"),
    [
        ("pgpe", dict(stdev_learning_rate=np.inf), r"stdev_learning_rate=inf: it must be a finite number"),
        ("cmaes", dict(diagonal="auto"), r"diagonal='auto': it must be True or False"),
    ],
)
def test_strategy_settings_errors_name_the_setting(name: str, kwargs: dict, match: str) -> None:
    with pytest.raises((ValueError, TypeError), match=match):
        STRATEGIES[name](np.zeros(3), **kwargs)


def test_errors_of_settings_given_positionally_say_what_is_wrong() -> None:
    with pytest.raises(
        ValueError, match=r"center_learning_rate=-1.0: it must be a positive number"
    ):  # not learning_rate
        PGPEStrategy(np.zeros(3), 6, stdev_init=0.1, center_learning_rate=-1.0)
    with pytest.raises(ValueError, match=r"n_top='2': it must be a whole number"):  # not "between 1 and n_delta"
        ARSStrategy(np.zeros(3), 4, "2", delta_std=0.1, learning_rate=0.05)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"size=1.9: the noise table needs a whole, positive number"):
        SharedNoiseTable(1.9)  # type: ignore[arg-type]


@pytest.mark.parametrize("name", ["ars", "openes"])
def test_a_learning_rate_scheduled_down_to_0_passes_the_settings_check(name: str) -> None:
    """A learning-rate schedule may end at 0 (written into the strategy); load() checks the settings again."""
    strategy = STRATEGIES[name](np.zeros(3))
    strategy.learning_rate = 0.0  # type: ignore[attr-defined]
    strategy.check_settings()
    strategy.learning_rate = -0.1  # type: ignore[attr-defined]
    with pytest.raises(ValueError, match="learning_rate=-0.1"):
        strategy.check_settings()


def test_make_optimizer_names() -> None:
    theta = th.nn.Parameter(th.zeros(2, dtype=th.float64))
    assert isinstance(make_optimizer("adam", [theta], 0.1), th.optim.Adam)
    assert isinstance(make_optimizer("sgd", [theta], 0.1), th.optim.SGD)
    assert isinstance(make_optimizer("clipup", [theta], 0.1, max_speed=0.3), ClipUp)
    with pytest.raises(ValueError, match="optimizer='rmsprop'"):
        make_optimizer("rmsprop", [theta], 0.1)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="max_speed"):
        make_optimizer("adam", [theta], 0.1, max_speed=0.3)


def test_an_infinite_step_size_is_refused_as_not_finite() -> None:
    with pytest.raises(ValueError, match=r"^sigma=inf: it must be a positive number \(a finite one\)\.$"):
        OpenESStrategy(np.zeros(3), 6, sigma=np.inf, learning_rate=0.05)
