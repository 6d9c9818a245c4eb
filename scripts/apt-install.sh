#!/usr/bin/env bash
# Debian packages for CI, the one way: as root where apt-get exists, `apt-get update` and
# `apt-get install -y` of the given packages; elsewhere one line saying what is missing and
# which packages to install, exit 1. Never a downloaded binary.
# usage: scripts/apt-install.sh NAME WHAT-IS-MISSING [--no-install-recommends] PACKAGE...
set -euo pipefail
name="$1" missing="$2"
shift 2
packages=()
for arg in "$@"; do
    [[ "$arg" == -* ]] || packages+=("$arg")
done
if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null; then
    echo "$name: $missing and this is not root on Debian: install the packages" \
         "${packages[*]}" >&2
    exit 1
fi
export DEBIAN_FRONTEND=noninteractive
apt-get update
apt-get install -y "$@"
