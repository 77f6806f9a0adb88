"""
What a walker-walk policy's return is made of: speed, torso height and uprightness, per episode.

dm_control's walker-walk pays per step ``stand * (5 * move + 1) / 6``, where ``stand`` rewards a torso at least
1.2 m high and upright and ``move`` a forward speed of at least 1 m/s: a return near 1,000 needs both. Example (the
shipped PGPE model)::

    python benchmarks/walker_gait.py benchmarks/trained/pgpe_walker_walk_mlp_ln.zip --episodes 5

Prints one line per episode (deterministic policy, reset seeds 300, 301, ...), then the same figures and the reward
per step over all episodes by phase of the episode (the first 100 steps, the next 100, the rest), which shows how
much of the return getting up from dm_control's random initial pose costs. ``--upright-starts`` starts every
episode upright instead (``walker_shaping.UprightStart``).
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np
import shimmy
from common import algorithm_classes, load_model
from stable_baselines3.common.base_class import BaseAlgorithm
from walker_shaping import STAND_HEIGHT, UprightStart, walker_physics

from sb3_es.zoo.registry import ALGOS

gym.register_envs(shimmy)  # the dm_control/ ids

#: ``--algo`` choices: sb3-es's algorithm classes by class name (``PGPE``) and by rl-zoo key (``pgpe``, ``ars_es``).
ALGORITHMS: dict[str, type[BaseAlgorithm]] = {
    **algorithm_classes(BaseAlgorithm),
    **ALGOS,
}


def main(argv: list[str] | None = None) -> None:
    """
    Print the figures of each episode, then by phase.

    :param argv: Arguments (defaults to ``sys.argv[1:]``).
    """
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("model", help="a saved sb3-es model (zip) trained on dm_control/walker-walk-v0")
    parser.add_argument(
        "--algo",
        choices=list(ALGORITHMS),
        default="PGPE",
        metavar="ALGO",
        help=f"its sb3-es algorithm, a class name or an rl-zoo key: {', '.join(ALGORITHMS)} (default PGPE)",
    )
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument(
        "--upright-starts", action="store_true", help="start every episode upright (walker_shaping.UprightStart)"
    )
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f"--episodes {args.episodes}: it must be at least 1")

    model = load_model(parser, ALGORITHMS[args.algo], args.model)
    env = gym.make("dm_control/walker-walk-v0")
    if args.upright_starts:
        env = UprightStart(env, probability=1.0)
    physics = walker_physics(env)
    per_step: list[np.ndarray] = []  # one (steps, 4) array per episode: reward, speed, height, uprightness
    for episode in range(args.episodes):
        obs, _ = env.reset(seed=300 + episode)
        rewards: list[float] = []
        speed, height, upright = [], [], []
        done = False
        while not done:
            action, _ = model.predict({key: np.asarray(value)[None] for key, value in obs.items()}, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(action[0])
            rewards.append(float(reward))
            done = terminated or truncated
            speed.append(physics.horizontal_velocity())
            height.append(physics.torso_height())
            upright.append(physics.torso_upright())
        steps = np.array([rewards, speed, height, upright]).T
        per_step.append(steps)
        h = steps[:, 2]
        print(
            f"episode {episode}: return {steps[:, 0].sum():.1f}, speed {steps[:, 1].mean():.2f} m/s, torso height "
            f"{h.mean():.2f} m (below {STAND_HEIGHT} m in {np.mean(h < STAND_HEIGHT):.0%} of the steps), upright "
            f"{steps[:, 3].mean():.2f}"
        )

    print_phases(per_step)


def print_phases(per_step: list[np.ndarray], bounds: tuple[int, ...] = (0, 100, 200)) -> None:
    """Print the mean reward per step, speed, torso height and uprightness over all episodes, by phase.

    :param per_step: One array per episode, a row per step: reward, speed, torso height, uprightness.
    :param bounds: The first step of each phase; the last phase runs to the end of the episode.
    """
    for start, stop in zip(bounds, (*bounds[1:], None)):
        rows = np.concatenate([steps[start:stop] for steps in per_step])
        if len(rows) == 0:
            continue
        reward, speed, height, upright = rows.mean(axis=0)
        label = f"steps {start}-{'end' if stop is None else stop - 1}"
        print(
            f"{label}: reward per step {reward:.3f}, speed {speed:.2f} m/s, torso height {height:.2f} m, "
            f"upright {upright:.2f}"
        )


if __name__ == "__main__":
    main()
