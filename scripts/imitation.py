#!/usr/bin/env python3
"""Makes the imitation table of docs/results.md, resumably (standard library only).

    python3 scripts/imitation.py [--bin PATH] [--data data/il] [--only Spot-Uncover ...] [--methods bc ...]
    python3 scripts/imitation.py --table

Per task: 30 demonstrations of the scripted expert with action noise 0.1 (seeds 1000-1029),
recorded with the robot camera and its image features cached (`record --cameras robot
--encoder ENCODER`); behaviour cloning and retrieval (k = 1) trained on the successful
demonstrations (`train --algo bc|retrieval --inputs INPUTS --successful-only`) with the image
features and the state (`features+state`, every task) and with the features alone (`features`,
the Spot tasks, as the paper);
each evaluated on 20 episodes from seed 1,000,000 (`eval --episodes 20 --json`), seeds the
demonstrations never used. One line per (task, method, inputs) goes to `<data>/results.jsonl`; a step
already done (a complete dataset, a trained policy, a line) is not redone.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from results import append_line, read_lines  # noqa: E402

TASKS = ["Spot-Uncover", "Spot-Cover", "Spot-Curtain", "Franka-Uncover", "Franka-Cover", "Franka-Curtain"]
# method name -> (train --algo, extra arguments); bc-chunk5: behaviour cloning with action chunks
# of 5 (learning.md), added in session 26 after BC stalled on Cover
METHODS = {"bc": ("bc", []), "retrieval": ("retrieval", ["--set", "k=1"]),
           "bc-chunk5": ("bc", ["--set", "chunk=5"]),
           "bc-chunk5-ens": ("bc", ["--set", "chunk=5", "--set", "ensemble=0.01"]),
           "retrieval-h10-ens": ("retrieval", ["--set", "horizon=10", "--set", "ensemble=0.01"]),
           "bc-chunk5-ens-m5": ("bc", ["--set", "chunk=5", "--set", "ensemble=0.01", "--set", "members=5"])}
# bc-chunk5-ens: the chunks played with ACT's temporal ensembling (learning.md), session 35;
# retrieval-h10-ens: segments of 10 retrieved at every step and ensembled the same way;
# bc-chunk5-ens-m5: bc-chunk5-ens with 5 networks averaged (`members`, learning.md), session 37
LABELS = {"bc": "BC", "retrieval": "Retrieval (k = 1)", "bc-chunk5": "BC, chunks of 5",
          "bc-chunk5-ens": "BC, chunks of 5, ensembled",
          "retrieval-h10-ens": "Retrieval, segments of 10, ensembled",
          "bc-chunk5-ens-m5": "BC, chunks of 5, ensembled, 5 members"}
# the paper's (MoDeSuite, Table: imitation on Spot, DINOv2 features, 30 keyboard demonstrations)
PAPER = {("Spot-Uncover", "bc"): 85, ("Spot-Cover", "bc"): 60, ("Spot-Curtain", "bc"): 60,
         ("Spot-Uncover", "retrieval"): 90, ("Spot-Cover", "retrieval"): 80, ("Spot-Curtain", "retrieval"): 80}
DEMOS, NOISE, DEMO_SEED = 30, 0.1, 1000


def run(cmd: list[str], log: Path) -> subprocess.CompletedProcess:
    with open(log, "a") as f:
        f.write("$ " + " ".join(cmd) + "\n")
        f.flush()
        r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=f, text=True)
        f.write(r.stdout)
    if r.returncode != 0:
        sys.exit(f"failed (exit {r.returncode}): {' '.join(cmd)}; see {log}")
    return r


def one_task(binary: str, root: Path, task: str, encoder: str, methods: list[str]) -> None:
    target = f"MoDe-{task}-v0"
    data = root / task
    log = root / f"{task}.log"
    # `record` resumes a killed recording and does nothing once the dataset is complete
    run([binary, "record", target, "--episodes", str(DEMOS), "--seed", str(DEMO_SEED),
         "--noise", str(NOISE), "--cameras", "robot", "--encoder", encoder, "--out", str(data)], log)
    info = json.loads(run([binary, "dataset", "info", str(data), "--json"], log).stdout)
    done = {(r["task"], r["method"], r["inputs"]) for r in read_lines(root / "results.jsonl")}
    variants = ["features+state"] + (["features"] if task.startswith("Spot") else [])
    for inputs in variants:
        for method in methods:
            if (task, method, inputs) not in done:
                one_policy(binary, root, task, method, inputs, info, encoder, log)


def one_policy(binary: str, root: Path, task: str, method: str, inputs: str,
               info: dict, encoder: str, log: Path) -> None:
    target = f"MoDe-{task}-v0"
    algo, extra = METHODS[method]
    out = root / "policies" / inputs / method / task
    if not (out / "policy" / "policy.json").is_file():
        run([binary, "train", target, "--algo", algo, "--dataset", str(root / task), "--inputs", inputs,
             "--successful-only", "--out", str(out), *extra], log)
    r = run([binary, "eval", str(out), "--episodes", "20", "--json"], log)
    summary = json.loads(r.stdout.strip().splitlines()[-1])
    line = {"task": task, "method": method, "inputs": inputs, "encoder": encoder, "demos": info["episodes"],
            "demo_success_rate": info.get("success_rate"), "success_rate": summary["success_rate"],
            "mean_length": summary["mean_length"], "errors": summary["errors"]}
    append_line(root / "results.jsonl", line)
    print(json.dumps(line), flush=True)


def table(root: Path) -> str:
    rows = ["| task | method | inputs | demonstrations (successful) | success (20 held-out episodes) | mean length | paper (DINOv2 features, keyboard demos) |",
            "|---|---|---|---|---|---|---|"]
    for r in read_lines(root / "results.jsonl"):
        ok = round(r["demos"] * (r["demo_success_rate"] or 0))
        paper = PAPER.get((r["task"], METHODS.get(r["method"], (r["method"],))[0]))
        rows.append(f"| {r['task']} | {LABELS.get(r['method'], r['method'])} | {r['encoder']} {r['inputs']} "
                    f"| {r['demos']} ({ok}) | **{round(20 * r['success_rate'])}/20** | {r['mean_length']:.0f} "
                    f"| {f'{paper} %' if paper is not None else '-'} |")
    return "\n".join(rows)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--bin", default=os.path.expanduser("~/.cache/modesuite-target/release/modesuite"))
    p.add_argument("--data", default="data/il", type=Path)
    p.add_argument("--encoder", default="pooled")
    p.add_argument("--only", nargs="*", help="tasks, e.g. Spot-Uncover")
    p.add_argument("--methods", nargs="*", choices=list(METHODS), help="methods (default: all)")
    p.add_argument("--table", action="store_true")
    args = p.parse_args()
    if args.table:
        print(table(args.data))
        return
    args.data.mkdir(parents=True, exist_ok=True)
    for task in args.only or TASKS:
        one_task(args.bin, args.data, task, args.encoder, args.methods or list(METHODS))


if __name__ == "__main__":
    main()
