"""Gymnasium environments over modesuite's Rust simulator.

:class:`ModeSuiteEnv` is a ``gymnasium.Env`` (one world); :class:`ModeSuiteVectorEnv` is a
``gymnasium.vector.VectorEnv`` whose worlds step together on the Rust thread pool with the GIL
released. Both are made from a task id (``MoDe-<Robot>-<Task>-v0``) or a scene file
(``*.scene.ron``).
"""

from __future__ import annotations

import os
from typing import Any, Sequence

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from . import _core

__all__ = ["ModeSuiteEnv", "ModeSuiteVectorEnv", "OBS_MODES"]

#: Observation modes: ``"state"`` (the task's state vector) or ``"rgbd"`` (a ``Dict`` of the
#: state and the robot camera's image: ``robot_rgb`` uint8 (128, 128, 3) and ``robot_depth``
#: float32 metres (128, 128, 1)). ``"rgbd:<camera>"`` names another camera of the scene.
OBS_MODES = ("state", "rgbd")

_U64 = 2**64


def _rgbd_camera(obs_mode: str) -> str | None:
    if obs_mode == "state":
        return None
    if obs_mode == "rgbd":
        return "robot"
    if isinstance(obs_mode, str) and obs_mode.startswith("rgbd:") and len(obs_mode) > 5:
        return obs_mode[5:]
    raise ValueError(
        f"obs_mode = {obs_mode!r}: 'state', 'rgbd' (the robot camera) or 'rgbd:<camera>'"
    )


def _seed(seed: Any, what: str = "seed") -> int | None:
    if seed is None:
        return None
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"{what} = {seed!r}: an int in 0..2**64 or None")
    seed = int(seed)
    if not 0 <= seed < _U64:
        raise ValueError(f"{what} = {seed}: an int in 0..2**64 or None")
    return seed


def _spaces(core: Any) -> tuple[gym.Space, gym.Space, list[tuple[str, int, int]]]:
    d = core.spaces()
    boxes = {}
    for key, dtype, shape, low, high in d["obs"]:
        boxes[key] = spaces.Box(low=low, high=high, shape=tuple(shape), dtype=np.dtype(dtype))
    obs_space = spaces.Dict(boxes) if d["obs_dict"] else boxes[""]
    if d["act_discrete"] is not None:
        act_space: gym.Space = spaces.Discrete(int(d["act_discrete"]))
    else:
        low = np.asarray(d["act_low"], dtype=np.float32)
        high = np.asarray(d["act_high"], dtype=np.float32)
        act_space = spaces.Box(low=low, high=high, dtype=np.float32)
    return obs_space, act_space, [tuple(p) for p in d["act_parts"]]


def _make_core(
    target: str | os.PathLike,
    num_envs: int,
    threads: int,
    obs_mode: str,
    actions: str | None,
    plugins: Sequence[str | os.PathLike],
    episode_steps: int | None,
    autoreset: bool,
) -> Any:
    if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
        raise ValueError(f"num_envs = {num_envs!r}: an int >= 1")
    if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 0:
        raise ValueError(f"num_threads = {threads!r}: an int >= 0 (0: all cores)")
    if episode_steps is not None and (
        isinstance(episode_steps, bool)
        or not isinstance(episode_steps, (int, np.integer))
        or episode_steps < 1
    ):
        raise ValueError(f"episode_steps = {episode_steps!r}: an int >= 1 or None")
    if actions is not None and not isinstance(actions, str):
        raise TypeError(f"actions = {actions!r}: RON text, e.g. '(base: Velocity, arm: JointDelta)'")
    return _core.Core(
        os.fspath(target),
        int(num_envs),
        int(threads),
        actions,
        _rgbd_camera(obs_mode),
        [os.fspath(p) for p in plugins],
        None if episode_steps is None else int(episode_steps),
        autoreset,
    )


def _as_float32(a: np.ndarray) -> np.ndarray:
    """Actions as contiguous float32. A value finite in float64 but beyond float32 becomes
    +-inf without numpy's overflow warning: the simulator then ends the episode with an error
    for the non-finite action, as for any other."""
    with np.errstate(over="ignore"):
        return np.ascontiguousarray(a, dtype=np.float32)


def _action_error(action: Any, expected: str) -> ValueError:
    got = getattr(action, "shape", None)
    dtype = getattr(action, "dtype", type(action).__name__)
    return ValueError(f"action of shape {got} and dtype {dtype}: expected {expected}")


def _reset_args(
    n: int, seed: int | Sequence[int | None] | None, options: dict[str, Any] | None
) -> tuple[list[int | None], list[bool] | None]:
    """A vector reset's ``seed`` and ``options`` as one seed per env (an int seed ``s`` gives
    env ``i`` the seed ``s + i``) and the ``reset_mask`` as a list (None: every env), checked as
    Gymnasium's vector envs check them."""
    if seed is None:
        seeds: list[int | None] = [None] * n
    elif isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_)):
        base = _seed(seed)
        seeds = [_seed(base + i, f"seed + {i}") for i in range(n)]
    else:
        seeds = [_seed(s, f"seed[{i}]") for i, s in enumerate(seed)]
        if len(seeds) != n:
            raise ValueError(
                f"If seeds are passed as a list the length must match num_envs={n} "
                f"but got length={len(seeds)}."
            )
    if options is None or "reset_mask" not in options:
        return seeds, None
    mask = options["reset_mask"]
    if not isinstance(mask, np.ndarray):
        raise TypeError(f"`options['reset_mask']` must be a numpy array, got {type(mask)}")
    if mask.shape != (n,):
        raise ValueError(f"`options['reset_mask']` must have shape `({n},)`, got {mask.shape}")
    if mask.dtype != np.bool_:
        raise TypeError(f"`options['reset_mask']` must have `dtype=np.bool_`, got {mask.dtype}")
    if not np.any(mask):
        raise ValueError(
            "`options['reset_mask']` must contain a boolean array with at least one "
            f"True value, got reset_mask={mask}"
        )
    return seeds, [bool(m) for m in mask]


def _vector_actions(space: gym.Space, n: int, actions: Any) -> np.ndarray:
    """A vector step's ``actions`` for ``n`` envs of ``space`` as the float32 ``n x act_dim``
    rows the simulator steps (a ``Discrete`` action as one float), checked."""
    if isinstance(space, spaces.Discrete):
        k = space.n
        a = np.asarray(actions)
        if a.dtype.kind not in "iu" or a.shape != (n,):
            raise _action_error(actions, f"shape ({n},), integers in 0..{k}")
        if np.any(a < 0) or np.any(a >= k):
            raise ValueError(f"actions = {a}: integers in 0..{k} (Discrete({k}))")
        return a.astype(np.float32).reshape(n, 1)
    shape = (n, *space.shape)
    a = np.asarray(actions)
    if a.dtype.kind not in "fiu" or a.shape != shape:
        raise _action_error(actions, f"shape {shape}, a float array (float32)")
    return _as_float32(a)


class ModeSuiteEnv(gym.Env):
    """One modesuite environment as a ``gymnasium.Env``.

    Args:
        target: a task id ``MoDe-<Robot>-<Task>-v0`` or a ``*.scene.ron`` path.
        render_mode: ``None`` or ``"rgb_array"`` (an orbit camera framing the scene).
        obs_mode: ``"state"``, ``"rgbd"`` or ``"rgbd:<camera>"`` (see :data:`OBS_MODES`).
        actions: action modes of the robot as RON, replacing the scene's, e.g.
            ``"(base: Velocity, arm: JointDelta, gripper: Binary)"`` or ``"(discrete: true)"``.
        plugins: compiled plugins (``.so`` paths, C ABI), as ``--plugin`` loads them.
        episode_steps: env steps per episode, replacing the scene's time limit.
        render_size: ``(width, height)`` of rendered frames.

    Observations are float32 (state) or a ``Dict`` with uint8 RGB and float32 depth; the action
    is one float32 ``Box`` (the parts named by :attr:`action_parts`) or ``Discrete(14)``.
    ``info`` holds ``success`` and ``values`` (the step's reward terms and diagnostics) and, on
    the step that ends an episode, ``is_success``, ``ended``, ``terminations`` and ``error``, as
    ``modesuite run --json`` reports them. A non-finite action ends the episode with
    ``info["error"]`` (``truncated``), as a physics blow-up does.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(
        self,
        target: str | os.PathLike,
        *,
        render_mode: str | None = None,
        obs_mode: str = "state",
        actions: str | None = None,
        plugins: Sequence[str | os.PathLike] = (),
        episode_steps: int | None = None,
        render_size: tuple[int, int] = (480, 320),
    ) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode = {render_mode!r}: None or 'rgb_array'")
        self._core = _make_core(target, 1, 1, obs_mode, actions, plugins, episode_steps, False)
        self.observation_space, self.action_space, self.action_parts = _spaces(self._core)
        self.render_mode = render_mode
        self.render_size = (int(render_size[0]), int(render_size[1]))
        self.metadata = {
            "render_modes": ["rgb_array"],
            "render_fps": max(1, round(1.0 / self._core.step_dt)),
        }
        self.target = self._core.target
        self.episode_steps = self._core.episode_steps

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        seed = _seed(seed)
        super().reset(seed=seed)
        return self._core.reset_one(seed)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        return self._core.step_one(self._action(action))

    def _action(self, action: Any) -> np.ndarray:
        if isinstance(self.action_space, spaces.Discrete):
            n = self.action_space.n
            a = np.asarray(action)
            if a.dtype.kind not in "iu" or a.size != 1 or a.ndim > 1:
                raise _action_error(action, f"one integer in 0..{n} (Discrete({n}))")
            k = int(a.reshape(()))
            if not 0 <= k < n:
                raise ValueError(f"action = {k}: an integer in 0..{n} (Discrete({n}))")
            return np.array([k], dtype=np.float32)
        shape = self.action_space.shape
        a = np.asarray(action)
        if a.dtype.kind not in "fiu" or a.shape != shape:
            raise _action_error(action, f"shape {shape}, a float array (float32)")
        return _as_float32(a)

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        return self._core.render(0, *self.render_size)

    def expert_action(self) -> np.ndarray:
        """The task's scripted expert's action for the current state (float32, or an int for
        ``Discrete``); ``NotImplementedError`` for a scene without an expert."""
        a = self._core.expert_actions()[0]
        if isinstance(self.action_space, spaces.Discrete):
            return np.int64(a[0])
        return a

    def state_hash(self) -> int:
        """A bit-exact hash of the simulation state."""
        return self._core.state_hashes()[0]

    def dump_state(self) -> str:
        """The state as ``modesuite.state.v1`` JSON (as ``modesuite run --dump-state``)."""
        return self._core.dump_state(0)

    def save_state(self) -> bytes:
        """The complete simulation state as a state file's bytes (``modesuite run
        --save-state``): write them anywhere, continue with :meth:`load_state`."""
        return self._core.save_state(0)

    def load_state(self, data: bytes) -> Any:
        """Continues the episode saved in ``data`` (bytes of :meth:`save_state` or a ``--save-state``
        file of the same target, plugins and build; anything else raises ``ValueError`` and
        changes nothing). Returns the observation; the next ``step`` continues bit-exactly as
        it would have in the env that saved it."""
        return self._core.load_state(0, bytes(data))


class ModeSuiteVectorEnv(VectorEnv):
    """``num_envs`` modesuite environments stepped together in Rust (GIL released).

    Same options as :class:`ModeSuiteEnv`, plus ``num_threads`` (0: all cores; results are
    bit-identical for any number) and ``autoreset_mode`` (``AutoresetMode.SAME_STEP``, the
    default, or ``AutoresetMode.DISABLED`` with ``reset(options={"reset_mask": mask})``).
    Infos are laid out exactly as Gymnasium's ``SyncVectorEnv`` lays them out: ``final_obs``
    and ``final_info`` with their masks on the steps that end episodes.
    """

    def __init__(
        self,
        target: str | os.PathLike,
        num_envs: int = 1,
        *,
        num_threads: int = 0,
        autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP,
        render_mode: str | None = None,
        obs_mode: str = "state",
        actions: str | None = None,
        plugins: Sequence[str | os.PathLike] = (),
        episode_steps: int | None = None,
        max_episode_steps: int | None = None,
        render_size: tuple[int, int] = (480, 320),
    ) -> None:
        mode = AutoresetMode(autoreset_mode)
        if mode not in (AutoresetMode.SAME_STEP, AutoresetMode.DISABLED):
            raise ValueError(
                f"autoreset_mode = {mode}: SAME_STEP or DISABLED (NEXT_STEP is not implemented)"
            )
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode = {render_mode!r}: None or 'rgb_array'")
        if max_episode_steps is not None:
            # gymnasium.make_vec passes the registered limit; a shorter one wins, as a TimeLimit
            # wrapper around single envs would cut them
            limit = episode_steps
            if limit is None:
                limit = _core.scene_episode_steps(os.fspath(target))
            episode_steps = max_episode_steps if limit is None else min(limit, max_episode_steps)
        self._core = _make_core(
            target,
            num_envs,
            num_threads,
            obs_mode,
            actions,
            plugins,
            episode_steps,
            mode == AutoresetMode.SAME_STEP,
        )
        self.num_envs = self._core.num_envs
        self.single_observation_space, self.single_action_space, self.action_parts = _spaces(
            self._core
        )
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.render_mode = render_mode
        self.render_size = (int(render_size[0]), int(render_size[1]))
        self.metadata = {
            "autoreset_mode": mode,
            "render_modes": ["rgb_array"],
            "render_fps": max(1, round(1.0 / self._core.step_dt)),
        }
        self.target = self._core.target
        self.episode_steps = self._core.episode_steps
        self.num_threads = self._core.threads

    def reset(
        self,
        *,
        seed: int | Sequence[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[Any, dict[str, Any]]:
        seeds, mask = _reset_args(self.num_envs, seed, options)
        if isinstance(seed, (int, np.integer)):
            super().reset(seed=int(seed))
        return self._core.reset(seeds, mask)

    def step(
        self, actions: Any
    ) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        return self._core.step(_vector_actions(self.single_action_space, self.num_envs, actions))

    def render(self) -> tuple[np.ndarray, ...] | None:
        if self.render_mode != "rgb_array":
            return None
        return tuple(self._core.render(i, *self.render_size) for i in range(self.num_envs))

    def expert_actions(self) -> np.ndarray:
        """The scripted expert's actions for every env's current state (batched like
        ``action_space``); ``NotImplementedError`` for a scene without an expert."""
        a = self._core.expert_actions()
        if isinstance(self.single_action_space, spaces.Discrete):
            return a[:, 0].astype(np.int64)
        return a

    def state_hashes(self) -> list[int]:
        """A bit-exact hash of each env's simulation state."""
        return self._core.state_hashes()

    def save_state(self, index: int) -> bytes:
        """The complete state of env ``index`` as a state file's bytes."""
        return self._core.save_state(index)

    def load_state(self, index: int, data: bytes) -> Any:
        """Continues env ``index`` from a state file's bytes (see ``ModeSuiteEnv.load_state``);
        returns that env's observation."""
        return self._core.load_state(index, bytes(data))
