"""Gymnasium's own environment checker on every environment (issue 27, point 1)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import modesuite


def test_sixteen_ids_are_registered() -> None:
    ids = sorted(i for i in gym.registry if i.startswith("modesuite/"))
    assert len(ids) == 16, ids
    # the registry's ids and the task ids are the same set, each with its scene's time limit
    assert {i.removeprefix("modesuite/") for i in ids} == set(modesuite.TASK_IDS)
    assert gym.spec("modesuite/MoDe-Franka-Place-v0").max_episode_steps == 600
    assert gym.spec("modesuite/MoDe-Spot-Drag-v0").max_episode_steps == 1500


# State observations (positions, velocities, distances) are unbounded and depth is unbounded
# above: the checker's advice about infinite Box bounds is expected, every other warning fails.
UNBOUNDED = pytest.mark.filterwarnings(
    "ignore:.*A Box observation space (minimum|maximum) value is (-)?infinity"
)


@UNBOUNDED
@pytest.mark.parametrize("task_id", modesuite.TASK_IDS)
def test_check_env_state(task_id: str) -> None:
    env = gym.make(f"modesuite/{task_id}")
    check_env(env.unwrapped, skip_render_check=True)
    assert env.observation_space.dtype == np.float32
    assert isinstance(env.action_space, gym.spaces.Box)
    env.close()


@UNBOUNDED
def test_check_env_rgbd_with_render() -> None:
    env = gym.make("modesuite/MoDe-Franka-Place-v0", obs_mode="rgbd", render_mode="rgb_array")
    check_env(env.unwrapped)
    space = env.observation_space
    assert isinstance(space, gym.spaces.Dict)
    assert space["robot_rgb"].shape == (128, 128, 3)
    assert space["robot_rgb"].dtype == np.uint8
    assert space["robot_depth"].shape == (128, 128, 1)
    assert space["robot_depth"].dtype == np.float32
    obs, _ = env.reset(seed=3)
    rgb, depth = obs["robot_rgb"], obs["robot_depth"]
    # a real image: not blank, depth in metres in front of the camera
    print(f"rgb mean {rgb.mean():.1f} std {rgb.std():.1f}; depth {depth.min():.3f}..{depth.max():.3f} m")
    assert rgb.std() > 5.0
    assert 0.0 <= depth.min() and 0.1 < depth.max() < 50.0
    frame = env.render()
    assert frame.shape == (320, 480, 3) and frame.dtype == np.uint8 and frame.std() > 5.0
    env.close()


@UNBOUNDED
def test_discrete_actions_check_env() -> None:
    env = gym.make("modesuite/MoDe-Spot-Uncover-v0", actions="(discrete: true)")
    assert env.action_space == gym.spaces.Discrete(14)
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_rendering_headless_prints_nothing_to_stderr() -> None:
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("XDG_RUNTIME_DIR", "NODEVICE_SELECT")}
    code = (
        "import modesuite\n"
        "e = modesuite.make_env('MoDe-Franka-Place-v0', obs_mode='rgbd', render_mode='rgb_array')\n"
        "e.reset(seed=0)\n"
        "assert e.render().shape == (320, 480, 3)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stderr == "", out.stderr
