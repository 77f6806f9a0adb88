"""
Render a saved agent to a GIF or an MP4, headless.

Examples::

    # a model trained through python -m sb3_es.zoo (env id, wrappers and VecNormalize found next to it)
    python benchmarks/render.py logs/ars_es/BipedalWalker-v3_1/BipedalWalker-v3.zip --out walker.gif

    # any SB3 / sb3-es save, naming the env (and the algorithm if the file does not say)
    python benchmarks/render.py model.zip --env Hopper-v5 --out hopper.mp4 --steps 1000
    python benchmarks/render.py ppo.zip --env Pendulum-v1 --algo ppo --out pendulum.gif

The algorithm is ``--algo`` if given, else the save's ``_algorithm_name`` (written by sb3-es models), else a
guess from the save's attributes (PPO, SAC, ...). Rendering uses ``render_mode="rgb_array"``: Box2D and
classic control through pygame with ``SDL_VIDEODRIVER=dummy``; MuJoCo and dm_control offscreen with
``MUJOCO_GL=egl`` (or ``osmesa``), picked from the libraries found unless ``MUJOCO_GL`` is set. ``.mp4``
needs imageio-ffmpeg; without it a GIF is written instead. If the model was trained with rl-zoo (a
``<env>/`` folder next to the zip with ``config.yml``/``args.yml``), its env kwargs (``--env-kwargs`` over the
config's), wrappers, frame stacking and ``VecNormalize`` statistics are applied as in training (rl-zoo's
``enjoy`` does the same). A video ends at the last step of its last episode (the env has reset after it). Needs
sb3-es's ``[zoo]`` extra (rl-zoo, imageio).
"""

from __future__ import annotations

import argparse
import ctypes.util
import importlib.util
import json
import os
import sys
import zipfile
from pathlib import Path
from typing import Any


def choose_mujoco_gl() -> str | None:
    """
    Set ``MUJOCO_GL`` for offscreen rendering (before MuJoCo is imported) unless it is set already.

    :return: The backend chosen (``"egl"``, ``"osmesa"``) or None when none was found or it was preset.
    """
    if os.environ.get("MUJOCO_GL"):
        return None
    for backend, library in (("egl", "EGL"), ("osmesa", "OSMesa")):
        if ctypes.util.find_library(library):
            os.environ["MUJOCO_GL"] = backend
            if backend == "osmesa":
                os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")
            else:
                os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
            return backend
    return None


# Must happen before gymnasium/mujoco/pygame are imported.
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
MUJOCO_GL = choose_mujoco_gl()

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import yaml  # noqa: E402
from common import load_model  # noqa: E402
from stable_baselines3.common.base_class import BaseAlgorithm  # noqa: E402
from stable_baselines3.common.env_util import make_vec_env  # noqa: E402
from stable_baselines3.common.vec_env import VecEnv, VecFrameStack, VecNormalize  # noqa: E402

from sb3_es.common.save_util import guess_foreign_algorithm  # noqa: E402
from sb3_es.zoo import register, register_envs, sb3_es_algos  # noqa: E402


def algorithm_classes() -> dict[str, type[BaseAlgorithm]]:
    """
    Algorithm classes by rl-zoo key: rl-zoo's (``ars`` is sb3-contrib's ARS) and sb3-es's (``ars_es``, ...).

    :return: ``key -> class``.
    """
    import rl_zoo3

    register()
    return dict(rl_zoo3.ALGOS)


def detect_algorithm(path: Path, algo: str | None) -> type[BaseAlgorithm]:
    """
    The class that loads a save: ``--algo``, else the save's ``_algorithm_name``, else a guess.

    :param path: The ``.zip`` save.
    :param algo: rl-zoo key given on the command line (or None).
    :return: The algorithm class.
    """
    classes = algorithm_classes()
    if algo is not None:
        if algo.lower() not in classes:
            raise SystemExit(f"Unknown --algo {algo!r}; choose one of {sorted(classes)}.")
        return classes[algo.lower()]
    with zipfile.ZipFile(path) as archive:
        data: dict[str, Any] = json.loads(archive.read("data"))
    ours = {cls.__name__: cls for cls in sb3_es_algos().values()}
    name = data.get("_algorithm_name")  # the class name, written by every sb3-es save
    policy_module = str((data.get("policy_class") or {}).get("__module__", ""))
    if not name and policy_module.startswith("sb3_es.reinforce"):
        name = "REINFORCE"
    if name in ours:
        return ours[name]
    guess = guess_foreign_algorithm(data)  # SB3 and sb3-contrib saves: guessed from their attributes
    key = "ars" if guess == "sb3-contrib's ARS" else guess.lower()
    if key not in classes:
        raise SystemExit(f"Cannot tell which algorithm saved {path} (guess: {guess}); pass --algo.")
    return classes[key]


def zoo_files(model_path: Path) -> tuple[dict[str, Any], dict[str, Any], Path | None]:
    """
    rl-zoo's files next to a model: ``<dir>/<env>/config.yml``, ``args.yml`` and ``vecnormalize.pkl``.

    :param model_path: The model's ``.zip``.
    :return: The saved hyperparameters, the saved arguments, and the VecNormalize path (or None).
    """
    folder = model_path.parent / model_path.stem
    if model_path.stem in ("best_model",) or not folder.is_dir():
        candidates = [p for p in model_path.parent.iterdir() if p.is_dir() and (p / "config.yml").is_file()]
        folder = candidates[0] if len(candidates) == 1 else folder
    config: dict[str, Any] = {}
    saved_args: dict[str, Any] = {}
    if (folder / "config.yml").is_file():
        config = dict(yaml.load((folder / "config.yml").read_text(), Loader=yaml.UnsafeLoader))
    if (folder / "args.yml").is_file():
        saved_args = dict(yaml.load((folder / "args.yml").read_text(), Loader=yaml.UnsafeLoader))
    vec_normalize = folder / "vecnormalize.pkl"
    return config, saved_args, vec_normalize if vec_normalize.is_file() else None


def make_env(
    env_id: str,
    config: dict[str, Any],
    saved_args: dict[str, Any],
    vec_normalize: Path | None,
    model: BaseAlgorithm,
    seed: int,
) -> VecEnv:
    """
    One rendering env (``rgb_array``) wrapped as in training.

    :param env_id: Env id.
    :param config: rl-zoo's saved hyperparameters (may give ``env_wrapper``, ``env_kwargs``, ``frame_stack``,
        ``vec_env_wrapper``).
    :param saved_args: rl-zoo's saved arguments (their ``env_kwargs``, from ``--env-kwargs``, win).
    :param vec_normalize: Saved VecNormalize statistics, or None.
    :param model: The loaded model (to flatten Dict observations when it expects a Box).
    :param seed: Env seed.
    :return: The VecEnv.
    """
    from rl_zoo3.utils import get_wrapper_class

    wrapper = get_wrapper_class(config) if config.get("env_wrapper") else None
    env_kwargs = {**(config.get("env_kwargs") or {}), **(saved_args.get("env_kwargs") or {})}
    env_kwargs["render_mode"] = "rgb_array"
    probe = gym.make(env_id)
    needs_flatten = isinstance(probe.observation_space, gym.spaces.Dict) and isinstance(
        model.observation_space, gym.spaces.Box
    )
    probe.close()
    if wrapper is None and needs_flatten:
        wrapper = gym.wrappers.FlattenObservation
    env = make_vec_env(env_id, n_envs=1, seed=seed, env_kwargs=env_kwargs, wrapper_class=wrapper)
    # In rl-zoo's ExperimentManager order: the VecEnv wrapper, VecNormalize, frame stacking.
    if config.get("vec_env_wrapper"):
        vec_env_wrapper: Any = get_wrapper_class(config, "vec_env_wrapper")  # typed by rl-zoo as an Env wrapper
        env = vec_env_wrapper(env)
    if vec_normalize is not None:
        env = VecNormalize.load(str(vec_normalize), env)
        env.training = False
        env.norm_reward = False
    if config.get("frame_stack"):
        env = VecFrameStack(env, int(config["frame_stack"]))
    return env


def render_error(env_id: str, error: Exception) -> SystemExit:
    """
    A clear message for a rendering failure.

    :param env_id: Env id.
    :param error: The original error.
    :return: The exception to raise.
    """
    hint = ""
    spec = gym.spec(env_id)
    if "mujoco" in str(spec.entry_point) or env_id.startswith("dm_control/"):
        hint = (
            f" MuJoCo/dm_control render offscreen through MUJOCO_GL (now {os.environ.get('MUJOCO_GL')!r}): use "
            "MUJOCO_GL=egl with libEGL (a GPU driver or Mesa's libegl1), or MUJOCO_GL=osmesa with libosmesa6 "
            "(apt-get install libosmesa6)."
        )
    else:
        hint = " Box2D and classic-control envs render through pygame: pip install pygame (SDL_VIDEODRIVER=dummy)."
    return SystemExit(f"Cannot render {env_id}: {type(error).__name__}: {error}.{hint}")


def write_video(frames: list[np.ndarray], out: Path, fps: int) -> Path:
    """
    Write frames to a GIF (imageio's pillow plugin) or an MP4 (imageio-ffmpeg; a GIF if it is missing).

    :param frames: RGB frames.
    :param out: Output path (``.gif`` or ``.mp4``).
    :param fps: Frames per second.
    :return: The path written.
    """
    import imageio.v3 as iio

    out.parent.mkdir(parents=True, exist_ok=True)
    if out.suffix.lower() == ".mp4":
        if importlib.util.find_spec("imageio_ffmpeg") is None:
            out = out.with_suffix(".gif")
            print(f"imageio-ffmpeg is not installed (pip install imageio-ffmpeg): writing {out} instead.")
        else:
            # macro_block_size=1 keeps odd frame sizes (e.g. 600x400 is fine, 500x500 too) without resizing.
            iio.imwrite(out, np.stack(frames), extension=".mp4", fps=fps, macro_block_size=1)
            return out
    if out.suffix.lower() != ".gif":
        raise SystemExit(f"Unsupported output {out}: use .gif or .mp4.")
    iio.imwrite(out, np.stack(frames), extension=".gif", duration=1000 / fps, loop=0)
    return out


def main(argv: list[str] | None = None) -> Path:
    """
    Render a saved agent.

    :param argv: Arguments (defaults to ``sys.argv[1:]``).
    :return: The file written.
    """
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("model", type=Path, help="saved model (.zip)")
    parser.add_argument("--env", default=None, help="env id (default: from rl-zoo's args.yml next to the model)")
    parser.add_argument("--algo", default=None, help="rl-zoo key (ppo, ars_es, ...); default: from the save")
    parser.add_argument("--out", type=Path, default=None, help="output .gif or .mp4 (default: <model>.gif)")
    parser.add_argument("--steps", type=int, default=500, help="env steps to record at most")
    parser.add_argument("--episodes", type=int, default=1, help="stop after this many episodes (default: 1)")
    parser.add_argument("--fps", type=int, default=30)
    parser.add_argument("--every", type=int, default=1, help="keep one frame in N (smaller files)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--stochastic", action="store_true", help="sample actions instead of deterministic ones")
    args = parser.parse_args(argv)
    for flag in ("steps", "episodes", "fps", "every"):
        if getattr(args, flag) < 1:
            parser.error(f"--{flag} {getattr(args, flag)}: it must be at least 1.")
    out = args.out or args.model.with_suffix(".gif")
    if out.suffix.lower() not in (".gif", ".mp4"):  # checked before the frames are rendered
        parser.error(f"--out {out}: unsupported output; give a .gif or .mp4 file.")
    if not args.model.is_file():
        raise SystemExit(f"No model file {args.model}.")
    register_envs()
    config, saved_args, vec_normalize = zoo_files(args.model)
    env_id = args.env or saved_args.get("env")
    if not env_id:
        raise SystemExit("Pass --env: no rl-zoo args.yml next to the model says which env it was trained on.")
    algo_class = detect_algorithm(args.model, args.algo)
    model = load_model(parser, algo_class, args.model)
    env = make_env(env_id, config, saved_args, vec_normalize, model, args.seed)

    def frame() -> np.ndarray:  # a rendering failure gets the install hints; other errors are raised as they are
        try:
            image = env.render()
            if image is None:
                raise RuntimeError("render() returned no frame")
        except Exception as e:
            raise render_error(env_id, e) from e
        return image

    frames: list[np.ndarray] = []
    returns: list[float] = []
    episode_return = 0.0
    try:
        obs = env.reset()
        frames.append(frame())
        for step in range(1, args.steps + 1):
            action, _ = model.predict(obs, deterministic=not args.stochastic)  # type: ignore[arg-type]
            obs, reward, done, _ = env.step(action)
            episode_return += float(reward[0])
            if done[0]:
                returns.append(episode_return)
                episode_return = 0.0
                if len(returns) >= args.episodes:
                    break  # the env has reset: its frame would show the next episode
            if step % args.every == 0:
                frames.append(frame())
    finally:
        env.close()
    written = write_video(frames, out, args.fps)
    finished = f"episode returns {[round(r, 1) for r in returns]}" if returns else "no episode finished"
    print(f"Wrote {written} ({len(frames)} frames, {type(model).__name__} on {env_id}; {finished}).")
    return written


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
