#!/usr/bin/env bash
# Set-up shared by scripts/run.sh and scripts/test.sh: everything a fresh Debian machine with
# Rust and Python needs, installed here, never by hand. Idempotent and quiet when all is present.
set -euo pipefail
cd "$(dirname "$0")/.."

# Rust toolchain components used by the test command.
if ! command -v cargo >/dev/null 2>&1; then
    echo "setup: cargo not found; install Rust (https://rustup.rs) first" >&2
    exit 1
fi
if command -v rustup >/dev/null 2>&1; then
    for c in rustfmt clippy; do
        if ! rustup component list --installed 2>/dev/null | grep -q "^$c"; then
            echo "setup: installing rust component $c"
            rustup component add "$c"
        fi
    done
fi

# System packages (Debian). One package per line in scripts/apt-packages.txt; comments allowed.
missing=()
while read -r pkg; do
    pkg="${pkg%%#*}"; pkg="$(echo "$pkg" | xargs)"
    [ -z "$pkg" ] && continue
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done < scripts/apt-packages.txt
if [ ${#missing[@]} -gt 0 ]; then
    echo "setup: installing system packages: ${missing[*]}"
    SUDO=""
    [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

# Build outputs outside the clone, so a later clone on the same machine reuses them.
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/modesuite-target}"
