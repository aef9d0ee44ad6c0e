"""Bad input gets a clear Python exception, never a dead interpreter (issue 27, point 6)."""

from __future__ import annotations

import re
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import modesuite
from modesuite import _core


@pytest.fixture(scope="module")
def env() -> modesuite.ModeSuiteEnv:
    e = modesuite.make_env("MoDe-Franka-Place-v0")
    e.reset(seed=0)
    return e


@pytest.fixture(scope="module")
def venv() -> modesuite.ModeSuiteVectorEnv:
    e = modesuite.make_vec_env("MoDe-Franka-Place-v0", 2, num_threads=1)
    e.reset(seed=0)
    return e


def test_wrong_action_shape_names_the_expected_shape(env, venv) -> None:
    dim = env.action_space.shape[0]
    with pytest.raises(ValueError, match=re.escape(f"shape ({dim},)")):
        env.step(np.zeros(dim + 1, dtype=np.float32))
    with pytest.raises(ValueError, match=re.escape(f"shape (2, {dim})")):
        venv.step(np.zeros((3, dim), dtype=np.float32))
    with pytest.raises(ValueError, match=re.escape(f"shape (2, {dim})")):
        venv.step(np.zeros(2 * dim, dtype=np.float32))


@pytest.mark.parametrize("bad", [np.array(["a"] * 10), np.zeros(10, dtype=complex), np.zeros(10, dtype=bool), [None] * 10])
def test_wrong_action_dtype_is_a_value_error(env, bad) -> None:
    dim = env.action_space.shape[0]
    bad = np.resize(np.asarray(bad), dim)
    with pytest.raises(ValueError, match="float"):
        env.step(bad)


def test_float64_and_int_actions_are_accepted(env) -> None:
    dim = env.action_space.shape[0]
    env.step(np.zeros(dim, dtype=np.float64))
    env.step(np.zeros(dim, dtype=np.int64))
    env.step(list(np.zeros(dim)))


def test_non_finite_action_ends_the_episode_with_an_error() -> None:
    env = modesuite.make_env("MoDe-Franka-Place-v0")
    env.reset(seed=0)
    a = np.zeros(env.action_space.shape, dtype=np.float32)
    env.step(a)
    a[3] = np.nan
    _, reward, terminated, truncated, info = env.step(a)
    print(f"info after a NaN action: {info['error']!r}, ended {info['ended']!r}")
    assert truncated and not terminated and reward == 0.0
    assert info["ended"] == "error" and "[3] = NaN" in info["error"]
    assert info["is_success"] is False
    # the episode is over: a step before reset is refused, a reset starts a clean one
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros_like(a))
    env.reset(seed=0)
    *_, info = env.step(np.zeros_like(a))
    assert "error" not in info


def test_bad_scene_file_raises_with_file_line_col(tmp_path: Path) -> None:
    scene = tmp_path / "bad.scene.ron"
    scene.write_text("(\n    objects: [\n        (name: \"box\", shape: Cube(size: 0.1)),\n    ],\n    nonsense: 3,\n)\n")
    with pytest.raises(modesuite.SceneError) as e:
        modesuite.make_env(scene)
    print(e.value)
    assert re.search(r"bad\.scene\.ron:\d+:\d+", str(e.value)), str(e.value)
    assert isinstance(e.value, ValueError)


def test_unknown_ids_and_options_are_clear_errors() -> None:
    with pytest.raises(modesuite.SceneError, match="MoDe-<Robot>-<Task>-v0"):
        modesuite.make_env("no/such/file.scene.ron")
    with pytest.raises(modesuite.SceneError, match="Franka"):
        modesuite.make_env("MoDe-Franka-Plase-v0")
    with pytest.raises(ValueError, match="obs_mode"):
        modesuite.make_env("MoDe-Franka-Place-v0", obs_mode="pixels")
    with pytest.raises(modesuite.SceneError, match="nope"):
        modesuite.make_env("MoDe-Franka-Place-v0", obs_mode="rgbd:nope")
    with pytest.raises(modesuite.SceneError, match="actions"):
        modesuite.make_env("MoDe-Franka-Place-v0", actions="(arm: Flying)")
    with pytest.raises(ValueError, match="num_envs"):
        modesuite.make_vec_env("MoDe-Franka-Place-v0", 0)
    with pytest.raises(ValueError, match="episode_steps"):
        modesuite.make_env("MoDe-Franka-Place-v0", episode_steps=0)
    with pytest.raises(modesuite.SceneError, match="plugin"):
        modesuite.make_env("MoDe-Franka-Place-v0", plugins=["/no/such/plugin.so"])
    with pytest.raises(ValueError, match="seed"):
        modesuite.make_env("MoDe-Franka-Place-v0").reset(seed=-1)
    with pytest.raises(gym.error.NameNotFound):
        gym.make("modesuite/MoDe-Franka-Fly-v0")


def test_step_before_reset_is_refused() -> None:
    env = modesuite.make_env("MoDe-Franka-Place-v0")
    with pytest.raises(RuntimeError, match="reset"):
        env.step(env.action_space.sample())


def test_a_panic_inside_rust_is_a_python_exception() -> None:
    with pytest.raises(RuntimeError, match="internal error in modesuite"):
        _core._panic_for_test("deliberate")
    # the interpreter and other envs go on
    env = modesuite.make_env("MoDe-Franka-Place-v0")
    env.reset(seed=0)
    env.step(env.action_space.sample())


def test_discrete_actions_out_of_range() -> None:
    env = modesuite.make_env("MoDe-Franka-Place-v0", actions="(discrete: true)")
    env.reset(seed=0)
    env.step(3)
    with pytest.raises(ValueError, match="0..14"):
        env.step(14)
    with pytest.raises(ValueError, match="integer"):
        env.step(1.5)
