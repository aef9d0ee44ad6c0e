#!/usr/bin/env bash
# Our FEM rod benchmark and MuJoCo 4.0 on the same reference rod, in one run, one after the other
# on the same machine (absolute speed drifts up to 1.5x between runs: compare within one run).
#
#   bash scripts/bench_peers.sh            (from the project root)
#
# Prints the machine, `modesuite bench fem --json` (release) and the peer harness's table for
# MuJoCo on R_stiff (369 nodes / 960 linear tets, one thread) and B (16 rods, 1 and all threads).
# Env: PEER_HARNESS (default ../shared/bench/peers), PEER_VENV (a venv with numpy and mujoco;
# created with only those if missing), PEER_ONLY (default R_stiff,B), CARGO_TARGET_DIR.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
HARNESS="${PEER_HARNESS:-$ROOT/../shared/bench/peers}"
PY="${PEER_PYTHON:-python3}"
TMPBASE="${TMPDIR:-/tmp}"
VENV="${PEER_VENV:-$TMPBASE/modesuite-peer-venv-mujoco}"

echo "== machine: $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ //'), $(date -u +%Y-%m-%dT%H:%MZ)"

echo "== modesuite bench fem --json (release)"
cd "$ROOT"
cargo build --release -q
TARGET="${CARGO_TARGET_DIR:-$ROOT/target}"
"$TARGET/release/modesuite" bench fem --json

if [ ! -x "$VENV/bin/python" ]; then
  echo "[bench_peers] creating venv $VENV (numpy, mujoco)" >&2
  "$PY" -m venv "$VENV"
  "$VENV/bin/pip" install -q --upgrade pip
  grep -E '^(numpy|mujoco|psutil)==' "$HARNESS/requirements.txt" > "$VENV/requirements.txt"
  "$VENV/bin/pip" install -q -r "$VENV/requirements.txt"
fi
echo "== MuJoCo $("$VENV/bin/python" -c 'import mujoco; print(mujoco.__version__)') (peer harness $HARNESS)"
PEER_VENV="$VENV" PEER_SKIP_GENESIS=1 PEER_PEERS=mujoco PEER_ONLY="${PEER_ONLY:-R_stiff,B}" \
  PEER_RESULTS="${PEER_RESULTS:-$TMPBASE/modesuite-peer-results}" bash "$HARNESS/run_all.sh"
