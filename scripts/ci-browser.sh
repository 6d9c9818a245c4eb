#!/usr/bin/env bash
# CI: Debian's Chromium and its driver for the console's browser tests (tests/integration/
# test_console.py), installed from the distribution only when missing. Never a downloaded
# browser build. CI runs as root on Debian; elsewhere this only says what is missing.
set -euo pipefail
if [ -x /usr/bin/chromium ] && [ -x /usr/bin/chromedriver ]; then
    exit 0
fi
exec "$(dirname "$0")/apt-install.sh" ci-browser \
    "/usr/bin/chromium or /usr/bin/chromedriver is missing" \
    --no-install-recommends chromium chromium-driver
