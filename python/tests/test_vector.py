"""The native vector env against Gymnasium's own SyncVectorEnv (issue 27, points 2-5)."""

from __future__ import annotations

import threading
import time

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from gymnasium.wrappers.vector import RecordEpisodeStatistics

import modesuite

N = 4
EPISODE = 25  # env steps per episode in these tests (the scenes' own limits are 600-1500)
STEPS = 55
# a non-finite action ends that env's episode with an error: ends fall on different steps
NAN_AT = {(7, 1), (12, 3)}


def actions_for(space: gym.Space, steps: int, seed: int) -> list[np.ndarray]:
    space.seed(seed)
    out = []
    for t in range(steps):
        a = space.sample()
        for step, env in NAN_AT:
            if step == t and a.dtype.kind == "f":
                a[env] = np.nan
        out.append(a)
    return out


def roll(envs: gym.vector.VectorEnv, actions: list[np.ndarray]) -> list[tuple]:
    out = [envs.reset(seed=11)]
    for a in actions:
        out.append(envs.step(a))
    return out


@pytest.mark.parametrize("task_id", modesuite.TASK_IDS)
def test_make_vec_equals_sync_vector_env(task_id: str) -> None:
    gym_id = f"modesuite/{task_id}"
    native = gym.make_vec(gym_id, num_envs=N, episode_steps=EPISODE, num_threads=2)
    assert isinstance(native, modesuite.ModeSuiteVectorEnv)
    assert native.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP
    sync = SyncVectorEnv(
        [lambda: gym.make(gym_id, episode_steps=EPISODE) for _ in range(N)],
        autoreset_mode=AutoresetMode.SAME_STEP,
    )
    assert native.single_observation_space == sync.single_observation_space
    assert native.single_action_space == sync.single_action_space
    actions = actions_for(native.action_space, STEPS, seed=5)
    got, want = roll(native, actions), roll(sync, actions)
    ends = np.zeros(N, dtype=int)
    for t, (g, w) in enumerate(zip(got, want)):
        assert len(g) == len(w)
        for k, (a, b) in enumerate(zip(g, w)):
            assert data_equivalence(a, b, exact=True), f"{task_id} step {t} item {k}:\n{a}\n{b}"
        if len(g) == 5:
            ends += g[2] | g[3]
    print(f"{task_id}: episode ends per env {ends.tolist()} (at least 2 each required)")
    assert ends.min() >= 2
    # one thread gives the same bits as two
    one = gym.make_vec(gym_id, num_envs=N, episode_steps=EPISODE, num_threads=1)
    for t, (g, w) in enumerate(zip(roll(one, actions), got)):
        for a, b in zip(g, w):
            assert data_equivalence(a, b, exact=True), f"{task_id} 1 vs 2 threads, step {t}"
    native.close(), sync.close(), one.close()


def test_final_info_reports_how_episodes_end() -> None:
    envs = modesuite.make_vec_env("MoDe-Franka-Place-v0", N, episode_steps=5, num_threads=1)
    envs.reset(seed=0)
    zero = np.zeros(envs.action_space.shape, dtype=np.float32)
    envs.step(zero)
    a = zero.copy()
    a[2] = np.inf
    _, r, term, trunc, info = envs.step(a)
    assert trunc.tolist() == [False, False, True, False] and not term.any()
    assert info["_final_obs"].tolist() == [False, False, True, False]
    assert info["final_obs"][0] is None
    assert info["final_obs"][2].shape == envs.single_observation_space.shape
    fi = info["final_info"]
    assert fi["_ended"].tolist() == [False, False, True, False]
    assert fi["ended"][2] == "error" and "must be finite" in fi["error"][2]
    assert fi["_is_success"][2] and not fi["is_success"][2]
    assert r[2] == 0.0
    for _ in range(3):
        _, _, term, trunc, info = envs.step(zero)
    # the other three reach the time limit together on their step 5
    assert trunc.tolist() == [True, True, False, True]
    assert list(info["final_info"]["ended"][[0, 1, 3]]) == ["time_limit"] * 3


def test_disabled_autoreset_with_reset_mask() -> None:
    envs = modesuite.make_vec_env(
        "MoDe-Franka-Place-v0", 3, episode_steps=3, autoreset_mode=AutoresetMode.DISABLED
    )
    assert envs.metadata["autoreset_mode"] is AutoresetMode.DISABLED
    obs0, _ = envs.reset(seed=1)
    zero = np.zeros(envs.action_space.shape, dtype=np.float32)
    for _ in range(3):
        obs, _, _, trunc, info = envs.step(zero)
    assert trunc.all() and "final_obs" not in info
    with pytest.raises(RuntimeError, match="reset"):
        envs.step(zero)
    mask = np.array([True, False, True])
    obs2, info2 = envs.reset(seed=1, options={"reset_mask": mask})
    # reset envs start over (seed 1 + i as before), env 1 keeps its last observation
    assert np.array_equal(obs2[0], obs0[0]) and np.array_equal(obs2[2], obs0[2])
    assert np.array_equal(obs2[1], obs[1])
    with pytest.raises(RuntimeError, match=r"\[1\]"):
        envs.step(zero)
    envs.reset(options={"reset_mask": np.array([False, True, False])})
    envs.step(zero)


def test_record_episode_statistics_on_the_native_env() -> None:
    envs = RecordEpisodeStatistics(
        modesuite.make_vec_env("MoDe-Franka-Place-v0", 2, episode_steps=6, num_threads=1)
    )
    envs.reset(seed=4)
    envs.action_space.seed(4)
    returns = np.zeros(2)
    for t in range(6):
        _, r, term, trunc, info = envs.step(envs.action_space.sample())
        returns += r
    assert (term | trunc).all()
    ep = info["episode"]
    print(f"episode returns {ep['r']} (summed here {returns}), lengths {ep['l']}")
    assert info["_episode"].all()
    assert np.allclose(ep["r"], returns) and ep["l"].tolist() == [6, 6]
    assert len(envs.return_queue) == 2


def test_no_returned_array_shares_memory() -> None:
    envs = modesuite.make_vec_env("MoDe-Franka-Place-v0", 2, num_threads=1)
    first = envs.reset(seed=0)
    a = np.zeros(envs.action_space.shape, dtype=np.float32)
    results = [first, envs.step(a), envs.step(a)]
    arrays = []

    def collect(x: object) -> None:
        if isinstance(x, np.ndarray) and x.dtype != object:
            arrays.append(x)
        elif isinstance(x, dict):
            for v in x.values():
                collect(v)
        elif isinstance(x, (tuple, list)):
            for v in x:
                collect(v)

    for r in results:
        collect(r)
    print(f"{len(arrays)} arrays checked")
    assert len(arrays) > 20
    for i in range(len(arrays)):
        for j in range(i + 1, len(arrays)):
            assert not np.shares_memory(arrays[i], arrays[j]), (i, j)
    single = modesuite.make_env("MoDe-Franka-Place-v0")
    o1, _ = single.reset(seed=0)
    o2, *_ = single.step(single.action_space.sample())
    assert not np.shares_memory(o1, o2)


def test_the_gil_is_released_while_envs_step() -> None:
    envs = modesuite.make_vec_env("MoDe-Spot-Cover-v0", 8, num_threads=1)
    envs.reset(seed=0)
    a = np.zeros(envs.action_space.shape, dtype=np.float32)
    stamps: list[float] = []
    stop = threading.Event()

    def count() -> None:
        while not stop.is_set():
            stamps.append(time.perf_counter())

    t = threading.Thread(target=count)
    t.start()
    time.sleep(0.02)
    start = time.perf_counter()
    envs.step(a)
    end = time.perf_counter()
    stop.set()
    t.join()
    inside = [s for s in stamps if start <= s <= end]
    # the longest stretch of the step during which the Python thread did not run at all: with
    # the GIL held by the step it is the whole step
    edges = [start, *inside, end]
    gap = max(b - a for a, b in zip(edges, edges[1:]))
    wall = end - start
    print(f"one step of 8 envs took {wall * 1e3:.1f} ms; the Python thread ran {len(inside)} "
          f"times meanwhile, longest pause {gap * 1e3:.1f} ms (tolerance: half the step)")
    assert wall > 0.01
    assert gap < wall / 2
