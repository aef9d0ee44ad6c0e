"""modesuite: mobile manipulation of deformable objects, simulated in Rust.

``import modesuite`` registers the 16 MoDeSuite environments with Gymnasium as
``modesuite/MoDe-<Robot>-<Task>-v0`` (``gymnasium.make`` and ``gymnasium.make_vec``; the vector
form is the native vector env, stepped in Rust). Scene files of your own:
:func:`make_env` and :func:`make_vec_env`.
"""

from __future__ import annotations

import os
from typing import Any, Sequence

# Without a desktop session (no XDG_RUNTIME_DIR: servers, containers, CI) Mesa's Vulkan
# device-select layer probes Wayland and prints "error: XDG_RUNTIME_DIR is invalid" for every
# renderer; modesuite picks its device itself, so the layer is switched off there, as the CLI
# does (unless the user chose a device).
if not any(k in os.environ for k in ("XDG_RUNTIME_DIR", "NODEVICE_SELECT", "MESA_VK_DEVICE_SELECT")):
    os.environ["NODEVICE_SELECT"] = "1"

from . import _core  # noqa: E402
from ._core import Encoder, Policy, PolicyPlayer, SceneError  # noqa: E402
from .envs import OBS_MODES, ModeSuiteEnv, ModeSuiteVectorEnv  # noqa: E402

__all__ = [
    "Encoder",
    "ModeSuiteEnv",
    "ModeSuiteVectorEnv",
    "OBS_MODES",
    "Policy",
    "PolicyPlayer",
    "SceneError",
    "TASK_IDS",
    "make_env",
    "make_vec_env",
    "register_envs",
]

#: The 16 task ids, ``MoDe-<Robot>-<Task>-v0`` (Gymnasium ids: ``modesuite/`` + id).
TASK_IDS: tuple[str, ...] = tuple(_core.task_ids())


def make_env(target: str | os.PathLike, **kwargs: Any) -> ModeSuiteEnv:
    """One env of a task id or a ``*.scene.ron`` file (options: :class:`ModeSuiteEnv`)."""
    return ModeSuiteEnv(target, **kwargs)


def make_vec_env(
    target: str | os.PathLike, num_envs: int = 1, **kwargs: Any
) -> ModeSuiteVectorEnv:
    """``num_envs`` envs of a task id or a ``*.scene.ron`` file stepped in Rust (options:
    :class:`ModeSuiteVectorEnv`)."""
    return ModeSuiteVectorEnv(target, num_envs, **kwargs)


def register_envs(ids: Sequence[str] = TASK_IDS) -> None:
    """Registers ``modesuite/<id>`` with Gymnasium for each task id (done on import)."""
    import gymnasium

    for task_id in ids:
        gym_id = f"modesuite/{task_id}"
        if gym_id in gymnasium.registry:
            continue
        gymnasium.register(
            id=gym_id,
            entry_point="modesuite.envs:ModeSuiteEnv",
            vector_entry_point="modesuite.envs:ModeSuiteVectorEnv",
            max_episode_steps=_core.scene_episode_steps(task_id),
            kwargs={"target": task_id},
        )


register_envs()
