"""Type stub of the extension module ``modesuite._core`` (written by hand)."""

from typing import Any

import numpy as np
import numpy.typing as npt

class SceneError(ValueError):
    """Bad input: a scene or task file (the message carries file:line:col), an unknown task
    id, a bad option value."""

class Core:
    """N environments of one target stepped together on the Rust thread pool."""

    def __init__(
        self,
        target: str,
        num_envs: int = 1,
        threads: int = 1,
        actions: str | None = None,
        rgbd: str | None = None,
        plugins: list[str] = ...,
        episode_steps: int | None = None,
        autoreset: bool = True,
    ) -> None: ...
    @property
    def num_envs(self) -> int: ...
    @property
    def threads(self) -> int: ...
    @property
    def episode_steps(self) -> int | None: ...
    @property
    def target(self) -> str: ...
    @property
    def step_dt(self) -> float: ...
    def spaces(self) -> dict[str, Any]: ...
    def reset(
        self, seeds: list[int | None], mask: list[bool] | None = None
    ) -> tuple[Any, dict[str, Any]]: ...
    def reset_one(self, seed: int | None = None) -> tuple[Any, dict[str, Any]]: ...
    def step(
        self, actions: npt.NDArray[np.float32]
    ) -> tuple[
        Any,
        npt.NDArray[np.float64],
        npt.NDArray[np.bool_],
        npt.NDArray[np.bool_],
        dict[str, Any],
    ]: ...
    def step_one(
        self, action: npt.NDArray[np.float32]
    ) -> tuple[Any, float, bool, bool, dict[str, Any]]: ...
    def expert_actions(self) -> npt.NDArray[np.float32]: ...
    def render(
        self, index: int = 0, width: int = 480, height: int = 320
    ) -> npt.NDArray[np.uint8]: ...
    def rollout(
        self, actions: npt.NDArray[np.float32]
    ) -> tuple[float, npt.NDArray[np.float64]]: ...
    def state_hashes(self) -> list[int]: ...
    def dump_state(self, index: int = 0) -> str: ...

def task_ids() -> list[str]: ...
def scene_episode_steps(target: str) -> int | None: ...
