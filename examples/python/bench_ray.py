"""Steps/s of RayVectorEnv (envs sharded over Ray actors) against the local vector env, and the
cost of one step's messages, from which BENCHMARKS.md estimates scaling to N nodes. Issue 32's
benchmark.

    scripts/python.sh --release   # a release build of the package, with ray installed
    python examples/python/bench_ray.py [--task MoDe-Franka-Place-v0] [--envs 16] [--workers 2]

Cases (one JSON object each, best of ``--repeats``):
- ``local``: ``make_vec_env(task, envs, num_threads=workers)`` stepped from Python;
- ``ray``: ``RayVectorEnv(task, envs, workers, num_threads=1)``, one core per worker;
- ``message_us``: microseconds per vector step of the drop scene (almost no physics) through
  the local vector env and through RayVectorEnv with 1 and ``workers`` workers: what the Ray
  round trip costs per step, and what each extra worker adds on the driver.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
import ray

import modesuite
from modesuite.ray import RayVectorEnv

ROOT = Path(__file__).resolve().parents[2]


def timed(envs, actions: np.ndarray) -> float:
    """Seconds per vector step of ``envs`` driven through ``actions`` (after one warm step)."""
    envs.reset(seed=0)
    envs.step(actions[0])
    start = time.perf_counter()
    for a in actions[1:]:
        envs.step(a)
    return (time.perf_counter() - start) / (len(actions) - 1)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", default="MoDe-Franka-Place-v0")
    p.add_argument("--envs", type=int, default=16)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--steps", type=int, default=300)
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args()
    ray.init(num_cpus=args.workers, include_dashboard=False, object_store_memory=200 * 2**20)
    n, w = args.envs, args.workers
    probe = modesuite.make_vec_env(args.task, n, num_threads=1)
    rng = np.random.default_rng(0)
    space = probe.single_action_space
    actions = rng.uniform(space.low, space.high, size=(args.steps, n, *space.shape)).astype(np.float32)
    probe.close()
    runs: dict[str, list[float]] = {"local": [], "ray": []}
    for _ in range(args.repeats):
        local = modesuite.make_vec_env(args.task, n, num_threads=w)
        runs["local"].append(n / timed(local, actions))
        local.close()
        remote = RayVectorEnv(args.task, n, w, num_threads=1)
        runs["ray"].append(n / timed(remote, actions))
        remote.close()
    for case, rates in runs.items():
        print(json.dumps({
            "case": case, "task": args.task, "envs": n, "workers": w if case == "ray" else None,
            "threads": w, "steps": args.steps, "steps_per_s": round(max(rates), 1),
            "runs": [round(r, 1) for r in rates],
        }))
    # the messages alone: a scene with almost no physics
    drop = str(ROOT / "scenes/examples/drop.scene.ron")
    zeros = np.zeros((2000, n, 0), np.float32)
    us: dict[str, float] = {}
    for name, make in [
        ("local", lambda: modesuite.make_vec_env(drop, n, num_threads=1)),
        ("ray_1_worker", lambda: RayVectorEnv(drop, n, 1, num_threads=1)),
        (f"ray_{w}_workers", lambda: RayVectorEnv(drop, n, w, num_threads=1)),
    ]:
        best = float("inf")
        for _ in range(args.repeats):
            envs = make()
            best = min(best, timed(envs, zeros))
            envs.close()
        us[name] = round(best * 1e6, 1)
    print(json.dumps({"case": "message_us", "envs": n, "us_per_vector_step": us}))
    print(json.dumps({
        "summary": True,
        "ray_over_local": round(max(runs["ray"]) / max(runs["local"]), 3),
        "round_trip_us": round(us["ray_1_worker"] - us["local"], 1),
        "per_extra_worker_us": round((us[f"ray_{w}_workers"] - us["ray_1_worker"]) / max(w - 1, 1), 1),
        "loadavg": os.getloadavg(),
    }))
    ray.shutdown()


if __name__ == "__main__":
    main()
