"""What is the worker processes' own: evaluator="processes" from an env id or a VecEnv, reproducibility for a seed
and a worker count, the SubprocVecEnv hint, and no process left behind (Ctrl-C, normal exit, garbage collection).

Their behaviour as a host of the sharded evaluator (same results as locally, callbacks, faults) is tested with Ray's
in ``test_sharded.py``."""

from __future__ import annotations

import functools
import gc
import math
import multiprocessing
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from envs import ToyEnv
from gymnasium.wrappers import ClipReward, TransformReward
from sb3_contrib.common.wrappers import TimeFeatureWrapper
from sharded_helpers import gone, toy_policy, toy_population, wait_gone
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.monitor import load_results
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

from sb3_es import ARS
from sb3_es.common.policies import MlpPolicy
from sb3_es.evaluation import VecEnvEvaluator, processes, sharded
from sb3_es.evaluation.processes import ProcessEvaluator, usable_cpus
from sb3_es.evaluation.worker import DEFAULT_ENVS_PER_WORKER

REPO = Path(__file__).resolve().parent.parent


def test_evaluator_processes_from_env_id() -> None:
    model = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, seed=0, evaluator="processes")
    model.learn(1)
    evaluator = model._evaluator
    assert isinstance(evaluator, ProcessEvaluator)
    assert evaluator.env == "Pendulum-v1" and evaluator.num_workers == usable_cpus()
    assert model._n_updates == 1 and model.num_timesteps >= 4 * 200
    pids = [process.pid for process in evaluator._workers]
    assert len(pids) == usable_cpus()
    del model, evaluator
    gc.collect()  # an evaluator no longer used stops its workers
    assert wait_gone(pids)


def test_a_loop_over_seeds_stops_each_dropped_models_workers() -> None:
    """The seed loop of the docs: each model dropped (kept until the garbage collector runs, by a reference cycle) has
    its workers stopped when the next model starts its own, by the process that started them, never by a forked
    worker that inherited a copy of it ("can only test a child process")."""
    script = (
        "import multiprocessing as mp\n"
        "from sb3_es import ARS\n"
        "for seed in range(3):\n"
        "    model = ARS('LinearPolicy', 'Pendulum-v1', n_delta=2, seed=seed, evaluator='processes')\n"
        "    model.learn(1)\n"
        "    print(len(mp.active_children()), flush=True)\n"
    )
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == [str(usable_cpus())] * 3
    assert "Exception ignored" not in result.stderr and "AssertionError" not in result.stderr


def test_one_worker_is_the_local_engine() -> None:
    """One worker with the default env slots runs the local engine on a VecEnv of that many envs, bit for bit."""
    local = ARS("LinearPolicy", make_vec_env("Pendulum-v1", n_envs=DEFAULT_ENVS_PER_WORKER), n_delta=2, seed=3)
    with ProcessEvaluator("Pendulum-v1", num_workers=1) as evaluator:
        remote = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, seed=3, evaluator=evaluator)
        for model in (local, remote):
            model.learn(1)
            model.learn(1, reset_num_timesteps=False)
    assert remote.num_timesteps == local.num_timesteps == 2 * 4 * 200
    np.testing.assert_array_equal(remote.strategy.center, local.strategy.center)


def test_default_env_slots_are_seeded_as_one_vec_env() -> None:
    """
    The documented default, 4 env slots per worker: worker ``k`` seeds its slots with ``seed + 4 * k``, so two
    workers run 8 candidates (one per slot) exactly as a local VecEnv of 8 envs does (Pendulum's random starts
    depend on the seed: a worker with one slot would run its 4 candidates one after the other from other starts).
    """
    assert DEFAULT_ENVS_PER_WORKER == 4
    env = make_vec_env("Pendulum-v1", n_envs=2 * DEFAULT_ENVS_PER_WORKER)
    policy = MlpPolicy(env.observation_space, env.action_space, net_arch=[8])
    population = np.random.default_rng(0).normal(scale=0.5, size=(8, policy.num_params))
    center = population.mean(axis=0)
    local = VecEnvEvaluator(env).evaluate(policy, population, center, 1, seed=11)
    with ProcessEvaluator("Pendulum-v1", num_workers=2, linger=False) as evaluator:
        assert evaluator.envs_per_worker == DEFAULT_ENVS_PER_WORKER
        remote = evaluator.evaluate(policy, population, center, 1, seed=11)
    np.testing.assert_array_equal(remote.returns, local.returns)
    assert remote.n_steps == local.n_steps == 8 * 200


@pytest.mark.parametrize("env_id", ["Pendulum-v1", "CartPole-v1"])
def test_reproducible_for_a_seed_and_worker_count(env_id: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """
    The headline's settings with evaluator="processes" (one worker per CPU; two CPUs here): a seed and a worker count
    give the same parameters whatever the timing (CartPole's episode lengths vary, so the workers linger for
    different times); with linger=False the step counts are the same too.
    """
    monkeypatch.setattr(processes, "usable_cpus", lambda: 2)

    def run(evaluator: str | ProcessEvaluator) -> ARS:
        model = ARS("MlpPolicy", env_id, n_delta=4, seed=5, evaluator=evaluator)
        try:
            model.learn(1)
            model.learn(1, reset_num_timesteps=False)
        finally:
            model._evaluator.close()  # type: ignore[union-attr]
        assert model._n_updates == 2
        return model

    lingering = [run("processes") for _ in range(2)]
    assert lingering[0]._evaluator.num_workers == 2  # type: ignore[union-attr]
    strict = [run(ProcessEvaluator(env_id, num_workers=2, linger=False)) for _ in range(2)]
    for model in (lingering[1], *strict):
        np.testing.assert_array_equal(model.strategy.center, lingering[0].strategy.center)
        np.testing.assert_allclose(model.policy.obs_mean.numpy(), lingering[0].policy.obs_mean.numpy(), rtol=1e-12)
    assert strict[0].num_timesteps == strict[1].num_timesteps
    # Two workers are not one: the shares' seeds differ from a single VecEnv's.
    one = run(ProcessEvaluator(env_id, num_workers=1))
    assert not np.array_equal(one.strategy.center, lingering[0].strategy.center)


def test_evaluator_processes_from_a_vec_env(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """
    Given a VecEnv (as rl-zoo builds it), evaluator="processes" rebuilds its envs in the workers from their specs:
    env kwargs and the wrappers outside Monitor reach the workers (same run as the explicit evaluator), the workers'
    episodes reach the model env's Monitor file, and what cannot be rebuilt is refused by name.
    """
    monkeypatch.setattr(processes, "usable_cpus", lambda: 2)
    clip = dict(wrapper_class=ClipReward, wrapper_kwargs={"min_reward": -1.0})

    def run(env: object, evaluator: str | ProcessEvaluator) -> ARS:
        model = ARS("LinearPolicy", env, n_delta=2, seed=5, evaluator=evaluator)  # type: ignore[arg-type]
        try:
            model.learn(1)
        finally:
            model._evaluator.close()  # type: ignore[union-attr]
        return model

    vec_env = make_vec_env("Pendulum-v1", n_envs=2, env_kwargs={"g": 9.0}, monitor_dir=str(tmp_path), **clip)
    from_vec_env = run(vec_env, "processes")
    vec_env.close()
    episodes = load_results(str(tmp_path))
    assert len(episodes) == 4 and (episodes["l"] == 200).all()  # 2 * n_delta candidates, one episode each
    evaluator = from_vec_env._evaluator
    assert isinstance(evaluator, ProcessEvaluator) and evaluator.num_workers == 2
    explicit = run("Pendulum-v1", ProcessEvaluator("Pendulum-v1", num_workers=2, env_kwargs={"g": 9.0}, **clip))
    np.testing.assert_array_equal(from_vec_env.strategy.center, explicit.strategy.center)
    plain = run(make_vec_env("Pendulum-v1", n_envs=2), "processes")
    assert not np.array_equal(plain.strategy.center, explicit.strategy.center)

    normalize_fix = "VecNormalize, which the workers cannot apply.*with rl-zoo, remove normalize .* normalize:False"
    with pytest.raises(ValueError, match=normalize_fix):
        ARS("LinearPolicy", VecNormalize(make_vec_env("Pendulum-v1")), evaluator="processes")
    with pytest.raises(ValueError, match="wrapper.*TimeFeatureWrapper do not record their constructor arguments"):
        ARS("LinearPolicy", make_vec_env("Pendulum-v1", wrapper_class=TimeFeatureWrapper), evaluator="processes")
    with pytest.raises(ValueError, match="not built by gym.make .*: give a registered env id instead, or pass"):
        ARS("LinearPolicy", ToyEnv(), evaluator="processes")


def test_workers_episodes_cut_at_max_episode_steps_reach_the_monitor_file(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """The workers' Monitors end the episodes cut at max_episode_steps and report the model Monitor's
    info_keywords, so the model's Monitor file gets those rows with every column."""
    monkeypatch.setattr(processes, "usable_cpus", lambda: 2)
    monitor_kwargs = dict(info_keywords=("TimeLimit.truncated",))
    vec_env = make_vec_env("Pendulum-v1", n_envs=2, monitor_dir=str(tmp_path), monitor_kwargs=monitor_kwargs)
    model = ARS("LinearPolicy", vec_env, n_delta=2, seed=5, evaluator="processes", max_episode_steps=50)
    try:
        model.learn(1)
    finally:
        model._evaluator.close()  # type: ignore[union-attr]
    vec_env.close()
    episodes = load_results(str(tmp_path))
    assert len(episodes) == 4 and (episodes["l"] == 50).all() and episodes["t"].notna().all()
    assert episodes["TimeLimit.truncated"].eq(True).all()


def test_workers_episodes_are_timed_from_the_model_monitors_start(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """The rows that the workers' episodes add to the model's Monitor file have their time ``t`` measured from that
    Monitor's start, as the model's own episodes would: not from the workers' start (at ``learn()``, and again for
    fresh workers)."""
    monkeypatch.setattr(processes, "usable_cpus", lambda: 2)
    vec_env = make_vec_env("Pendulum-v1", n_envs=2, monitor_dir=str(tmp_path))
    model = ARS("LinearPolicy", vec_env, n_delta=2, seed=5, evaluator="processes")
    start = vec_env.get_attr("t_start", indices=[0])[0]
    time.sleep(1.0)
    try:
        for pause in (0.0, 0.5):
            time.sleep(pause)
            model.learn(1, reset_num_timesteps=False)
            evaluator = model._evaluator
            assert isinstance(evaluator, ProcessEvaluator)
            assert evaluator.call_workers(lambda env: set(env.get_attr("t_start"))) == [{start}, {start}]
            evaluator.close()  # the next generation starts fresh workers
    finally:
        model._evaluator.close()  # type: ignore[union-attr]
    vec_env.close()
    t = load_results(str(tmp_path))["t"].to_numpy()  # sorted by t
    assert len(t) == 8 and (t[:4] >= 1.0).all() and (t[4:] >= t[3] + 0.5).all()


def _pendulum(g: float) -> gym.Env:
    return gym.make("Pendulum-v1", g=g)


def test_evaluator_processes_from_envs_registered_with_a_partial() -> None:
    """
    Envs registered with a ``functools.partial`` entry point (as shimmy registers ``dm_control/...``) are rebuilt in
    the workers: ``gym.make`` copies the partial into each env's spec, and the copies are still the same env. Envs
    that really differ are refused, and the message names the env id to give instead.
    """
    gym.register("PartialPendulum-v0", entry_point=functools.partial(_pendulum, g=9.0), max_episode_steps=200)
    try:
        model = ARS("LinearPolicy", make_vec_env("PartialPendulum-v0", n_envs=2), n_delta=2, evaluator="processes")
        try:
            model.learn(1)
        finally:
            model._evaluator.close()  # type: ignore[union-attr]
        assert model._n_updates == 1 and model.num_timesteps >= 4 * 200  # 2 * n_delta episodes of 200 steps, at least
        differ = DummyVecEnv([lambda: gym.make("Pendulum-v1", g=9.0), lambda: gym.make("Pendulum-v1", g=10.0)])
        with pytest.raises(
            ValueError, match=r"envs differ, in their specs' kwargs: give the env id instead \(env='Pen"
        ):
            ARS("LinearPolicy", differ, evaluator="processes")
        # A lambda made anew for each env: the message names the wrapper argument and how to share it.
        fresh = make_vec_env("Pendulum-v1", n_envs=2, wrapper_class=lambda e: TransformReward(e, lambda r: 0.01 * r))
        with pytest.raises(
            ValueError, match=r"differ, in the TransformReward wrapper's func \(a function or lambda made"
        ):
            ARS("LinearPolicy", fresh, evaluator="processes")
    finally:
        del gym.registry["PartialPendulum-v0"]


def test_load_and_set_env_refuse_an_env_the_workers_cannot_rebuild(tmp_path: Path) -> None:
    ARS("LinearPolicy", ToyEnv(), n_delta=2).save(tmp_path / "model.zip")
    with pytest.raises(ValueError, match="evaluator='processes': .*not built by gym.make"):  # at load, not at learn
        ARS.load(tmp_path / "model.zip", env=ToyEnv(), evaluator="processes")
    model = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, evaluator="processes")
    with pytest.raises(ValueError, match="not built by gym.make"):
        model.set_env(DummyVecEnv([lambda: gym.wrappers.TimeLimit(ToyEnv(), 50)]))


def test_load_without_env_says_how_to_give_one(tmp_path: Path) -> None:
    ARS("LinearPolicy", "Pendulum-v1", n_delta=2).save(tmp_path / "model.zip")
    model = ARS.load(tmp_path / "model.zip", evaluator="processes")
    with pytest.raises(ValueError, match=r"has none .*pass env= to load\(\) .* or call model.set_env"):
        model.learn(1)
    model.set_env(make_vec_env("Pendulum-v1"))  # the fix it names works
    model.learn(1)
    assert model.num_timesteps > 0


def test_set_env_rebuilds_the_workers_from_the_new_env(monkeypatch: pytest.MonkeyPatch) -> None:
    """After ``set_env()`` the workers run the new env (rebuilt from its specs), not the env id of the constructor."""
    monkeypatch.setattr(processes, "usable_cpus", lambda: 2)
    model = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, seed=0, evaluator="processes")
    model.learn(1)
    old = model._evaluator
    assert isinstance(old, ProcessEvaluator) and old.env == "Pendulum-v1"
    pids = [process.pid for process in old._workers]
    assert len(pids) == 2
    model.set_env(make_vec_env("Pendulum-v1", env_kwargs={"g": 2.0}))
    assert wait_gone(pids)  # the old workers are stopped at once
    try:
        model.learn(1, reset_num_timesteps=False)
        new = model._evaluator
        assert isinstance(new, ProcessEvaluator) and new is not old
        assert new.env().unwrapped.g == 2.0  # the factory the workers build their envs with
    finally:
        model._evaluator.close()  # type: ignore[union-attr]
    assert model._n_updates == 2


def test_close_stops_the_workers_the_model_built(monkeypatch: pytest.MonkeyPatch) -> None:
    # They idled until the model was garbage-collected (learn()'s locals and the callbacks hold it in a cycle)
    monkeypatch.setattr(processes, "usable_cpus", lambda: 2)
    model = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, seed=0, evaluator="processes")
    model.learn(1)
    assert isinstance(model._evaluator, ProcessEvaluator)
    pids = [process.pid for process in model._evaluator._workers]
    model.close()
    assert wait_gone(pids) and model._evaluator is None
    model.learn(1, reset_num_timesteps=False)  # new workers
    assert isinstance(model._evaluator, ProcessEvaluator) and model._n_updates == 2
    model.close()
    # an evaluator passed in is its owner's: close() leaves it running
    with ProcessEvaluator("Pendulum-v1", num_workers=1) as evaluator:
        model = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, seed=0, evaluator=evaluator)
        model.learn(1)
        model.close()
        model.learn(1, reset_num_timesteps=False)
        assert model._evaluator is evaluator and not any(gone(p.pid) for p in evaluator._workers)


def test_models_in_a_loop() -> None:
    pids: list[int] = []
    for seed in range(3):
        model = ARS("LinearPolicy", "Pendulum-v1", n_delta=1, seed=seed, evaluator="processes")
        model.learn(1)
        assert model._n_updates == 1
        pids += [process.pid for process in model._evaluator._workers]  # type: ignore[union-attr]
        model._evaluator.close()  # type: ignore[union-attr]
    assert len(pids) == 3 * usable_cpus()
    assert wait_gone(pids)


def test_subproc_vec_env_user_is_told_the_faster_option() -> None:
    env = VecNormalize(SubprocVecEnv([lambda: ToyEnv()] * 2, start_method="fork"))
    model = ARS("LinearPolicy", env, n_delta=1)
    try:
        with pytest.warns(UserWarning, match=r"SubprocVecEnv.*evaluator='processes'"):
            model.learn(1)
    finally:
        env.close()


def test_an_interrupted_call_leaves_no_reply_for_the_next_generation(monkeypatch: pytest.MonkeyPatch) -> None:
    """A Ctrl-C while call_workers() waits leaves the replies unread: the next generation must not take them for its
    shares' results."""
    policy = toy_policy()
    population = toy_population(policy, 4)
    with ProcessEvaluator(ToyEnv, num_workers=2, envs_per_worker=2) as evaluator:

        def interrupted(*args: Any) -> Any:
            raise KeyboardInterrupt

        monkeypatch.setattr(evaluator.pool, "result", interrupted)  # the call is sent, no reply is read
        with pytest.raises(KeyboardInterrupt):
            evaluator.call_workers(lambda venv: venv.num_envs)
        monkeypatch.undo()
        result = evaluator.evaluate(policy, population, population[0], 1, seed=0)
        local = VecEnvEvaluator(make_vec_env(ToyEnv, n_envs=4)).evaluate(policy, population, population[0], 1, seed=0)
        np.testing.assert_array_equal(result.returns, local.returns)


def test_a_ctrl_c_while_the_workers_are_stopped_is_held_until_all_are(monkeypatch: pytest.MonkeyPatch) -> None:
    """A second Ctrl-C (one during the stop that follows the first) must not leave a worker running with its reply
    unread, for the next generation to take as its own."""
    policy = toy_policy()
    population = toy_population(policy, 4)
    evaluator = ProcessEvaluator(ToyEnv, num_workers=2, envs_per_worker=2)
    evaluator.start()
    running = list(evaluator._workers)
    first = running[0]
    kill = first.kill

    def kill_then_ctrl_c() -> None:
        kill()
        os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(first, "kill", kill_then_ctrl_c)
    handler = signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a terminal (a background job ignores it)
    try:
        with pytest.raises(KeyboardInterrupt):
            evaluator.close()
        assert not any(process.is_alive() for process in running)
        result = evaluator.evaluate(policy, population, population[0], 1, seed=0)
        local = VecEnvEvaluator(make_vec_env(ToyEnv, n_envs=4)).evaluate(policy, population, population[0], 1, seed=0)
        np.testing.assert_array_equal(result.returns, local.returns)
    finally:
        signal.signal(signal.SIGINT, handler)
        monkeypatch.undo()
        evaluator.close()
        for process in running:
            process.kill()


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="env instance"):
        ProcessEvaluator(ToyEnv())  # type: ignore[arg-type]
    for bad in (0, 1.5, float("nan"), "2"):
        with pytest.raises(ValueError, match=rf"num_workers={bad!r}: it must be"):
            ProcessEvaluator("Pendulum-v1", num_workers=bad)  # type: ignore[arg-type]
        with pytest.raises(ValueError, match=rf"envs_per_worker={bad!r}: it must be"):
            ProcessEvaluator("Pendulum-v1", envs_per_worker=bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"max_worker_restarts=-1: it must be at least 0"):
        ProcessEvaluator("Pendulum-v1", max_worker_restarts=-1)
    with pytest.raises(ValueError, match=r"SubprocVecEnv: worker processes are daemons .* \(num_workers=\)"):
        ProcessEvaluator("Pendulum-v1", vec_env_cls=SubprocVecEnv)
    with pytest.raises(TypeError, match="linger='False': it must be True or False"):
        ProcessEvaluator("Pendulum-v1", linger="False")  # type: ignore[arg-type]
    # make_vec_env's arguments of the wrong kind are named now, not by a worker at the first learn().
    with pytest.raises(TypeError, match=r"vec_env_cls='DummyVecEnv': pass the VecEnv class itself, not its name"):
        ProcessEvaluator("Pendulum-v1", vec_env_cls="DummyVecEnv")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"vec_env_cls=<class 'dict'>: pass a VecEnv class .*or None for DummyVecEnv"):
        ProcessEvaluator("Pendulum-v1", vec_env_cls=dict)  # type: ignore[arg-type]
    for name in ("env_kwargs", "wrapper_kwargs", "vec_env_kwargs", "monitor_kwargs"):
        for wrong in ([1], "g=9", [("g", 9.0)]):
            with pytest.raises(TypeError, match=rf"{name}={re.escape(repr(wrong))}: it must be a dict of keyword"):
                ProcessEvaluator("Pendulum-v1", **{name: wrong})  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"env_kwargs=\{1: 9.0\}: its keys must be argument names \(strings\), not 1"):
        ProcessEvaluator("Pendulum-v1", env_kwargs={1: 9.0})  # type: ignore[dict-item]
    with pytest.raises(TypeError, match=r"wrapper_class=3: it must be a gym.Wrapper class, or a function"):
        ProcessEvaluator("Pendulum-v1", wrapper_class=3)  # type: ignore[arg-type]
    assert ProcessEvaluator("Pendulum-v1", env_kwargs={"g": 9.0}, vec_env_cls=DummyVecEnv, wrapper_class=None)
    with pytest.raises(ValueError, match="start_method='thread'"):
        ProcessEvaluator("Pendulum-v1", start_method="thread")
    with pytest.raises(TypeError, match="env_kwarg: the env arguments of a worker are wrapper_class, env_kwargs"):
        ProcessEvaluator("Pendulum-v1", env_kwarg={"g": 9.0})  # type: ignore[call-arg]
    # RayEvaluator's name for it is not taken for an env argument.
    with pytest.raises(TypeError, match="max_actor_restarts: that is RayEvaluator's; this evaluator's is max_worker_r"):
        ProcessEvaluator("Pendulum-v1", max_actor_restarts=1)  # type: ignore[call-arg]
    # Timeouts: a positive number of seconds, math.inf (or None, for generation_timeout) for no limit.
    for name in ("start_timeout", "generation_timeout"):
        for wrong in (None, "5"):
            if not (wrong is None and name == "generation_timeout"):
                with pytest.raises(TypeError, match=rf"{name}={wrong!r}: it must be a number"):
                    ProcessEvaluator("Pendulum-v1", **{name: wrong})  # type: ignore[arg-type]
        for wrong in (0, -1, math.nan):
            with pytest.raises(ValueError, match=rf"{name}={wrong!r}: give a positive number of seconds \(.*math.inf"):
                ProcessEvaluator("Pendulum-v1", **{name: wrong})  # type: ignore[arg-type]
    assert ProcessEvaluator("Pendulum-v1", start_timeout=math.inf).start_timeout == math.inf
    assert ProcessEvaluator("Pendulum-v1", generation_timeout=math.inf).generation_timeout is None
    lock = threading.Lock()  # every worker gets a copy of the env arguments: one that does not pickle is named now
    with pytest.raises(TypeError, match=r"env=<function .* does not pickle \(TypeError: cannot pickle '_thread.lock'"):
        ProcessEvaluator(lambda: ToyEnv() if lock else ToyEnv())
    with pytest.raises(TypeError, match=r"env_kwargs=\{'g': <unlocked _thread.lock .*inside the env factory"):
        ProcessEvaluator("Pendulum-v1", env_kwargs={"g": lock})
    evaluator = ProcessEvaluator("NoSuchEnv-v0", num_workers=1)
    with pytest.raises(Exception, match="NoSuchEnv"):
        evaluator.start()
    assert evaluator._workers == []


def test_waits_longer_than_the_os_takes_are_made_of_pieces(monkeypatch: pytest.MonkeyPatch) -> None:
    """poll() refuses a timeout over about 24 days (OverflowError): a longer wait, math.inf included, is a series
    of shorter ones, which goes on until a reply comes or the whole timeout is over."""
    receiver, sender = multiprocessing.Pipe(duplex=False)
    sender.send("at once")
    assert processes._wait([receiver], 1e12) == [receiver]
    assert receiver.recv() == "at once"
    monkeypatch.setattr(sharded, "MAX_WAIT", 0.02)
    start = time.monotonic()
    assert processes._wait([receiver], 0.2) == []
    assert time.monotonic() - start >= 0.19  # not over after the first piece
    timer = threading.Timer(0.2, sender.send, ("later",))
    timer.start()
    assert processes._wait([receiver], math.inf) == [receiver]
    assert receiver.recv() == "later"
    timer.join()


def test_an_env_registered_by_the_script_is_named_in_a_spawned_worker() -> None:
    gym.register("ScriptOnlyPendulum-v0", entry_point="gymnasium.envs.classic_control:PendulumEnv")
    try:
        evaluator = ProcessEvaluator("ScriptOnlyPendulum-v0", num_workers=1, start_method="spawn")
        with pytest.raises(
            gym.error.NameNotFound,
            match=r"ScriptOnlyPendulum.* \(in a worker process\)\. An env "
            r"registered by your script .*'my_package.envs:MyEnv-v0'.*or pass an env factory",
        ):
            evaluator.start()
    finally:
        gym.registry.pop("ScriptOnlyPendulum-v0")


#: Opens the driver scripts below (as run): a driver dies with the test process should pytest itself be killed mid-test
#: (Linux's ``PR_SET_PDEATHSIG``), rather than train on with ``learn(10**9)``; its workers then exit as its pipes close.
DIE_WITH_PYTEST = """
import ctypes
import signal
import sys

if sys.platform == "linux":
    ctypes.CDLL(None).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
"""

SCRIPT = """
import signal
import sys
from sb3_es import ARS

# As in a terminal, whatever ignored SIGINT in the process that started the tests (e.g. a background job)
signal.signal(signal.SIGINT, signal.default_int_handler)
from sb3_es.evaluation.processes import ProcessEvaluator

evaluator = ProcessEvaluator("Pendulum-v1", num_workers=2)
model = ARS("LinearPolicy", "Pendulum-v1", n_delta=4, evaluator=evaluator)
evaluator.start()
print(" ".join(str(p.pid) for p in evaluator._workers), flush=True)
model.learn(int(sys.argv[1]))
print("done", flush=True)
"""


def run_script(steps: int) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-c", DIE_WITH_PYTEST + SCRIPT, str(steps)],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group, as a terminal's foreground job
    )


def test_normal_exit_leaves_no_process() -> None:
    script = run_script(1)  # never closes the evaluator
    out, err = script.communicate(timeout=600)
    assert script.returncode == 0, err
    pids = [int(pid) for pid in out.splitlines()[0].split()]
    assert len(pids) == 2
    assert out.splitlines()[-1] == "done"
    assert wait_gone(pids)


def test_ctrl_c_leaves_no_process() -> None:
    script = run_script(10**9)
    assert script.stdout is not None
    pids = [int(pid) for pid in script.stdout.readline().split()]
    assert len(pids) == 2
    time.sleep(2.0)  # inside a generation
    os.killpg(script.pid, signal.SIGINT)  # Ctrl-C: the whole foreground group gets SIGINT
    _, err = script.communicate(timeout=600)
    assert script.returncode != 0 and "KeyboardInterrupt" in err
    assert wait_gone(pids)


KILLED_DRIVER_SCRIPT = """
import os
import sys
import time

import gymnasium as gym

from sb3_es import ARS
from sb3_es.evaluation.processes import ProcessEvaluator


class Slow(gym.Wrapper):
    def step(self, action):
        time.sleep(self.delay)
        return self.env.step(action)


def make():  # the first env made is slow: its worker is still busy when the other one lingers
    env = Slow(gym.make("Pendulum-v1"))
    try:
        os.close(os.open(sys.argv[1], os.O_CREAT | os.O_EXCL))
        env.delay = 0.005
    except FileExistsError:
        env.delay = 0.0
    return env


evaluator = ProcessEvaluator(make, num_workers=2, envs_per_worker=1)
model = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, evaluator=evaluator)
evaluator.start()
print(" ".join(str(p.pid) for p in evaluator._workers), flush=True)
model.learn(10**9)
"""


def test_killed_driver_leaves_no_process(tmp_path: Path) -> None:
    """A driver killed at once (SIGKILL: the OOM killer, a crashed kernel) leaves no worker running, including one
    that was lingering on the center policy."""
    script = subprocess.Popen(
        [sys.executable, "-c", DIE_WITH_PYTEST + KILLED_DRIVER_SCRIPT, str(tmp_path / "slow")],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    assert script.stdout is not None
    pids = [int(pid) for pid in script.stdout.readline().split()]
    assert len(pids) == 2
    time.sleep(1.0)  # the slow worker's share takes 2 s (2 episodes of 200 steps at 5 ms): the other one lingers
    script.kill()
    script.communicate(timeout=60)
    try:
        assert wait_gone(pids, timeout=20.0)
    finally:
        for pid in pids:
            if not gone(pid):
                os.kill(pid, signal.SIGKILL)


def test_a_failed_call_leaves_the_workers_usable() -> None:
    """When a call fails in one worker, the other workers' replies are read too: none is left for the next call."""
    with ProcessEvaluator("Pendulum-v1", num_workers=2, envs_per_worker=1) as evaluator:
        evaluator.start()
        first = evaluator._workers[0].pid

        def fails_in_the_first(venv: Any) -> str:
            if os.getpid() == first:
                raise KeyError("only the first worker fails")
            return "a reply from the second"

        with pytest.raises(KeyError, match="only the first worker fails"):
            evaluator.call_workers(fails_in_the_first)
        assert evaluator.call_workers(lambda venv: venv.num_envs) == [1, 1]


class InfoEnv(ToyEnv):
    """``ToyEnv`` whose last step's info holds ``make_value()`` under ``"extra"``."""

    def __init__(self, make_value: Any) -> None:
        super().__init__()
        self.make_value = make_value

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        obs, reward, terminated, truncated, info = super().step(action)
        if terminated or truncated:
            info["extra"] = self.make_value()
        return obs, reward, terminated, truncated, info


class Handle:
    """Copied as itself (as SB3's DummyVecEnv copies infos) but not picklable, as a handle to a native resource."""

    def __deepcopy__(self, memo: dict) -> Handle:
        return self

    def __reduce__(self) -> Any:
        raise TypeError("cannot pickle 'Handle' object")


class TwoPartError(Exception):
    """An exception whose ``__init__`` does not take its ``args``: pickle cannot rebuild it."""

    def __init__(self, what: str, why: str) -> None:
        super().__init__(f"{what} failed: {why}")


class FailingEnv(ToyEnv):
    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        raise TwoPartError("the simulator", "a joint broke")


def test_what_workers_send_back_crosses_or_is_named() -> None:
    policy = toy_policy()
    population = toy_population(policy, 4)
    # A lambda in an info crosses, as with Ray (and locally).
    with ProcessEvaluator(functools.partial(InfoEnv, lambda: lambda: 7), num_workers=2, envs_per_worker=1) as evaluator:
        assert evaluator.evaluate(policy, population, population[0], 1, seed=0).returns.shape == (4, 1)
    # A value that does not pickle is named with its info key, not left as a bare pickling error.
    locked = ProcessEvaluator(functools.partial(InfoEnv, Handle), num_workers=2, envs_per_worker=1)
    with locked, pytest.raises(RuntimeError, match=r"holds Handle under 'extra', which does not pickle"):
        locked.evaluate(policy, population, population[0], 1, seed=0)
    # An exception that pickle cannot rebuild in the driver arrives as its type and message (it was a TypeError
    # about __init__'s arguments, without the worker's traceback).
    with ProcessEvaluator(FailingEnv, num_workers=2, envs_per_worker=1) as evaluator:
        with pytest.raises(RuntimeError, match=r"TwoPartError: the simulator failed: a joint broke") as info:
            evaluator.evaluate(policy, population, population[0], 1, seed=0)
        assert "raise TwoPartError" in str(info.value.__cause__)


def test_worker_count_follows_the_container_cpu_quota(tmp_path: Path) -> None:
    # docker --cpus / a Kubernetes CPU limit shows as a cgroup quota, not in the affinity mask: one worker per CPU
    # of the quota (rounded up), not one per CPU of the host.
    cpus = len(os.sched_getaffinity(0))
    v2, v1 = tmp_path / "v2", tmp_path / "v1"
    (v1 / "cpu").mkdir(parents=True)
    v2.mkdir()
    (v2 / "cpu.max").write_text("50000 100000\n")
    assert processes.cgroup_cpu_quota(str(v2)) == 0.5 and usable_cpus(str(v2)) == 1
    (v2 / "cpu.max").write_text("max 100000\n")
    assert processes.cgroup_cpu_quota(str(v2)) is None and usable_cpus(str(v2)) == cpus
    (v1 / "cpu" / "cpu.cfs_quota_us").write_text("150000\n")
    (v1 / "cpu" / "cpu.cfs_period_us").write_text("100000\n")
    assert processes.cgroup_cpu_quota(str(v1)) == 1.5 and usable_cpus(str(v1)) == min(cpus, 2)
    (v1 / "cpu" / "cpu.cfs_quota_us").write_text("-1\n")
    assert processes.cgroup_cpu_quota(str(v1)) is None and usable_cpus(str(v1)) == cpus
    assert processes.cgroup_cpu_quota(str(tmp_path / "none")) is None
