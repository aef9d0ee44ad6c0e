"""Stable-Baselines3 adapter: ``VecAdapter(venv)`` is an SB3 ``VecEnv`` over a
:class:`~modesuite.ModeSuiteVectorEnv` (same-step autoreset).

SB3 is not a dependency of modesuite: it is imported when ``VecAdapter`` is first used.
Per-env infos follow SB3's conventions: ``terminal_observation`` (the last observation of a
finished episode; the returned observation is already the next episode's first),
``TimeLimit.truncated`` (the episode hit its time limit: SB3 bootstraps from it; an episode
ended by an error is not bootstrapped) and
``is_success``, plus modesuite's own keys (``ended``, ``error``, ``values``...)::

    import modesuite
    from modesuite.sb3 import VecAdapter
    from stable_baselines3 import PPO
    env = VecAdapter(modesuite.make_vec_env("MoDe-Franka-Place-v0", 16))
    PPO("MlpPolicy", env).learn(100_000)
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from gymnasium.vector import AutoresetMode

__all__ = ["VecAdapter", "unbatch_infos"]


def _row(value: Any, i: int) -> Any:
    if isinstance(value, dict):
        return {
            k: _row(v, i)
            for k, v in value.items()
            if not k.startswith("_") and (f"_{k}" not in value or value[f"_{k}"][i])
        }
    item = value[i]
    return item.item() if isinstance(item, np.generic) else item


def unbatch_infos(infos: dict[str, Any], num_envs: int) -> list[dict[str, Any]]:
    """Gymnasium's batched info dict (arrays with ``_key`` masks) as one dict per env, keeping
    only the keys each env reported."""
    out: list[dict[str, Any]] = [{} for _ in range(num_envs)]
    for key, value in infos.items():
        if key.startswith("_"):
            continue
        mask = infos.get(f"_{key}")
        for i in range(num_envs):
            if mask is None or mask[i]:
                out[i][key] = _row(value, i)
    return out


def sb3_step(
    step: tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]], num_envs: int
) -> tuple[Any, np.ndarray, np.ndarray, list[dict[str, Any]]]:
    """A same-step vector env's ``step`` result in SB3's form: ``(obs, rewards float32, dones,
    infos list)`` with ``terminal_observation`` and ``TimeLimit.truncated`` where episodes
    ended."""
    obs, rewards, terminated, truncated, infos = step
    dones = terminated | truncated
    out = unbatch_infos(infos, num_envs)
    final_obs = infos.get("final_obs")
    for i in np.flatnonzero(dones):
        info = out[i]
        final = info.pop("final_info", {})
        info.pop("final_obs", None)
        info.update(final)
        info["terminal_observation"] = final_obs[i]
        # only the time limit is a cut that the value should bootstrap over; an episode ended
        # by an error (a physics blow-up, a bad action) is not continued in the value estimate
        info["TimeLimit.truncated"] = bool(truncated[i] and info.get("ended") == "time_limit")
    return obs, rewards.astype(np.float32), dones, out


class _Logic:
    """The adapter's behaviour; the SB3 base class is mixed in when first used."""

    def __init__(self, venv: Any) -> None:
        if venv.metadata.get("autoreset_mode") is not AutoresetMode.SAME_STEP:
            raise ValueError("VecAdapter needs a vector env with AutoresetMode.SAME_STEP")
        self.venv = venv
        self._actions: np.ndarray | None = None
        super().__init__(  # type: ignore[call-arg]
            num_envs=venv.num_envs,
            observation_space=venv.single_observation_space,
            action_space=venv.single_action_space,
        )

    def reset(self) -> Any:
        seeds = list(getattr(self, "_seeds", [None] * self.num_envs))
        obs, infos = self.venv.reset(seed=seeds if any(s is not None for s in seeds) else None)
        self.reset_infos = unbatch_infos(infos, self.num_envs)
        if hasattr(self, "_reset_seeds"):
            self._reset_seeds()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> tuple[Any, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        return sb3_step(self.venv.step(self._actions), self.num_envs)

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self.venv, attr_name) for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *args: Any, indices: Any = None, **kwargs: Any) -> list[Any]:
        return [getattr(self.venv, method_name)(*args, **kwargs) for _ in self._indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False for _ in self._indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        frames = self.venv.render()
        return list(frames) if frames is not None else [None] * self.num_envs

    def _indices(self, indices: Any) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices)


_CLASS: type | None = None


def _adapter_class() -> type:
    global _CLASS
    if _CLASS is None:
        try:
            from stable_baselines3.common.vec_env import VecEnv
        except ImportError as e:  # pragma: no cover - depends on the user's installation
            raise ImportError(
                "modesuite.sb3.VecAdapter needs stable-baselines3: pip install stable-baselines3"
            ) from e
        _CLASS = type("VecAdapter", (_Logic, VecEnv), {"__doc__": __doc__})
    return _CLASS


def __getattr__(name: str) -> Any:
    if name == "VecAdapter":
        return _adapter_class()
    raise AttributeError(name)
