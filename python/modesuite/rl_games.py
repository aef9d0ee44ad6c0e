"""rl_games registration: ``register(name, target, **make_kwargs)`` makes a modesuite vector env
available to rl_games as ``env_name: <name>`` (``vecenv_type`` of the same name).

rl_games is not a dependency of modesuite: it is imported by :func:`register` only::

    import modesuite.rl_games
    modesuite.rl_games.register("mode_place", "MoDe-Franka-Place-v0")
    # in the rl_games config: params.config.env_name: mode_place, num_actors: 16

The env follows rl_games' ``IVecEnv``: ``step`` returns ``(obs, rewards, dones, infos)`` with
``infos["time_outs"]`` (the episode hit its time limit: rl_games' ``value_bootstrap`` reads it;
an episode ended by an error is not bootstrapped)
and the batched modesuite infos; the observation is the next episode's first where an episode
ended (same-step autoreset; rl_games does not read final observations).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .envs import ModeSuiteVectorEnv

__all__ = ["RlGamesVecEnv", "register"]


class RlGamesVecEnv:
    """rl_games' ``IVecEnv`` over a :class:`~modesuite.ModeSuiteVectorEnv`."""

    def __init__(self, target: str, num_actors: int, **make_kwargs: Any) -> None:
        self.env = ModeSuiteVectorEnv(target, num_actors, **make_kwargs)
        self._seed: int | None = None

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, dict[str, Any]]:
        if hasattr(actions, "detach"):  # a torch tensor
            actions = actions.detach().cpu().numpy()
        obs, rewards, terminated, truncated, infos = self.env.step(actions)
        ended = infos.get("final_info", {}).get("ended")
        infos["time_outs"] = (
            np.zeros_like(truncated) if ended is None else truncated & (ended == "time_limit")
        )
        return obs, rewards.astype(np.float32), terminated | truncated, infos

    def reset(self) -> Any:
        obs, _ = self.env.reset(seed=self._seed)
        self._seed = None
        return obs

    def seed(self, seed: int) -> None:
        self._seed = int(seed)

    def get_number_of_agents(self) -> int:
        return 1

    def has_action_masks(self) -> bool:
        return False

    def get_env_info(self) -> dict[str, Any]:
        return {
            "observation_space": self.env.single_observation_space,
            "action_space": self.env.single_action_space,
            "agents": 1,
            "value_size": 1,
        }

    def set_train_info(self, env_frames: int, *args: Any, **kwargs: Any) -> None:
        pass

    def get_env_state(self) -> None:
        return None

    def set_env_state(self, env_state: Any) -> None:
        pass

    def close(self) -> None:
        self.env.close()


def register(name: str, target: str, **make_kwargs: Any) -> None:
    """Registers ``name`` with rl_games' ``vecenv`` and ``env_configurations`` so a config
    with ``env_name: <name>`` trains on ``target`` (a task id or scene file)."""
    try:
        from rl_games.common import env_configurations, vecenv
    except ImportError as e:  # pragma: no cover - depends on the user's installation
        raise ImportError("modesuite.rl_games needs rl_games: pip install rl-games") from e
    vecenv.register(
        name,
        lambda config_name, num_actors, **kwargs: RlGamesVecEnv(
            target, num_actors, **{**make_kwargs, **kwargs}
        ),
    )
    env_configurations.register(name, {"vecenv_type": name, "env_creator": lambda **kw: None})
