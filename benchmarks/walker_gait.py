"""
What a walker-walk policy's return is made of: speed, torso height and uprightness, per episode.

dm_control's walker-walk pays per step ``stand * (5 * move + 1) / 6``, where ``stand`` rewards a torso at least
1.2 m high and upright and ``move`` a forward speed of at least 1 m/s: a return near 1,000 needs both. Example (the
shipped PGPE model)::

    python benchmarks/walker_gait.py benchmarks/trained/pgpe_walker_walk_mlp_ln.zip --episodes 5

Prints one line per episode (deterministic policy, reset seeds 300, 301, ...).
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np
import shimmy
from stable_baselines3.common.base_class import BaseAlgorithm
from walker_shaping import STAND_HEIGHT, walker_physics

import sb3_es

gym.register_envs(shimmy)  # the dm_control/ ids


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("model", help="a saved sb3-es model (zip) trained on dm_control/walker-walk-v0")
    parser.add_argument("--algo", default="PGPE", help="its algorithm class in sb3_es (default PGPE)")
    parser.add_argument("--episodes", type=int, default=5)
    args = parser.parse_args()

    model: BaseAlgorithm = getattr(sb3_es, args.algo).load(args.model, device="cpu")
    env = gym.make("dm_control/walker-walk-v0")
    physics = walker_physics(env)
    for episode in range(args.episodes):
        obs, _ = env.reset(seed=300 + episode)
        total, speed, height, upright = 0.0, [], [], []
        done = False
        while not done:
            action, _ = model.predict({key: np.asarray(value)[None] for key, value in obs.items()}, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(action[0])
            total += float(reward)
            done = terminated or truncated
            speed.append(physics.horizontal_velocity())
            height.append(physics.torso_height())
            upright.append(physics.torso_upright())
        h = np.array(height)
        print(
            f"episode {episode}: return {total:.1f}, speed {np.mean(speed):.2f} m/s, torso height {h.mean():.2f} m "
            f"(below {STAND_HEIGHT} m in {np.mean(h < STAND_HEIGHT):.0%} of the steps), upright {np.mean(upright):.2f}"
        )


if __name__ == "__main__":
    main()
