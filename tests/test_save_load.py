"""Saving, loading, parameters and exact resumption of ARS runs."""

from __future__ import annotations

import base64
import io
import json
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.save_util import load_from_zip_file
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_es import ARS

GENERATION = 2 * 2 * 200  # Pendulum-v1, n_delta=2, one env: 4 candidates x 200 steps


def pendulum_env() -> DummyVecEnv:
    return make_vec_env("Pendulum-v1", n_envs=1)


def trained_model(steps: int = GENERATION, **kwargs) -> ARS:
    model = ARS("LinearPolicy", pendulum_env(), n_delta=2, seed=0, **kwargs)
    model.learn(steps)
    return model


def random_obs(n: int = 16) -> np.ndarray:
    rng = np.random.default_rng(0)
    theta = rng.uniform(-np.pi, np.pi, n)
    return np.stack([np.cos(theta), np.sin(theta), rng.uniform(-8, 8, n)], axis=1).astype(np.float32)


def assert_same_policy(a: ARS, b: ARS) -> None:
    np.testing.assert_array_equal(a.policy.parameters_to_vector(), b.policy.parameters_to_vector())
    for name in ("obs_mean", "obs_var", "obs_count"):
        np.testing.assert_array_equal(getattr(a.policy, name).numpy(), getattr(b.policy, name).numpy())


# ---------------------------------------------------------------------------- round trip
@pytest.mark.parametrize("policy", ["LinearPolicy", "MlpPolicy"])
def test_save_load_round_trip(tmp_path: Path, policy: str) -> None:
    model = ARS(
        policy, pendulum_env(), n_delta=2, seed=0, policy_kwargs=dict(net_arch=[8]) if policy == "MlpPolicy" else None
    )
    model.learn(GENERATION)
    # The obs statistics must be non-trivial for this test to check that they are saved.
    assert model.policy.obs_count.item() > 1
    model.save(tmp_path / "model.zip")
    loaded = ARS.load(tmp_path / "model.zip")

    assert type(loaded.policy) is type(model.policy)
    assert_same_policy(model, loaded)
    obs = random_obs()
    np.testing.assert_array_equal(loaded.predict(obs)[0], model.predict(obs)[0])
    np.testing.assert_array_equal(loaded.predict(obs[0])[0], model.predict(obs[0])[0])
    # Hyperparameters and the strategy state come back too.
    assert (loaded.n_delta, loaded.n_top, loaded.delta_std) == (2, 2, 0.05)
    assert loaded.num_timesteps == model.num_timesteps
    np.testing.assert_array_equal(loaded.strategy.center, model.strategy.center)
    np.testing.assert_array_equal(loaded.strategy.ask(), model.strategy.ask())


def test_save_load_file_object() -> None:
    model = trained_model()
    buffer = io.BytesIO()
    model.save(buffer)
    buffer.seek(0)
    loaded = ARS.load(buffer)
    assert_same_policy(model, loaded)
    obs = random_obs()
    np.testing.assert_array_equal(loaded.predict(obs)[0], model.predict(obs)[0])


@pytest.mark.parametrize("reset_num_timesteps", [True, False])
def test_loaded_model_needs_env_to_learn(tmp_path: Path, reset_num_timesteps: bool) -> None:
    trained_model().save(tmp_path / "model.zip")
    loaded = ARS.load(tmp_path / "model.zip")
    with pytest.raises(ValueError, match="env"):
        loaded.learn(GENERATION, reset_num_timesteps=reset_num_timesteps)


# ---------------------------------------------------------------------------- parameters
def test_get_set_parameters_moves_strategy_center(tmp_path: Path) -> None:
    source = trained_model(2 * GENERATION)
    target = ARS("LinearPolicy", pendulum_env(), n_delta=2, seed=1)
    params = source.get_parameters()
    assert set(params) == {"policy"}
    target.set_parameters(params)
    assert_same_policy(source, target)
    obs = random_obs()
    np.testing.assert_array_equal(target.predict(obs)[0], source.predict(obs)[0])
    weights = source.policy.parameters_to_vector()
    np.testing.assert_array_equal(target.strategy.center.astype(np.float32), weights.astype(np.float32))

    # The next learn() starts from the set weights: its candidates are center +/- perturbations.
    asked = []
    ask = target.strategy.ask

    def spy() -> np.ndarray:
        population = ask()
        asked.append(population)
        return population

    target.strategy.ask = spy  # type: ignore[method-assign]
    target.learn(GENERATION)
    population = asked[0]
    np.testing.assert_allclose((population[:2] + population[2:]) / 2, np.tile(weights, (2, 1)), atol=1e-6)


def test_set_parameters_from_file(tmp_path: Path) -> None:
    source = trained_model()
    source.save(tmp_path / "source.zip")
    target = ARS("LinearPolicy", pendulum_env(), n_delta=2, seed=1)
    target.set_parameters(str(tmp_path / "source.zip"))
    assert_same_policy(source, target)
    np.testing.assert_array_equal(
        target.strategy.center.astype(np.float32), source.policy.parameters_to_vector().astype(np.float32)
    )


def test_get_parameters_is_a_copy_of_the_policy_state() -> None:
    model = trained_model()
    state = model.get_parameters()["policy"]
    assert {"obs_mean", "obs_var", "obs_count"} <= set(state)
    np.testing.assert_array_equal(state["obs_mean"].numpy(), model.policy.obs_mean.numpy())


# ---------------------------------------------------------------------------- exact resumption
@pytest.mark.parametrize("n", [GENERATION, 2 * GENERATION])
def test_resume_is_identical_to_an_uninterrupted_run(tmp_path: Path, n: int) -> None:
    straight = ARS("LinearPolicy", pendulum_env(), n_delta=2, seed=3)
    straight.learn(2 * n)

    first = ARS("LinearPolicy", pendulum_env(), n_delta=2, seed=3)
    first.learn(n)
    first.save(tmp_path / "half.zip")
    resumed = ARS.load(tmp_path / "half.zip", env=pendulum_env())
    resumed.learn(n, reset_num_timesteps=False)

    assert resumed.num_timesteps == straight.num_timesteps == 2 * n
    assert resumed._n_updates == straight._n_updates
    assert_same_policy(straight, resumed)
    np.testing.assert_array_equal(straight.strategy.center, resumed.strategy.center)
    # Sanity: training did move the parameters, so equality is not trivial.
    assert not np.array_equal(first.policy.parameters_to_vector(), straight.policy.parameters_to_vector())


def test_resume_mlp_matches_in_memory_continuation(tmp_path: Path) -> None:
    """Same identity for an MLP, and the in-memory model continuing gives the same result as the loaded one."""
    kwargs = dict(n_delta=2, seed=4, policy_kwargs=dict(net_arch=[8]))
    first = ARS("MlpPolicy", pendulum_env(), **kwargs)
    first.learn(GENERATION)
    first.save(tmp_path / "m.zip")
    first.learn(GENERATION, reset_num_timesteps=False)
    resumed = ARS.load(tmp_path / "m.zip", env=pendulum_env())
    resumed.learn(GENERATION, reset_num_timesteps=False)
    assert_same_policy(first, resumed)


# ---------------------------------------------------------------------------- bad files
def test_load_random_bytes(tmp_path: Path) -> None:
    path = tmp_path / "random.zip"
    path.write_bytes(np.random.default_rng(0).bytes(4096))
    with pytest.raises(ValueError, match="corrupt"):
        ARS.load(path)


def test_load_truncated_zip(tmp_path: Path) -> None:
    trained_model().save(tmp_path / "model.zip")
    raw = (tmp_path / "model.zip").read_bytes()
    path = tmp_path / "truncated.zip"
    path.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(ValueError, match="corrupt"):
        ARS.load(path)


def test_load_missing_file(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        ARS.load(tmp_path / "nothing_here.zip")


def rewrite_member(src: Path, dst: Path, member: str, mutate: Callable[[bytes], bytes | None]) -> None:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for name in zin.namelist():
            content = zin.read(name)
            if name == member:
                content = mutate(content)
                if content is None:
                    continue
            zout.writestr(name, content)


def drop_strategy(data: bytes) -> bytes:
    decoded = json.loads(data)
    del decoded["strategy"]
    return json.dumps(decoded).encode()


def test_load_save_without_strategy_state(tmp_path: Path) -> None:
    trained_model().save(tmp_path / "model.zip")
    rewrite_member(tmp_path / "model.zip", tmp_path / "damaged.zip", "data", drop_strategy)
    with pytest.raises(ValueError, match="strategy"):
        ARS.load(tmp_path / "damaged.zip")


def test_load_save_without_policy(tmp_path: Path) -> None:
    trained_model().save(tmp_path / "model.zip")
    rewrite_member(tmp_path / "model.zip", tmp_path / "damaged.zip", "policy.pth", lambda _: None)
    with pytest.raises(ValueError, match="policy"):
        ARS.load(tmp_path / "damaged.zip")


def garble_policy_weights(content: bytes) -> bytes:
    return np.random.default_rng(0).bytes(len(content))


def truncate_strategy_pickle(content: bytes) -> bytes:
    decoded = json.loads(content)
    serialized = decoded["strategy"][":serialized:"]
    # Keep valid base64 (a multiple of 4 characters) so that the pickle itself is what is truncated.
    decoded["strategy"][":serialized:"] = serialized[: len(serialized) // 8 * 4]
    return json.dumps(decoded).encode()


def garble_strategy_pickle(content: bytes) -> bytes:
    decoded = json.loads(content)
    decoded["strategy"][":serialized:"] = base64.b64encode(np.random.default_rng(0).bytes(300)).decode()
    return json.dumps(decoded).encode()


@pytest.mark.parametrize(
    ("member", "mutate"),
    [
        ("policy.pth", garble_policy_weights),
        ("data", truncate_strategy_pickle),
        ("data", garble_strategy_pickle),
    ],
)
def test_load_zip_with_corrupt_member(tmp_path: Path, member: str, mutate: Callable[[bytes], bytes]) -> None:
    trained_model().save(tmp_path / "model.zip")
    rewrite_member(tmp_path / "model.zip", tmp_path / "damaged.zip", member, mutate)
    with pytest.raises(ValueError, match="corrupt"):
        ARS.load(tmp_path / "damaged.zip")


@pytest.fixture(scope="module")
def ppo_save(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("ppo") / "ppo.zip"
    PPO("MlpPolicy", "Pendulum-v1", n_steps=64, batch_size=64, seed=0).save(path)
    return path


def test_load_ppo_save_is_rejected(ppo_save: Path) -> None:
    with pytest.raises(ValueError, match=r"ARS\.load"):
        ARS.load(ppo_save)


def test_load_ppo_save_names_the_algorithm(ppo_save: Path) -> None:
    with pytest.raises(ValueError, match="PPO"):
        ARS.load(ppo_save)


def test_load_sb3_contrib_ars_save_is_rejected(tmp_path: Path) -> None:
    sb3_contrib = pytest.importorskip("sb3_contrib")
    path = tmp_path / "contrib_ars.zip"
    sb3_contrib.ARS("LinearPolicy", "Pendulum-v1", seed=0).save(path)
    with pytest.raises(ValueError, match="sb3_contrib"):
        ARS.load(path)


@pytest.mark.parametrize("other", ["OpenES", "CMAES"])
def test_load_ars_save_with_another_sb3_es_algorithm(tmp_path: Path, other: str) -> None:
    import sb3_es

    trained_model().save(tmp_path / "ars.zip")
    with pytest.raises(ValueError, match=r"saved by sb3-es ARS.*ARS\.load\(\)"):
        getattr(sb3_es, other).load(tmp_path / "ars.zip")


# ---------------------------------------------------------------------------- files from older versions
LEGACY_DIR = Path(__file__).resolve().parent / "data" / "legacy"


@pytest.mark.parametrize("name", ["ars", "openes", "cmaes"])
def test_files_saved_before_strategy_state_version_2_load_and_continue(name: str) -> None:
    """Saves written at fcb4e90 (the algorithm then set and decayed the strategy's step sizes every generation).

    They load, the strategy gets the hyperparameters the algorithm had (OpenES: sigma 0.1 x 0.8 and learning
    rate 0.05 x 0.9 after the one saved generation), and one more generation continues the run that the old
    code ran on (tests/data/legacy/make_legacy.py).
    """
    import sb3_es

    algo = {"ars": sb3_es.ARS, "openes": sb3_es.OpenES, "cmaes": sb3_es.CMAES}[name]
    data, _, _ = load_from_zip_file(LEGACY_DIR / f"{name}.zip")
    assert data is not None and data["strategy"].restored_legacy_state
    model = algo.load(LEGACY_DIR / f"{name}.zip", env=pendulum_env())
    assert not model.strategy.restored_legacy_state  # upgraded on load
    assert model.strategy.best_fitness == -np.inf or np.isfinite(model.strategy.best_fitness)
    if name == "openes":
        assert model.strategy.sigma == pytest.approx(0.08)
        assert model.strategy.learning_rate == pytest.approx(0.045)
        assert (model.strategy.sigma_decay, model.strategy.learning_rate_decay) == (0.8, 0.9)
    if name == "ars":
        assert (model.strategy.delta_std, model.strategy.learning_rate) == (0.05, 0.02)
    model.learn(1, reset_num_timesteps=False)
    assert model._n_updates == 2
    np.testing.assert_allclose(
        model.policy.parameters_to_vector(), np.load(LEGACY_DIR / f"{name}_next.npy"), rtol=1e-6, atol=1e-9
    )
    # It saves again in today's format.
    buffer = io.BytesIO()
    model.save(buffer)
    buffer.seek(0)
    data, _, _ = load_from_zip_file(buffer)
    assert data is not None and data["strategy"].state_version == 2
