"""Stable-Baselines3 PPO on a modesuite task through ``modesuite.sb3.VecAdapter``.

Not part of the test suite (SB3 needs torch, gigabytes): run by hand in an environment with
``pip install stable-baselines3`` and the modesuite package::

    python examples/python/train_sb3_ppo.py --task MoDe-Franka-Place-v0 --envs 16 --steps 200000

Prints SB3's progress table and, at the end, the success rate of the trained policy over
``--eval-episodes`` episodes on seeds 1000 and up (never used in training).
"""

from __future__ import annotations

import argparse

import numpy as np

import modesuite
from modesuite.sb3 import VecAdapter


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--task", default="MoDe-Franka-Place-v0")
    p.add_argument("--envs", type=int, default=16)
    p.add_argument("--steps", type=int, default=200_000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--eval-episodes", type=int, default=20)
    args = p.parse_args()

    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    # VecMonitor: episode returns and lengths in SB3's logs (ep_rew_mean); VecNormalize:
    # observation and reward scaling (the task's returns are in the thousands)
    env = VecNormalize(VecMonitor(VecAdapter(modesuite.make_vec_env(args.task, args.envs))))
    env.seed(args.seed)
    model = PPO(
        "MlpPolicy",
        env,
        n_steps=64,
        batch_size=256,
        n_epochs=5,
        learning_rate=3e-4,
        gamma=0.99,
        gae_lambda=0.95,
        policy_kwargs={"net_arch": [256, 128, 64]},
        seed=args.seed,
        verbose=1,
    )
    model.learn(total_timesteps=args.steps)

    env.training = False  # freeze the observation statistics for evaluation
    evaluation = modesuite.make_vec_env(args.task, 1, num_threads=1)
    successes = []
    for ep in range(args.eval_episodes):
        obs, _ = evaluation.reset(seed=1000 + ep)
        while True:
            action, _ = model.predict(env.normalize_obs(obs), deterministic=True)
            obs, _, term, trunc, info = evaluation.step(action)
            if term[0] or trunc[0]:
                successes.append(bool(info["final_info"].get("is_success", [False])[0]))
                break
    print(f"success {np.mean(successes):.2f} over {len(successes)} episodes (seeds 1000+)")


if __name__ == "__main__":
    main()
