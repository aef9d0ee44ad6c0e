"""User scene files, compiled plugins and the scripted experts through Python."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import modesuite


def test_a_scene_file_without_task(root: Path) -> None:
    env = modesuite.make_env(root / "scenes/examples/drop.scene.ron")
    obs, info = env.reset(seed=0)
    assert info == {}
    assert env.action_space.shape == (0,)
    z0 = json.loads(env.dump_state())["objects"]["box"]["position"][2]
    for _ in range(30):
        obs, reward, terminated, truncated, info = env.step(np.zeros(0, dtype=np.float32))
    z1 = json.loads(env.dump_state())["objects"]["box"]["position"][2]
    print(f"the box fell from z = {z0:.3f} to {z1:.3f} m in 30 steps")
    assert z1 < z0 - 0.05
    assert "success" not in info


def test_a_compiled_plugin_by_path(root: Path, plugin_dir: Path) -> None:
    lib = plugin_dir / "libplugin_trefoil.so"
    assert lib.is_file(), f"{lib}: build it with cargo build -p plugin-trefoil"
    scene = root / "examples/plugin-trefoil/trefoil.scene.ron"
    with pytest.raises(modesuite.SceneError, match="trefoil"):
        modesuite.make_env(scene)  # the scene names the plugin's shape; nothing loads it
    env = modesuite.make_env(scene, plugins=[lib])
    env.reset(seed=0)
    _, reward, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    print(f"reward with the plugin's terms: {reward:.4f}; values {sorted(info['values'])}")
    assert any(k.startswith("reward/") for k in info["values"])
    venv = modesuite.make_vec_env(scene, 2, plugins=[lib], num_threads=1)
    venv.reset(seed=0)
    venv.step(np.zeros(venv.action_space.shape, dtype=np.float32))


def test_the_scripted_expert_succeeds_through_python() -> None:
    env = gym.make("modesuite/MoDe-Franka-Place-v0")
    obs, _ = env.reset(seed=0)
    for t in range(600):
        obs, reward, terminated, truncated, info = env.step(env.unwrapped.expert_action())
        if terminated or truncated:
            break
    print(f"expert episode: {t + 1} steps, ended {info['ended']}, is_success {info['is_success']}")
    assert info["ended"] == "success" and info["is_success"] is True


def test_experts_of_a_vector_env_match_single_envs() -> None:
    venv = modesuite.make_vec_env("MoDe-Franka-Drag-v0", 2, num_threads=2)
    venv.reset(seed=3)
    singles = [modesuite.make_env("MoDe-Franka-Drag-v0") for _ in range(2)]
    for i, e in enumerate(singles):
        e.reset(seed=3 + i)
    for _ in range(40):
        a = venv.expert_actions()
        for i, e in enumerate(singles):
            assert np.array_equal(a[i], e.expert_action())
            e.step(a[i])
        venv.step(a)
    assert venv.state_hashes() == [e.state_hash() for e in singles]


def test_the_shipped_drag_policy_drags_the_belt_round_the_post(root: Path) -> None:
    """Issue 29: the shipped PPO Franka Drag policy, from Python, on the first held-out seed:
    success after exactly the 77 steps `modesuite eval` reports (deterministic; 78 before the
    belt's penalty contacts of session 32)."""
    policy = modesuite.Policy(root / "policies/ppo/MoDe-Franka-Drag-v0")
    assert (policy.target, policy.algo) == ("MoDe-Franka-Drag-v0", "ppo")
    env = gym.make(f"modesuite/{policy.target}")
    obs, _ = env.reset(seed=1_000_000)
    steps = 0
    for steps in range(1, 301):
        obs, _, terminated, truncated, info = env.step(policy.act(obs.astype(np.float32)))
        if terminated or truncated:
            break
    print(f"PPO Drag from Python: ended {info['ended']} after {steps} steps (want success, 77)")
    assert (info["ended"], steps) == ("success", 77)


def test_a_shipped_trained_policy_solves_its_task(root: Path) -> None:
    policy = modesuite.Policy(root / "policies/ppo/MoDe-Franka-Place-v0")
    assert (policy.target, policy.algo) == ("MoDe-Franka-Place-v0", "ppo")
    env = gym.make(f"modesuite/{policy.target}")
    obs, _ = env.reset(seed=1_000_000)
    for _ in range(600):
        obs, _, terminated, truncated, info = env.step(policy.act(obs.astype(np.float32)))
        if terminated or truncated:
            break
    print(f"trained PPO policy from Python: ended {info['ended']}")
    assert info["ended"] == "success"
    batch = policy.act(np.zeros((3, policy.obs_dim), np.float32))
    assert batch.shape == (3, policy.act_dim)
    # any numeric array: float64, a strided view, a list, all as their float32 values
    rows = np.random.default_rng(0).normal(size=(3, policy.obs_dim)).astype(np.float32)
    want = policy.act(rows)
    wide = np.zeros((3, 2 * policy.obs_dim), np.float32)
    wide[:, ::2] = rows
    assert np.array_equal(policy.act(wide[:, ::2]), want)
    assert np.array_equal(policy.act(rows.astype(np.float64)), want)
    assert np.array_equal(policy.act(np.asfortranarray(rows)), want)
    assert np.array_equal(policy.act(rows[1].tolist()), want[1])
    with pytest.raises(ValueError, match="expected"):
        policy.act(np.zeros(policy.obs_dim + 1, np.float32))
    with pytest.raises(modesuite.SceneError, match="not a policy folder"):
        modesuite.Policy(root / "scenes")


def test_a_saved_state_continues_bit_exactly_in_a_new_env(tmp_path: Path) -> None:
    """save_state -> bytes -> file -> load_state in another env: the next 30 steps are the
    same as those of the env that saved it (a plugin-less FEM task, varied actions)."""
    env = gym.make("modesuite/MoDe-Franka-Bend-v0").unwrapped
    env.reset(seed=4)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, size=(60,) + env.action_space.shape).astype(np.float32)
    for a in actions[:30]:
        env.step(a)
    path = tmp_path / "bend.state"
    path.write_bytes(env.save_state())
    straight = [env.step(a) for a in actions[30:]]

    other = gym.make("modesuite/MoDe-Franka-Bend-v0").unwrapped
    other.reset(seed=99)
    obs = other.load_state(path.read_bytes())
    resumed = [other.step(a) for a in actions[30:]]
    same = all(
        np.array_equal(x[0], y[0]) and x[1] == y[1] and x[2:4] == y[2:4]
        for x, y in zip(straight, resumed)
    )
    print(f"state file {path.stat().st_size // 1024} kB; 30 resumed steps identical: {same}")
    assert obs.shape == env.observation_space.shape
    assert same
    assert other.state_hash() == env.state_hash()

    place = gym.make("modesuite/MoDe-Franka-Place-v0").unwrapped
    place.reset(seed=0)
    before = place.state_hash()
    with pytest.raises(ValueError, match="another env"):
        place.load_state(path.read_bytes())
    with pytest.raises(ValueError, match="not a modesuite state file"):
        place.load_state(b"hello")
    assert place.state_hash() == before
