"""Steps/s of the native vector env driven from Python, against gymnasium's AsyncVectorEnv of
single envs (subprocesses) and against the Rust VecEnv stepping the same actions with no
Python in the loop (the binding's overhead). Issue 27's benchmark; BENCHMARKS.md records it.

    scripts/python.sh --release   # or: pip install .   (a release build)
    python examples/python/bench_vector.py [--task MoDe-Franka-Place-v0] [--envs 16] [--steps 300]

Prints one JSON object per case (``case``, ``steps_per_s`` = env steps per second summed over
envs, ``envs``, ``threads``) and the load average.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import gymnasium as gym
import numpy as np

import modesuite


def actions_for(space: gym.spaces.Box, steps: int, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(space.low, space.high, size=(steps, n, *space.shape)).astype(np.float32)


def timed_steps(envs: gym.vector.VectorEnv, actions: np.ndarray) -> float:
    """Env steps per second of ``envs`` driven from Python through ``actions``; closes it."""
    envs.reset(seed=0)
    start = time.perf_counter()
    for a in actions:
        envs.step(a)
    wall = time.perf_counter() - start
    envs.close()
    return len(actions) * envs.num_envs / wall


def native_python(task: str, n: int, threads: int, actions: np.ndarray) -> float:
    return timed_steps(gym.make_vec(f"modesuite/{task}", num_envs=n, num_threads=threads), actions)


def native_rust(task: str, n: int, threads: int, actions: np.ndarray) -> float:
    envs = modesuite.make_vec_env(task, n, num_threads=threads)
    envs.reset(seed=0)
    wall, _ = envs._core.rollout(actions)
    return len(actions) * n / wall


def binding_us_per_step(n: int, steps: int = 2000, repeats: int = 5) -> tuple[float, float]:
    """Microseconds per vector step through ``step()`` and through ``rollout()`` (no Python in
    the loop) of ``n`` envs of the drop scene, which has almost no physics: the difference is
    what the binding costs per step (argument checks, conversions, info dicts)."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    envs = modesuite.make_vec_env(os.path.join(root, "scenes/examples/drop.scene.ron"), n, num_threads=1)
    a = np.zeros((n, 0), np.float32)
    best_py = best_rs = float("inf")
    for _ in range(repeats):
        envs.reset(seed=0)
        t = time.perf_counter()
        for _ in range(steps):
            envs.step(a)
        best_py = min(best_py, (time.perf_counter() - t) / steps)
        envs.reset(seed=0)
        wall, _ = envs._core.rollout(np.zeros((steps, n, 0), np.float32))
        best_rs = min(best_rs, wall / steps)
    return best_py * 1e6, best_rs * 1e6


def gym_async(task: str, n: int, actions: np.ndarray) -> float:
    return timed_steps(gym.make_vec(f"modesuite/{task}", num_envs=n, vectorization_mode="async"), actions)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", default="MoDe-Franka-Place-v0")
    p.add_argument("--envs", type=int, default=16)
    p.add_argument("--steps", type=int, default=300)
    p.add_argument("--threads", type=int, default=0, help="0: all cores")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--skip-async", action="store_true")
    args = p.parse_args()
    probe = modesuite.make_env(args.task)
    actions = actions_for(probe.action_space, args.steps, args.envs, seed=0)
    threads = modesuite.make_vec_env(args.task, 1, num_threads=args.threads).num_threads
    cases = {"native_python": [], "rust_vecenv": [], "gym_async": []}
    for _ in range(args.repeats):
        cases["rust_vecenv"].append(native_rust(args.task, args.envs, args.threads, actions))
        cases["native_python"].append(native_python(args.task, args.envs, args.threads, actions))
        if not args.skip_async:
            cases["gym_async"].append(gym_async(args.task, args.envs, actions))
    best = {k: max(v) for k, v in cases.items() if v}
    py_us, rs_us = binding_us_per_step(args.envs)
    vec_step_us = 1e6 * args.envs / best["rust_vecenv"]
    print(json.dumps({
        "case": "binding_us_per_step", "envs": args.envs, "python_us": round(py_us, 1),
        "rust_us": round(rs_us, 1), "binding_us": round(py_us - rs_us, 1),
        "share_of_task_step_pct": round(100 * (py_us - rs_us) / vec_step_us, 2),
    }))
    for case, rates in cases.items():
        if not rates:
            continue
        print(json.dumps({
            "case": case, "task": args.task, "steps_per_s": round(best[case], 1),
            "runs": [round(r, 1) for r in rates], "envs": args.envs,
            "threads": 1 if case == "gym_async" else threads, "steps": args.steps,
        }))
    print(json.dumps({
        "summary": True,
        "binding_overhead_pct": round(100 * (best["rust_vecenv"] / best["native_python"] - 1), 2),
        "speedup_vs_async": round(best["native_python"] / best["gym_async"], 2) if "gym_async" in best else None,
        "loadavg": os.getloadavg(),
    }))


if __name__ == "__main__":
    main()
