"""Random calls through the Python API (issue 33): actions of random shapes, dtypes and values
(NaN, inf, huge, empty), seeds and options of every kind, on a single and a vector env. Every
call either works, with finite observations and rewards, or raises a Python exception of an
expected type; the interpreter never dies. Deterministic (a fixed generator seed)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import modesuite

EXPECTED = (ValueError, TypeError, RuntimeError, OverflowError)
VALUES = [0.0, -0.0, 1.0, -1.0, 0.5, 1e-320, 3.5e38, 1e308, -1e308, math.inf, -math.inf, math.nan]


def random_action(rng: np.random.Generator, shape: tuple[int, ...]):
    kind = rng.integers(8)
    if kind == 0:  # right shape, edge values
        return rng.choice(VALUES, size=shape).astype(np.float64)
    if kind == 1:  # a wrong shape
        return np.zeros(tuple(int(s) + int(rng.integers(-1, 2)) for s in shape) or (1,))
    if kind == 2:  # other dtypes
        return np.zeros(shape, dtype=rng.choice([np.int64, np.uint8, np.float16, np.int8]))
    if kind == 3:  # not an array
        return rng.choice([None, "abc", 3, [1.0] * 3, {"a": 1}], shape=None)
    if kind == 4:  # empty and 0-d
        return rng.choice([np.zeros(0), np.float32(1.0)])
    return rng.uniform(-2.0, 2.0, size=shape).astype(np.float32)


def finite(x) -> bool:
    return bool(np.all(np.isfinite(np.asarray(x, dtype=np.float64))))


def exercise(env, rng: np.random.Generator, steps: int, vector: bool) -> tuple[int, int]:
    ok = refused = 0
    shape = env.action_space.shape
    for _ in range(steps):
        what = rng.integers(10)
        try:
            if what == 0:
                seed = rng.choice([0, 1, 2**31, 2**63 - 1, 2**64, -1, None, 1.5, "x"])
                obs, _ = env.reset(seed=seed)
            elif what == 1:
                obs, _ = env.reset(options=rng.choice([None, {}, {"x": 1}, "opts"]))
            else:
                obs, reward, _, _, _ = env.step(random_action(rng, shape))
                assert finite(reward), reward
            assert finite(obs)
            ok += 1
        except EXPECTED:
            refused += 1
    return ok, refused


@pytest.mark.parametrize("vector", [False, True])
def test_random_calls_work_or_raise(vector: bool) -> None:
    rng = np.random.default_rng(20261127)
    if vector:
        env = modesuite.make_vec_env("MoDe-Franka-Place-v0", 2, num_threads=1)
    else:
        env = modesuite.make_env("MoDe-Franka-Place-v0")
    env.reset(seed=0)
    ok, refused = exercise(env, rng, 300, vector)
    print(f"python API fuzz ({'vector' if vector else 'single'}): {ok} calls worked, {refused} raised an expected exception, 0 crashed")
    assert ok > 50 and refused > 50
    # the env still works afterwards
    env.reset(seed=3)
    obs, *_ = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert finite(obs)
