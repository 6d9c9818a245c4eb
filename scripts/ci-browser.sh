#!/usr/bin/env bash
# CI: Debian's Chromium and its driver for the console's browser tests (tests/integration/
# test_console.py), installed from the distribution only when missing. Never a downloaded
# browser build. CI runs as root on Debian; elsewhere this only says what is missing.
set -euo pipefail
if [ -x /usr/bin/chromium ] && [ -x /usr/bin/chromedriver ]; then
    exit 0
fi
if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null; then
    echo "ci-browser: /usr/bin/chromium or /usr/bin/chromedriver is missing and this is not" \
         "root on Debian: install the packages chromium and chromium-driver" >&2
    exit 1
fi
export DEBIAN_FRONTEND=noninteractive
apt-get update
apt-get install -y --no-install-recommends chromium chromium-driver
