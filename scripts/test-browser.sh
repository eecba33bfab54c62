#!/usr/bin/env bash
# Browser tests of `mvem serve`: Playwright (Python) driving Debian's Chromium, headless.
# Installs what it needs on a fresh Debian machine: the chromium package (apt-get, as root) if
# /usr/bin/chromium is missing, and playwright + pytest into .venv-browser (no browser download:
# Playwright is pointed at /usr/bin/chromium). Builds the CLI (Cargo profile $MVEM_PROFILE, default
# release; scripts/test-all.sh sets ci), then runs tests/browser with pytest.
# Screenshots and timings go to target/browser-artifacts/.
set -euo pipefail
cd "$(dirname "$0")/.."
root="$PWD"
venv="$root/.venv-browser"
start=$(date +%s)

if [ ! -x /usr/bin/chromium ]; then
    if [ "$(id -u)" -ne 0 ]; then
        echo "test-browser.sh: /usr/bin/chromium is missing; install Debian's chromium package (apt-get install chromium)" >&2
        exit 2
    fi
    echo "== installing chromium (apt-get)"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -q >/dev/null
    apt-get install -y -q --no-install-recommends chromium >/dev/null
fi

if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install -q --upgrade pip >/dev/null
"$venv/bin/python" -m pip install -q "playwright>=1.40,<2" pytest

profile="${MVEM_PROFILE:-release}"
echo "== building the CLI (profile $profile)"
cargo build -q --profile "$profile" -p mvem-cli
export MVEM_CLI="$root/target/$profile/mvem"
export MVEM_ARTIFACTS="$root/target/browser-artifacts"
mkdir -p "$MVEM_ARTIFACTS"

echo "== pytest tests/browser ($(/usr/bin/chromium --version 2>/dev/null || echo chromium))"
"$venv/bin/python" -m pytest -q tests/browser
echo "test-browser.sh: done in $(( $(date +%s) - start )) s; artifacts in target/browser-artifacts/"
