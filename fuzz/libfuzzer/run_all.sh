#!/usr/bin/env bash
# Runs every libFuzzer target in turn for SECONDS (default 60) each and prints libFuzzer's final
# stats line per target. Build first (see README.md). Usage: ./run_all.sh [SECONDS] [TARGET...]
set -euo pipefail
cd "$(dirname "$0")"
secs="${1:-60}"
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(mesh_obj mesh_stl mesh_msh mesh_medit urdf robot_file scene_ron)
fi
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$PWD/target}"
mkdir -p logs
status=0
for t in "${targets[@]}"; do
    mkdir -p "corpus/$t"
    echo "== $t (${secs} s, load $(cut -d' ' -f1-3 /proc/loadavg))"
    # The parsers of shipped files start from the shipped files themselves.
    case "$t" in
        urdf | robot_file) seeds=../../assets/robots ;;
        scene_ron) seeds=../../scenes/examples ;;
        *) seeds="seeds/$t" ;;
    esac
    if ! cargo +nightly fuzz run -O --fuzz-dir . "$t" "corpus/$t" "$seeds" -- \
        -max_total_time="$secs" -rss_limit_mb=2048 -timeout=20 >"logs/$t.log" 2>&1; then
        echo "   FAILED: see logs/$t.log and artifacts/$t/"
        status=1
    fi
    grep -E '^#[0-9]+[[:space:]]+DONE' "logs/$t.log" | tail -1 || true
done
exit $status
