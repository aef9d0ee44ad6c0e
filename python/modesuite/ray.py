"""Scale-out on Ray: vector envs whose worlds step on many machines, and distributed evaluation.

:class:`RayVectorEnv` is a ``gymnasium.vector.VectorEnv`` whose ``num_envs`` envs are sharded
over ``num_workers`` Ray actors, each holding one native :class:`~modesuite.ModeSuiteVectorEnv`
(stepped on its node's cores by the Rust thread pool). Spaces, ``SAME_STEP`` autoreset and the
info layout are those of the local vector env, and env ``i`` gets the seed that env ``i`` of a
local ``make_vec_env`` gets, so results do not depend on the number of workers. One message goes
to each worker per step (the rows of its envs as one float32 array) and one comes back.

A worker whose process dies, or that does not answer a step within ``step_timeout`` seconds, is
restarted by Ray; its envs are reset and the step reports them as truncated with
``info["worker_restarted"]`` set (see :meth:`RayVectorEnv.step`). Every other env's results are
unchanged.

:func:`evaluate` runs whole episodes of a policy over many targets and seeds on a pool of
actors and returns, per target, the summary that ``modesuite run --json`` prints.

Ray is an optional extra: ``pip install 'modesuite[ray]'``. Call ``ray.init(address=...)``
first to use a cluster; without it Ray starts a local instance. ``docs/ray.md`` has a cluster
recipe.
"""

from __future__ import annotations

import os
import time
from typing import Any, Callable, Sequence

import numpy as np

try:
    import ray
    from ray.exceptions import GetTimeoutError, RayActorError
except ImportError as e:  # pragma: no cover - depends on the installation
    raise ImportError(
        "modesuite.ray needs Ray: pip install 'modesuite[ray]' (or pip install ray)"
    ) from e

from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .envs import ModeSuiteEnv, ModeSuiteVectorEnv, _reset_args, _vector_actions

__all__ = ["ExpertPolicy", "RayVectorEnv", "TrainedPolicy", "evaluate"]

#: Tries to bring a dead worker back (each waits for Ray's restart) before the step fails.
RESTART_TRIES = 5


class _Worker:
    """A Ray actor's state: one native vector env of a shard of a :class:`RayVectorEnv`."""

    def __init__(self, target: str, num_envs: int, kwargs: dict[str, Any]) -> None:
        self._hang = 0.0
        self._error: BaseException | None = None
        try:
            self.env = ModeSuiteVectorEnv(target, num_envs, **kwargs)
        except Exception as e:  # reported by describe(): a failed constructor kills the actor
            self._error = e

    def describe(self) -> dict[str, Any]:
        if self._error is not None:
            raise self._error
        e = self.env
        return {
            "obs": e.single_observation_space,
            "act": e.single_action_space,
            "parts": e.action_parts,
            "metadata": e.metadata,
            "target": e.target,
            "episode_steps": e.episode_steps,
            "num_threads": e.num_threads,
        }

    def pid(self) -> int:
        return os.getpid()

    def reset(self, seeds: list[int | None], mask: list[bool] | None) -> tuple[Any, dict]:
        return self.env._core.reset(seeds, mask)

    def step(self, actions: np.ndarray) -> tuple:
        if self._hang > 0.0:
            time.sleep(self._hang)
            self._hang = 0.0
        return self.env._core.step(actions)

    def call(self, name: str, *args: Any) -> Any:
        return getattr(self.env, name)(*args)

    def hang_next_step(self, seconds: float) -> None:
        self._hang = float(seconds)


def _blank(like: np.ndarray, n: int) -> np.ndarray:
    """``n`` entries of an info column that no env of a shard reported (False, 0.0, None)."""
    if like.dtype == object:
        return np.empty(n, dtype=object)
    return np.zeros(n, dtype=like.dtype)


def _merge_infos(parts: Sequence[dict[str, Any]], sizes: Sequence[int]) -> dict[str, Any]:
    """The batched info of consecutive shards (``sizes[k]`` envs in ``parts[k]``), laid out as
    one vector env of ``sum(sizes)`` envs lays it out: each key's column over all envs, its
    ``_key`` mask, nested dicts merged the same way; a column's kind is that of the first shard
    that reports it (as the first env reporting a key sets it in Gymnasium's ``_add_info``)."""
    keys: list[str] = []
    for p in parts:
        keys.extend(k for k in p if k not in keys)
    out: dict[str, Any] = {}
    for k in keys:
        values = [p.get(k) for p in parts]
        first = next(v for v in values if v is not None)
        if isinstance(first, dict):
            out[k] = _merge_infos([v if isinstance(v, dict) else {} for v in values], sizes)
            continue
        cols = [_blank(first, n) if v is None else np.asarray(v) for v, n in zip(values, sizes)]
        if any(c.dtype == object for c in cols):
            cols = [c.astype(object) for c in cols]
        else:
            cols = [c.astype(first.dtype, copy=False) for c in cols]
        out[k] = np.concatenate(cols)
    return out


def _concat_obs(parts: Sequence[Any]) -> Any:
    if isinstance(parts[0], dict):
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    return np.concatenate(parts)


def _obs_row(obs: Any, i: int) -> Any:
    if isinstance(obs, dict):
        return {k: v[i].copy() for k, v in obs.items()}
    return obs[i].copy()


def _column(values: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
    """An info column of one value per env of a shard (bools, else objects), and its
    all-true mask."""
    if all(isinstance(v, (bool, np.bool_)) for v in values):
        col = np.array(values, dtype=np.bool_)
    else:
        col = np.empty(len(values), dtype=object)
        for i, v in enumerate(values):
            col[i] = v
    return col, np.ones(len(values), dtype=np.bool_)


def _info(entries: dict[str, Sequence[Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, values in entries.items():
        out[k], out[f"_{k}"] = _column(values)
    return out


class RayVectorEnv(VectorEnv):
    """``num_envs`` modesuite envs of ``target`` sharded over ``num_workers`` Ray actors.

    Args:
        target: a task id ``MoDe-<Robot>-<Task>-v0`` or a ``*.scene.ron`` path (readable on
            every node: a relative path is taken from the worker's working directory).
        num_envs: envs in all; worker ``k`` holds the consecutive envs of its shard (the first
            ``num_envs % num_workers`` workers one more than the others).
        num_workers: Ray actors, ``1..=num_envs``.
        step_timeout: seconds a worker may take for one step or reset before it is taken as
            hung, killed and restarted (None: wait for ever).
        worker_options: Ray actor options of each worker (``num_cpus``, ``resources``,
            ``scheduling_strategy``, ...; default ``{"num_cpus": 1}``).
        **make_kwargs: the options of :class:`~modesuite.ModeSuiteVectorEnv` (``num_threads``
            per worker, 0: all cores of its node; ``autoreset_mode``, ``obs_mode``,
            ``actions``, ``plugins``, ``episode_steps``, ``render_mode``, ...).

    Also :meth:`expert_actions`, :meth:`state_hashes`, :meth:`save_state`,
    :meth:`load_state` and :meth:`render` as the local vector env has them, and
    :meth:`worker_pids` (for monitoring and fault-injection tests).
    """

    def __init__(
        self,
        target: str | os.PathLike,
        num_envs: int = 1,
        num_workers: int = 1,
        *,
        step_timeout: float | None = None,
        worker_options: dict[str, Any] | None = None,
        **make_kwargs: Any,
    ) -> None:
        for name, v in (("num_envs", num_envs), ("num_workers", num_workers)):
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"{name} = {v!r}: an int >= 1")
        if num_workers > num_envs:
            raise ValueError(f"num_workers = {num_workers}: at most num_envs = {num_envs}")
        if step_timeout is not None and not (
            isinstance(step_timeout, (int, float)) and step_timeout > 0
        ):
            raise ValueError(f"step_timeout = {step_timeout!r}: seconds > 0, or None")
        self.num_envs = int(num_envs)
        self.num_workers = int(num_workers)
        self.step_timeout = None if step_timeout is None else float(step_timeout)
        base, extra = divmod(self.num_envs, self.num_workers)
        self.shard_sizes = [base + (k < extra) for k in range(self.num_workers)]
        self.shard_offsets = [sum(self.shard_sizes[:k]) for k in range(self.num_workers)]
        options = {"num_cpus": 1, **(worker_options or {})}
        # Ray restarts a dead worker (its constructor runs again); a step is never retried,
        # which would run it twice on the envs of a worker that died after stepping them
        actor = ray.remote(_Worker).options(max_restarts=-1, max_task_retries=0, **options)
        target = os.fspath(target)
        self._workers = [
            actor.remote(target, n, dict(make_kwargs)) for n in self.shard_sizes
        ]
        self._closed_workers = False
        try:
            desc = ray.get([w.describe.remote() for w in self._workers])[0]
        except Exception:
            self.close()
            raise
        self.single_observation_space = desc["obs"]
        self.single_action_space = desc["act"]
        self.action_parts = desc["parts"]
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.metadata = dict(desc["metadata"])
        self.render_mode = make_kwargs.get("render_mode")
        self.target = desc["target"]
        self.episode_steps = desc["episode_steps"]
        self.num_threads = desc["num_threads"]
        self.autoreset_mode = AutoresetMode(self.metadata["autoreset_mode"])
        #: restarts of each worker so far
        self.restarts = [0] * self.num_workers
        self._started = False
        self._waiting = np.zeros(self.num_envs, dtype=np.bool_)
        self._last_obs: Any = None
        self._base_seed = 0

    # -- plumbing -------------------------------------------------------------------------

    def _shard(self, k: int) -> slice:
        return slice(self.shard_offsets[k], self.shard_offsets[k] + self.shard_sizes[k])

    def _gather(self, refs: Sequence[Any]) -> tuple[list[Any], dict[int, str]]:
        """Each worker's answer, and why each worker that gave none failed. A worker that
        does not answer within ``step_timeout`` is killed (Ray restarts it)."""
        deadline = None if self.step_timeout is None else time.monotonic() + self.step_timeout
        out: list[Any] = [None] * len(refs)
        failed: dict[int, str] = {}
        for k, ref in enumerate(refs):
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                out[k] = ray.get(ref, timeout=left)
            except GetTimeoutError:
                ray.kill(self._workers[k], no_restart=False)
                failed[k] = f"worker {k} gave no answer within step_timeout = {self.step_timeout} s"
            except RayActorError as e:
                failed[k] = f"worker {k} died: {str(e).splitlines()[0][:300]}"
        return out, failed

    def _restart_seeds(self, k: int) -> list[int]:
        """Seeds of worker ``k``'s envs after its ``restarts[k]``-th restart: a function of the
        last reset's base seed, the env's index and that count."""
        out = []
        for i in range(self.shard_offsets[k], self.shard_offsets[k] + self.shard_sizes[k]):
            ss = np.random.SeedSequence([self._base_seed, i, self.restarts[k]])
            out.append(int(ss.generate_state(1, dtype=np.uint64)[0]))
        return out

    def _revive(
        self, k: int, why: str, seeds: list[int | None] | None = None
    ) -> tuple[Any, dict]:
        """Resets every env of worker ``k`` once Ray has restarted it (env ``i`` with
        ``seeds[i]`` where given, else with its restart seed); that reset's ``(obs, info)``
        with ``worker_restarted`` set. Raises ``RuntimeError`` when it cannot be brought back."""
        self.restarts[k] += 1
        fresh = self._restart_seeds(k)
        if seeds is not None:
            fresh = [f if s is None else s for f, s in zip(fresh, seeds)]
        last = why
        for _ in range(RESTART_TRIES):
            out, failed = self._gather([self._workers[k].reset.remote(fresh, None)])
            if not failed:
                obs, info = out[0]
                info = dict(info)
                info.update(_info({"worker_restarted": [True] * self.shard_sizes[k]}))
                return obs, info
            last = failed[0]
            time.sleep(0.2)
        raise RuntimeError(f"{why}; restarting it failed {RESTART_TRIES} times: {last}")

    def _restarted_step(self, k: int, why: str) -> tuple:
        """The step result of worker ``k``'s envs when it failed during the step: each env's
        episode is cut (truncated, reward 0) at its last observation (``final_obs``); the
        observation is the first of a new episode of the restarted worker."""
        n, lo = self.shard_sizes[k], self.shard_offsets[k]
        obs, reset_info = self._revive(k, why)
        final_obs = [_obs_row(self._last_obs, lo + i) for i in range(n)]
        final_info = _info(
            {"ended": ["error"] * n, "error": [why] * n, "worker_restarted": [True] * n}
        )
        info = dict(reset_info)
        info.update(_info({"final_obs": final_obs}))
        info["final_info"] = final_info
        info["_final_info"] = np.ones(n, dtype=np.bool_)
        return (
            obs,
            np.zeros(n, dtype=np.float64),
            np.zeros(n, dtype=np.bool_),
            np.ones(n, dtype=np.bool_),
            info,
        )

    # -- the VectorEnv API ----------------------------------------------------------------

    def reset(
        self,
        *,
        seed: int | Sequence[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[Any, dict[str, Any]]:
        seeds, mask = _reset_args(self.num_envs, seed, options)
        if isinstance(seed, (int, np.integer)):
            super().reset(seed=int(seed))
            self._base_seed = int(seed)
        refs = []
        for k in range(self.num_workers):
            s = self._shard(k)
            refs.append(self._workers[k].reset.remote(seeds[s], None if mask is None else mask[s]))
        out, failed = self._gather(refs)
        for k, why in failed.items():
            # a worker lost during a reset: its envs are reset (with the seeds asked for, where
            # its shard had any) after its restart
            s = self._shard(k)
            out[k] = self._revive(k, why, [x if mask is None or mask[i] else None
                                           for i, x in zip(range(s.start, s.stop), seeds[s])])
        obs = _concat_obs([o for o, _ in out])
        info = _merge_infos([i for _, i in out], self.shard_sizes)
        self._last_obs = obs
        self._started = True
        if mask is None:
            self._waiting[:] = False
        else:
            self._waiting[np.asarray(mask)] = False
        return obs, info

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Steps every env. A worker that died or hung during the step is restarted: its envs
        come back ``truncated`` with reward 0, ``info["worker_restarted"]`` set (and its mask),
        ``final_obs`` the last observation they returned and ``final_info`` ``{"ended":
        "error", "error": why, "worker_restarted": True}``; the observation starts their next
        episode (seeded from the last reset's seed, the env index and the restart count)."""
        if not self._started:
            raise RuntimeError("step() before reset(): call reset() first")
        if self._waiting.any():
            raise RuntimeError(
                f"envs {np.flatnonzero(self._waiting).tolist()} ended their episode: reset them "
                'first (reset(options={"reset_mask": mask}))'
            )
        a = _vector_actions(self.single_action_space, self.num_envs, actions)
        refs = [self._workers[k].step.remote(a[self._shard(k)]) for k in range(self.num_workers)]
        out, failed = self._gather(refs)
        for k, why in failed.items():
            out[k] = self._restarted_step(k, why)
        obs = _concat_obs([o[0] for o in out])
        rewards = np.concatenate([o[1] for o in out])
        terminated = np.concatenate([o[2] for o in out])
        truncated = np.concatenate([o[3] for o in out])
        info = _merge_infos([o[4] for o in out], self.shard_sizes)
        self._last_obs = obs
        if self.autoreset_mode == AutoresetMode.DISABLED:
            self._waiting |= terminated | truncated
        return obs, rewards, terminated, truncated, info

    def close_extras(self, **kwargs: Any) -> None:
        """Ends the workers."""
        if not self._closed_workers:
            self._closed_workers = True
            for w in self._workers:
                ray.kill(w, no_restart=True)

    def close(self, **kwargs: Any) -> None:
        self.close_extras()
        self.closed = True

    # -- the extras of the local vector env -----------------------------------------------

    def _call_all(self, name: str, *args: Any) -> list[Any]:
        out, failed = self._gather([w.call.remote(name, *args) for w in self._workers])
        if failed:
            raise RuntimeError("; ".join(failed.values()))
        return out

    def _route(self, index: int) -> tuple[int, int]:
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
            raise TypeError(f"index = {index!r}: an int in 0..{self.num_envs}")
        if not 0 <= index < self.num_envs:
            raise ValueError(f"index = {index}: 0..{self.num_envs}")
        k = max(j for j in range(self.num_workers) if self.shard_offsets[j] <= index)
        return k, int(index) - self.shard_offsets[k]

    def expert_actions(self) -> np.ndarray:
        """The scripted expert's actions for every env (see the local vector env)."""
        return np.concatenate(self._call_all("expert_actions"))

    def state_hashes(self) -> list[int]:
        """A bit-exact hash of each env's simulation state."""
        return [h for part in self._call_all("state_hashes") for h in part]

    def render(self) -> tuple[np.ndarray, ...] | None:
        if self.render_mode != "rgb_array":
            return None
        return tuple(f for part in self._call_all("render") for f in part)

    def save_state(self, index: int) -> bytes:
        """The complete state of env ``index`` as a state file's bytes."""
        k, i = self._route(index)
        out, failed = self._gather([self._workers[k].call.remote("save_state", i)])
        if failed:
            raise RuntimeError(failed[0])
        return out[0]

    def load_state(self, index: int, data: bytes) -> Any:
        """Continues env ``index`` from a state file's bytes; returns that env's observation."""
        k, i = self._route(index)
        out, failed = self._gather([self._workers[k].call.remote("load_state", i, bytes(data))])
        if failed:
            raise RuntimeError(failed[0])
        return out[0]

    def worker_pids(self) -> list[int]:
        """The process id of each worker (on its node)."""
        out, failed = self._gather([w.pid.remote() for w in self._workers])
        if failed:
            raise RuntimeError("; ".join(failed.values()))
        return out

    def _hang_next_step(self, worker: int, seconds: float) -> None:
        """Fault injection for tests: worker ``worker`` sleeps ``seconds`` in its next step."""
        ray.get(self._workers[worker].hang_next_step.remote(seconds))


# -- distributed evaluation --------------------------------------------------------------


class ExpertPolicy:
    """The task's scripted expert as a Python policy for :func:`evaluate`: the action of the
    env it is bound to (``ModeSuiteEnv.expert_action``) whatever the observation."""

    def bind(self, env: ModeSuiteEnv) -> None:
        """Called by :func:`evaluate` with each env before its episodes."""
        self._env = env

    def __call__(self, obs: Any) -> Any:
        return self._env.expert_action()


class TrainedPolicy:
    """A trained policy's folder (``modesuite train --out DIR``, or one of ``policies/``) as a
    policy for :func:`evaluate`: the path is what travels to the workers, each of which loads
    the policy once (the folder must be readable on every node). Loaded on the driver too, so
    that a bad folder fails here; :attr:`target` and :attr:`actions` are the task and action
    modes it was trained with (pass ``actions=policy.actions`` to :func:`evaluate`)."""

    def __init__(self, path: str | os.PathLike) -> None:
        from . import Policy

        self.path = os.fspath(path)
        self._policy: Any = Policy(self.path)
        self.target: str = self._policy.target
        self.actions: str | None = self._policy.actions

    def __getstate__(self) -> dict[str, Any]:
        return {"path": self.path, "target": self.target, "actions": self.actions}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._policy = None

    def __call__(self, obs: Any) -> np.ndarray:
        if self._policy is None:
            from . import Policy

            self._policy = Policy(self.path)
        return self._policy.act(np.asarray(obs, dtype=np.float32))


class _Evaluator:
    """A Ray actor that runs whole episodes of one policy (one env per target, made once)."""

    def __init__(self, policy: Callable[[Any], Any], kwargs: dict[str, Any]) -> None:
        self.policy = policy
        self.kwargs = kwargs
        self.envs: dict[str, ModeSuiteEnv] = {}

    def episode(self, target: str, seed: int, steps: int | None) -> dict[str, Any]:
        """One episode from ``seed``, reported as a line of ``modesuite run --json``."""
        env = self.envs.get(target)
        if env is None:
            env = self.envs[target] = ModeSuiteEnv(target, **self.kwargs)
        policy = self.policy
        if hasattr(policy, "bind"):
            policy.bind(env)
        obs, _ = env.reset(seed=seed)
        if hasattr(policy, "reset"):
            policy.reset(seed)
        limit = steps or env.episode_steps or 600
        ret, length = 0.0, 0
        success, error, ended, terminations = None, None, "steps", []
        start = time.perf_counter()
        for _ in range(limit):
            try:
                action = policy(obs)
            except Exception as e:  # as `run` reports a failing policy
                error, ended = f"policy: {e}", "error"
                break
            obs, reward, terminated, truncated, info = env.step(action)
            ret += reward
            length += 1
            if terminated or truncated:
                success = info.get("is_success")
                error = info.get("error")
                ended = info["ended"]
                terminations = list(info["terminations"])
                break
            success = info.get("success")
        wall = time.perf_counter() - start
        return {
            "seed": seed,
            "return": ret,
            "length": length,
            "success": None if success is None else bool(success),
            "error": error,
            "ended": ended,
            "terminations": terminations,
            "wall_s": wall,
            "steps_per_s": length / max(wall, 1e-12),
        }


def _summary(target: str, episodes: list[dict[str, Any]], wall: float) -> dict[str, Any]:
    """``modesuite run --json``'s summary line of ``episodes`` (in episode order: the same
    sums in the same order give the same bits), and ``wall_s`` of the whole evaluation."""
    n = len(episodes)
    total_return, total_steps, total_time = 0.0, 0, 0.0
    for e in episodes:
        total_return += e["return"]
        total_steps += e["length"]
        total_time += e["wall_s"]
    successes = [e["success"] for e in episodes if e["success"] is not None]
    ended: dict[str, int] = {}
    for e in episodes:
        ended[e["ended"]] = ended.get(e["ended"], 0) + 1
    return {
        "summary": True,
        "target": target,
        "episodes": n,
        "success_rate": sum(successes) / len(successes) if successes else None,
        "mean_return": total_return / n,
        "mean_length": total_steps / n,
        "errors": sum(e["error"] is not None for e in episodes),
        "ended": dict(sorted(ended.items())),
        "env_steps_per_s": total_steps / max(total_time, 1e-12),
        "wall_s": wall,
    }


def evaluate(
    policy_fn: Callable[[Any], Any],
    targets: str | Sequence[str],
    episodes: int = 20,
    num_workers: int = 2,
    *,
    seed: int = 0,
    steps: int | None = None,
    worker_options: dict[str, Any] | None = None,
    return_episodes: bool = False,
    **make_kwargs: Any,
) -> dict[str, dict[str, Any]]:
    """Evaluates ``policy_fn`` on ``episodes`` episodes of each target on ``num_workers`` Ray
    actors, as ``modesuite run TARGET --episodes E --seed S --json`` does on one machine.

    ``policy_fn(obs) -> action`` is sent to each worker once and called there; if it has
    ``bind(env)`` it is first given the worker's :class:`~modesuite.ModeSuiteEnv` of the
    target (as :class:`ExpertPolicy` needs), and ``reset(seed)`` is called after each reset
    when it has one. Episode ``e`` starts from seed ``seed + e``; it ends when the env ends it
    or after ``steps`` env steps (default: the target's episode length). A policy that raises
    ends its episode with the error ``policy: ...``, as ``run`` reports a failing policy.

    Returns ``{target: summary}``, each summary with the keys of ``run --json``'s summary line
    (``episodes``, ``success_rate``, ``mean_return``, ``mean_length``, ``errors``, ``ended``,
    ``env_steps_per_s``; equal to ``run``'s for the same seeds but the speed) and ``wall_s``;
    with ``return_episodes`` also ``"episode_results"``: one ``run --json`` line per episode.
    A worker that dies is restarted by Ray and its episodes run again (an episode is a
    function of its seed, so none is counted twice).
    """
    if isinstance(targets, (str, os.PathLike)):
        targets = [targets]
    targets = [os.fspath(t) for t in targets]
    for name, v in (("episodes", episodes), ("num_workers", num_workers)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name} = {v!r}: an int >= 1")
    if steps is not None and (isinstance(steps, bool) or not isinstance(steps, int) or steps < 1):
        raise ValueError(f"steps = {steps!r}: an int >= 1 or None")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**64:
        raise ValueError(f"seed = {seed!r}: an int in 0..2**64")
    options = {"num_cpus": 1, **(worker_options or {})}
    actor = ray.remote(_Evaluator).options(max_restarts=-1, max_task_retries=0, **options)
    # the policy travels with each worker's constructor (pickled once per worker), so that a
    # restarted worker gets it again
    workers = [actor.remote(policy_fn, dict(make_kwargs)) for _ in range(int(num_workers))]
    jobs = [(t, e) for t in targets for e in range(int(episodes))]
    results: dict[tuple[str, int], dict[str, Any]] = {}
    tries: dict[tuple[str, int], int] = {}
    pending: dict[Any, tuple[int, tuple[str, int]]] = {}
    queue = list(reversed(jobs))
    start = time.perf_counter()

    def submit(w: int) -> None:
        job = queue.pop()
        target, e = job
        seed_e = (int(seed) + e) % 2**64
        pending[workers[w].episode.remote(target, seed_e, steps)] = (w, job)

    try:
        # two episodes queued per worker hide the round trip between them
        for _ in range(2):
            for w in range(len(workers)):
                if queue:
                    submit(w)
        while pending:
            [ref], _ = ray.wait(list(pending), num_returns=1)
            w, job = pending.pop(ref)
            try:
                results[job] = ray.get(ref)
            except RayActorError as err:
                tries[job] = tries.get(job, 0) + 1
                if tries[job] > RESTART_TRIES:
                    raise RuntimeError(
                        f"{job[0]} episode {job[1]}: its worker died {tries[job]} times: {err}"
                    ) from err
                queue.append(job)
            if queue:
                submit(w)
    finally:
        for w in workers:
            ray.kill(w, no_restart=True)
    wall = time.perf_counter() - start
    out = {}
    for t in targets:
        eps = [dict(results[(t, e)], episode=e) for e in range(int(episodes))]
        s = _summary(t, eps, wall)
        if return_episodes:
            s["episode_results"] = eps
        out[t] = s
    return out
