"""Scale-out on Ray (issue 32): RayVectorEnv against the local vector env, worker faults, and
distributed evaluation against ``modesuite run --json``. A local Ray instance of 2 CPUs is
started by the module's fixture."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import ray
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.vector import AutoresetMode

import modesuite
from modesuite.ray import ExpertPolicy, RayVectorEnv, TrainedPolicy, evaluate

TASK = "MoDe-Franka-Place-v0"
N = 5  # uneven shards over two workers: 3 + 2
EPISODE = 25
STEPS = 60
NAN_AT = {(7, 1), (12, 3), (30, 4)}  # (step, env): episodes end on different steps


@pytest.fixture(scope="module", autouse=True)
def local_ray() -> Any:
    ray.init(num_cpus=2, include_dashboard=False, object_store_memory=100 * 2**20)
    yield
    ray.shutdown()


def actions_for(envs: Any, steps: int, seed: int) -> list[np.ndarray]:
    envs.action_space.seed(seed)
    out = []
    for t in range(steps):
        a = envs.action_space.sample()
        for step, env in NAN_AT:
            if step == t and env < envs.num_envs:
                a[env] = np.nan
        out.append(a)
    return out


def rows(x: Any, idx: list[int]) -> Any:
    """Entries ``idx`` of a batched result (arrays, and infos with their masks)."""
    if isinstance(x, dict):
        return {k: rows(v, idx) for k, v in x.items()}
    return np.asarray(x)[idx]


@pytest.mark.parametrize("workers", [1, 2])
@pytest.mark.parametrize("mode", [AutoresetMode.SAME_STEP, AutoresetMode.DISABLED])
def test_ray_vector_env_equals_the_local_vector_env(workers: int, mode: AutoresetMode) -> None:
    kw = dict(episode_steps=EPISODE, num_threads=1, autoreset_mode=mode)
    local = modesuite.make_vec_env(TASK, N, **kw)
    remote = RayVectorEnv(TASK, N, workers, **kw)
    try:
        assert remote.shard_sizes == ([5] if workers == 1 else [3, 2])
        assert remote.single_observation_space == local.single_observation_space
        assert remote.single_action_space == local.single_action_space
        assert remote.metadata == local.metadata
        ends = 0
        got, want = remote.reset(seed=11), local.reset(seed=11)
        assert data_equivalence(got, want, exact=True)
        for t, a in enumerate(actions_for(local, STEPS, seed=5)):
            got, want = remote.step(a), local.step(a)
            assert data_equivalence(got, want, exact=True), f"step {t}:\n{got}\n{want}"
            done = got[2] | got[3]
            ends += int(done.sum())
            if mode == AutoresetMode.DISABLED and done.any():
                opts = {"reset_mask": done}
                got, want = remote.reset(seed=100 + t, options=opts), local.reset(
                    seed=100 + t, options=opts
                )
                assert data_equivalence(got, want, exact=True), f"reset after step {t}"
        assert remote.state_hashes() == local.state_hashes()
        assert np.array_equal(remote.expert_actions(), local.expert_actions())
        print(f"{workers} workers, {mode}: {ends} episode ends over {STEPS} steps, all equal")
        assert ends >= 2 * N
        assert remote.restarts == [0] * workers
    finally:
        remote.close()


def test_a_killed_worker_is_restarted_and_flagged() -> None:
    kw = dict(episode_steps=EPISODE, num_threads=1)
    local = modesuite.make_vec_env(TASK, 4, **kw)
    remote = RayVectorEnv(TASK, 4, 2, **kw)
    ours = [0, 1]  # the envs of worker 0, which lives on
    try:
        actions = actions_for(local, 40, seed=7)
        want_obs, _ = local.reset(seed=3)
        got_obs, _ = remote.reset(seed=3)
        pid = remote.worker_pids()[1]
        for t, a in enumerate(actions):
            last = got_obs
            if t == 10:
                # killed in the middle of its step
                remote._hang_next_step(1, 3.0)
                threading.Timer(0.5, os.kill, (pid, signal.SIGKILL)).start()
            got = remote.step(a)
            want = local.step(a)
            got_obs = got[0]
            for k in range(4):
                assert data_equivalence(rows(got[k], ours), rows(want[k], ours), exact=True), t
            info = got[4]
            if t == 10:
                assert info["worker_restarted"].tolist() == [False, False, True, True]
                assert info["_worker_restarted"].tolist() == [False, False, True, True]
                assert got[3][2:].all() and not got[2][2:].any() and (got[1][2:] == 0).all()
                for i in (2, 3):
                    assert np.array_equal(info["final_obs"][i], last[i])
                    assert info["final_info"]["ended"][i] == "error"
                    assert "worker 1 died" in info["final_info"]["error"][i]
                assert remote.restarts == [0, 1]
                print("restarted worker:", info["final_info"]["error"][2])
            else:
                assert "worker_restarted" not in info, t
        assert remote.worker_pids()[1] != pid
        assert np.isfinite(got_obs).all()
    finally:
        remote.close()


def test_a_hung_worker_is_restarted_after_the_timeout() -> None:
    remote = RayVectorEnv(TASK, 2, 2, episode_steps=EPISODE, num_threads=1, step_timeout=3.0)
    try:
        remote.reset(seed=0)
        a = np.zeros(remote.action_space.shape, np.float32)
        remote._hang_next_step(0, 120.0)
        start = time.monotonic()
        _, _, _, truncated, info = remote.step(a)
        took = time.monotonic() - start
        print(f"hung worker replaced after {took:.1f} s (timeout 3 s)")
        assert took < 60.0
        assert info["worker_restarted"].tolist() == [True, False]
        assert truncated.tolist() == [True, False]
        assert "no answer within step_timeout = 3.0 s" in info["final_info"]["error"][0]
        remote.step(a)
        assert remote.restarts == [1, 0]
    finally:
        remote.close()


def test_bad_targets_and_options_are_clear_errors() -> None:
    with pytest.raises(ValueError, match="MoDe-Nope-Task-v0"):
        RayVectorEnv("MoDe-Nope-Task-v0", 2, 1)
    with pytest.raises(ValueError, match="num_workers = 3: at most num_envs = 2"):
        RayVectorEnv(TASK, 2, 3)
    with pytest.raises(ValueError, match="step_timeout"):
        RayVectorEnv(TASK, 2, 1, step_timeout=0)


def run_json(
    binary: Path, target: str, episodes: int, policy: str = "scripted", seed: int = 0
) -> dict[str, Any]:
    out = subprocess.run(
        [str(binary), "run", target, "--policy", policy, "--episodes", str(episodes)]
        + ["--seed", str(seed), "--json"],
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_evaluate_reproduces_run_json_for_the_scripted_expert(modesuite_bin: Path) -> None:
    targets = ["MoDe-Franka-Place-v0", "MoDe-Spot-Place-v0"]
    got = evaluate(ExpertPolicy(), targets, episodes=20, num_workers=2)
    for t in targets:
        want = run_json(modesuite_bin, t, 20)
        print(f"{t}: evaluate {got[t]}\n{' ' * len(t)}  run      {want}")
        for key in want:
            if key != "env_steps_per_s":
                assert got[t][key] == want[key], (t, key)


def test_evaluate_a_shipped_trained_policy_as_run_does(root: Path, modesuite_bin: Path) -> None:
    folder = root / "policies/ppo/MoDe-Franka-Place-v0"
    policy = TrainedPolicy(folder)
    got = evaluate(policy, policy.target, episodes=6, num_workers=2, seed=1_000_000,
                   actions=policy.actions)[policy.target]
    want = run_json(modesuite_bin, policy.target, 6, policy=str(folder), seed=1_000_000)
    print(f"trained PPO: evaluate {got}\n             run      {want}")
    for key in want:
        if key != "env_steps_per_s":
            assert got[key] == want[key], key
    with pytest.raises(modesuite.SceneError, match="not a policy folder"):
        TrainedPolicy(root / "scenes")


def test_evaluate_reports_a_failing_policy_as_errors() -> None:
    def broken(obs: Any) -> Any:
        raise KeyError("no such joint")

    got = evaluate(broken, TASK, episodes=3, num_workers=1, return_episodes=True)[TASK]
    assert got["errors"] == 3 and got["ended"] == {"error": 3}
    assert got["episode_results"][0]["error"] == "policy: 'no such joint'"
