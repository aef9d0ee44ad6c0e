"""The Stable-Baselines3 and rl_games adapters' conventions (their libraries need torch, which
CI does not install: the adapters' logic is tested over a stand-in base class)."""

from __future__ import annotations

import numpy as np

import modesuite
from modesuite import sb3
from modesuite.rl_games import RlGamesVecEnv


class FakeSb3Base:
    """What SB3's VecEnv base sets up, for the adapter's logic."""

    def __init__(self, num_envs, observation_space, action_space) -> None:
        self.num_envs = num_envs
        self.observation_space = observation_space
        self.action_space = action_space
        self._seeds = [None] * num_envs

    def seed(self, seed: int) -> list[int]:
        self._seeds = [seed + i for i in range(self.num_envs)]
        return self._seeds

    def _reset_seeds(self) -> None:
        self._seeds = [None] * self.num_envs

    def step(self, actions):
        self.step_async(actions)
        return self.step_wait()


class Adapter(sb3._Logic, FakeSb3Base):
    pass


def test_sb3_infos_carry_terminal_observation_and_time_limit() -> None:
    venv = modesuite.make_vec_env("MoDe-Franka-Place-v0", 3, episode_steps=4, num_threads=1)
    env = Adapter(venv)
    env.seed(7)
    obs = env.reset()
    assert obs.shape == (3, *venv.single_observation_space.shape)
    a = np.zeros((3, *venv.single_action_space.shape), dtype=np.float32)
    obs, rewards, dones, infos = env.step(a)
    assert not dones.any() and "terminal_observation" not in infos[0]
    a[1, 0] = np.nan
    obs, rewards, dones, infos = env.step(a)
    assert rewards.dtype == np.float32 and dones.tolist() == [False, True, False]
    # an error is not a time limit: SB3 does not bootstrap over it
    assert infos[1]["ended"] == "error" and infos[1]["TimeLimit.truncated"] is False
    assert infos[1]["terminal_observation"].shape == venv.single_observation_space.shape
    assert infos[1]["is_success"] is False
    for _ in range(2):
        obs, rewards, dones, infos = env.step(np.zeros_like(a))
    assert dones.tolist() == [True, False, True]
    assert infos[0]["ended"] == "time_limit" and infos[0]["TimeLimit.truncated"] is True
    assert isinstance(infos[0]["values"], dict) and infos[0]["values"]
    # the returned observation is the next episode's first, the terminal one differs
    assert not np.array_equal(obs[0], infos[0]["terminal_observation"])


def test_unbatch_infos_keeps_only_reported_keys() -> None:
    infos = {
        "a": np.array([1.0, 2.0]),
        "_a": np.array([True, False]),
        "d": {"x": np.array([True, False]), "_x": np.array([False, True])},
        "_d": np.array([True, True]),
    }
    rows = sb3.unbatch_infos(infos, 2)
    assert rows == [{"a": 1.0, "d": {}}, {"d": {"x": False}}]


def test_rl_games_vec_env_reports_time_outs() -> None:
    env = RlGamesVecEnv("MoDe-Franka-Place-v0", 2, episode_steps=2, num_threads=1)
    info = env.get_env_info()
    assert info["agents"] == 1 and info["value_size"] == 1
    assert info["action_space"] == env.env.single_action_space
    env.seed(3)
    env.reset()
    a = np.zeros((2, *info["action_space"].shape), dtype=np.float32)
    env.step(a)
    obs, rewards, dones, infos = env.step(a)
    assert dones.all() and infos["time_outs"].all()
    assert rewards.dtype == np.float32
