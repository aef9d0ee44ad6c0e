#!/usr/bin/env python3
"""Trains and evaluates the runs behind docs/results.md, resumably (standard library only).

    python3 scripts/results.py [--bin PATH] [--runs runs] [--only ppo/MoDe-Franka-Place-v0/0 ...]
    python3 scripts/results.py --only ppo/MoDe-Franka-Lift-v0/0 --variant sep --set separate=true
    python3 scripts/results.py --only sac/MoDe-Spot-Lift-v0/0 --stop-at 100000

Each run (algorithm, task, seed) trains in chunks with `modesuite train` (the same command
resumes it) and after each chunk its policy is evaluated with `modesuite eval` on 20 episodes
from seed 1,000,000 (never a training seed). A line per evaluation goes to
`runs/<algo>/<task>/seed<k>/evals.jsonl`: env steps, the run's training wall time (from its
metrics), the success rate and mean return. A run stops at its budget or at its first
evaluation with every episode successful (`--stop-at N` stops this call at N env steps
instead; the same command without it continues the run); the policy of its best evaluation so far is kept in
`best_policy/` (with `eval.json`), since a later chunk can do worse (SAC especially). Killed at any moment, it continues where it was: a
chunk already evaluated is not evaluated again, and training resumes from its checkpoint.
`--table` prints the markdown table of all evaluations found, `--summary` one row per algorithm
and task (seeds, best and last held-out success per seed). A hyper-parameter study names a
variant: `--variant NAME --set KEY=VALUE ...` trains with those `train --set` values (give the
same ones to resume it) into `runs/<algo>/<task>+NAME/seed<k>`, its ledger and rows labelled
`<task>+NAME`.

Every evaluation line is also appended to `docs/results/evals/<algo>-<task>-seed<k>.jsonl`, which
is committed: `runs/` (checkpoints, metrics) stays on the machine that trained, the record of
what each run reached does not, and `--table` reads it when a run's folder is absent. A run
started again where its folder is gone (a fresh machine) moves its old ledger to
`docs/results/evals/superseded/restarted/` first, so the two runs' lines do not mix.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

ELASTIC = ["Place", "Drag", "Bend", "Transport", "Lift"]
# (algo, chunk env steps, budget env steps)
ALGOS = {"ppo": (25_600, 256_000), "sac": (20_000, 200_000)}
# the order runs are made in: the must-show rows first
PLAN = (
    [("ppo", "MoDe-Franka-Place-v0", s) for s in range(2)]
    + [("ppo", "MoDe-Franka-Drag-v0", 0), ("sac", "MoDe-Franka-Place-v0", 0)]
    + [("ppo", "MoDe-Franka-Place-v0", s) for s in range(2, 5)]
    + [("ppo", f"MoDe-Franka-{t}-v0", 0) for t in ELASTIC[2:]]
    + [("ppo", f"MoDe-Spot-{t}-v0", 0) for t in ELASTIC]
    + [("ppo", "MoDe-Franka-Drag-v0", s) for s in range(1, 5)]
    + [("sac", f"MoDe-{r}-{t}-v0", 0) for r in ("Franka", "Spot") for t in ELASTIC
       if (r, t) != ("Franka", "Place")]
)


def run_dir(root: Path, algo: str, task: str, seed: int) -> Path:
    return root / algo / task / f"seed{seed}"


LEDGER = Path(__file__).resolve().parent.parent / "docs" / "results" / "evals"


def ledger_path(algo: str, task: str, seed: int) -> Path:
    return LEDGER / f"{algo}-{task}-seed{seed}.jsonl"


def read_lines(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    out = []
    for line in path.read_text().splitlines():
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            pass  # a line cut by a kill
    return out


def append_line(path: Path, obj: dict) -> None:
    with open(path, "a") as f:
        f.write(json.dumps(obj) + "\n")
        f.flush()
        os.fsync(f.fileno())


def one_run(binary: str, root: Path, algo: str, task: str, seed: int,
            variant: str | None = None, sets: list[str] | None = None,
            stop_at: int | None = None) -> None:
    chunk, budget = ALGOS[algo]
    if stop_at is not None:
        # an earlier stop for this call only: the same command without it continues the run
        budget = min(budget, stop_at)
    label = f"{task}+{variant}" if variant else task
    d = run_dir(root, algo, label, seed)
    d.mkdir(parents=True, exist_ok=True)
    evals = d / "evals.jsonl"
    done = {e["env_steps"] for e in read_lines(evals)}
    old = ledger_path(algo, label, seed)
    if not done and read_lines(old):
        # the ledger of a run whose folder is gone (another machine, a fresh checkout): this
        # run starts over, so its lines go aside instead of mixing with the new run's
        aside = LEDGER / "superseded" / "restarted" / old.name
        aside.parent.mkdir(parents=True, exist_ok=True)
        if aside.exists():
            aside = aside.with_name(f"{old.stem}-{int(aside.stat().st_mtime)}.jsonl")
        os.rename(old, aside)
        print(f"{d}: no evaluations here but a ledger: it starts over, the old ledger moved to "
              f"{aside}", file=sys.stderr)
    if any(e["success_rate"] == 1.0 for e in read_lines(evals)):
        return
    for target in range(chunk, budget + 1, chunk):
        if target in done:
            continue
        cmd = [binary, "train", task, "--algo", algo, "--seed", str(seed),
               "--env-steps", str(target), "--out", str(d)]
        for kv in sets or []:
            cmd += ["--set", kv]
        with open(d / "train.log", "a") as log:
            r = subprocess.run(cmd, stdout=log, stderr=log)
        if r.returncode != 0:
            print(f"{d}: train failed (exit {r.returncode}); see {d / 'train.log'}", file=sys.stderr)
            return
        out = subprocess.run([binary, "eval", str(d), "--episodes", "20", "--json"],
                             capture_output=True, text=True)
        if out.returncode != 0:
            print(f"{d}: eval failed: {out.stderr}", file=sys.stderr)
            return
        summary = json.loads(out.stdout.strip().splitlines()[-1])
        metrics = read_lines(d / "metrics.jsonl")
        line = {"env_steps": target, "train_wall_s": metrics[-1]["wall_s"] if metrics else None,
                "success_rate": summary["success_rate"], "mean_return": summary["mean_return"],
                "mean_length": summary["mean_length"], "errors": summary["errors"]}
        best = max((e["success_rate"] or 0 for e in read_lines(evals)), default=-1.0)
        append_line(evals, line)
        ledger_path(algo, label, seed).parent.mkdir(parents=True, exist_ok=True)
        append_line(ledger_path(algo, label, seed), line)
        if (summary["success_rate"] or 0) > best or not (d / "best_policy").is_dir():
            # keep the policy of the best evaluation: SAC in particular can fall back later
            shutil.rmtree(d / "best_policy.tmp", ignore_errors=True)
            shutil.copytree(d / "policy", d / "best_policy.tmp")
            (d / "best_policy.tmp" / "eval.json").write_text(json.dumps(line) + "\n")
            shutil.rmtree(d / "best_policy", ignore_errors=True)
            os.rename(d / "best_policy.tmp", d / "best_policy")
        print(f"{algo} {label} seed {seed}: {line}", flush=True)
        if summary["success_rate"] == 1.0:
            return


def table(root: Path) -> str:
    rows = ["| algo | task | seed | env steps | train wall (s) | eval success (20, seeds 1e6+) | eval return | first eval >= 90 %: env steps / train wall (s) |",
            "|---|---|---|---|---|---|---|---|"]
    # the plan's runs, then any other run with a ledger (more seeds), in name order
    extra = []
    for f in sorted(LEDGER.glob("*-seed*.jsonl")):
        algo, rest = f.stem.split("-", 1)
        task, _, seed = rest.rpartition("-seed")
        if algo in ALGOS and seed.isdigit() and (algo, task, int(seed)) not in PLAN:
            extra.append((algo, task, int(seed)))
    for algo, task, seed in PLAN + extra:
        ev = read_lines(run_dir(root, algo, task, seed) / "evals.jsonl") or read_lines(
            ledger_path(algo, task, seed))
        if not ev:
            continue
        last = ev[-1]
        first = next((e for e in ev if (e["success_rate"] or 0) >= 0.9), None)
        first_s = f"{first['env_steps']:,} / {first['train_wall_s']:.0f}" if first else "not reached"
        rows.append(f"| {algo.upper()} | {task} | {seed} | {last['env_steps']:,} | {last['train_wall_s']:.0f} | "
                    f"{100 * (last['success_rate'] or 0):.0f} % | {last['mean_return']:.1f} | {first_s} |")
    return "\n".join(rows)


def summary() -> str:
    """One row per algorithm and task from the committed ledgers: the seeds run, each seed's
    best and last held-out success, and where each first reached 20 of 20."""
    runs: dict[tuple[str, str], list[tuple[int, list[dict]]]] = {}
    for f in sorted(LEDGER.glob("*-seed*.jsonl")):
        algo, rest = f.stem.split("-", 1)
        task, _, seed = rest.rpartition("-seed")
        ev = read_lines(f)
        if algo in ALGOS and seed.isdigit() and ev:
            runs.setdefault((algo, task), []).append((int(seed), ev))
    rows = ["| algo | task | seeds | best held-out success per seed | last evaluation per seed | first 20/20 (env steps) |",
            "|---|---|---|---|---|---|"]
    order = {t: i for i, t in enumerate(f"MoDe-{r}-{t}-v0" for r in ("Franka", "Spot") for t in ELASTIC)}
    for (algo, task), seeds in sorted(runs.items(), key=lambda kv: (kv[0][0], order.get(kv[0][1], 99))):
        seeds.sort()
        pct = lambda e: f"{100 * (e['success_rate'] or 0):.0f} %"
        best = ", ".join(pct(max(ev, key=lambda e: e["success_rate"] or 0)) for _, ev in seeds)
        last = ", ".join(f"{pct(ev[-1])} at {ev[-1]['env_steps']:,}" for _, ev in seeds)
        first = ", ".join(next((f"{e['env_steps']:,}" for e in ev if e["success_rate"] == 1.0), "-")
                          for _, ev in seeds)
        rows.append(f"| {algo.upper()} | {task} | {', '.join(str(k) for k, _ in seeds)} | {best} | {last} | {first} |")
    return "\n".join(rows)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--bin", default=os.path.expanduser("~/.cache/modesuite-target/release/modesuite"))
    p.add_argument("--runs", default="runs", type=Path)
    p.add_argument("--only", nargs="*", help="algo/task/seed, e.g. ppo/MoDe-Franka-Place-v0/0")
    p.add_argument("--variant", help="a hyper-parameter study's name (runs and ledgers <task>+NAME)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="`train --set` value of the variant (repeatable; needs --variant)")
    p.add_argument("--stop-at", type=int, metavar="ENV_STEPS",
                   help="train only up to this many env steps this time (below the algorithm's "
                        "budget; run again without it to continue to the budget)")
    p.add_argument("--table", action="store_true")
    p.add_argument("--summary", action="store_true",
                   help="one row per algorithm and task from docs/results/evals/")
    args = p.parse_args()
    if args.table:
        print(table(args.runs))
        return
    if args.summary:
        print(summary())
        return
    if args.stop_at is not None and args.stop_at <= 0:
        p.error(f"--stop-at {args.stop_at}: a positive number of env steps")
    if args.set and not args.variant:
        p.error("--set needs --variant NAME (the runs of other settings go elsewhere)")
    if args.variant and (not args.only or not args.variant.replace("-", "").replace("_", "").isalnum()):
        p.error(f"--variant {args.variant}: letters, digits, - and _, with --only")
    plan = PLAN
    if args.only:
        # any run, in the order given (more seeds than the plan's, say)
        plan = []
        for o in args.only:
            parts = o.split("/")
            if len(parts) != 3 or parts[0] not in ALGOS or not parts[2].isdigit():
                p.error(f"--only {o}: expected algo/task/seed with algo one of {sorted(ALGOS)}, "
                        "e.g. ppo/MoDe-Franka-Place-v0/0")
            plan.append((parts[0], parts[1], int(parts[2])))
    for algo, task, seed in plan:
        one_run(args.bin, args.runs, algo, task, seed, args.variant, args.set, args.stop_at)


if __name__ == "__main__":
    main()
