#!/usr/bin/env bash
# CI (and `make compose-test`): what the compose scenario in real containers needs
# (docker/compose_test.py, tests/integration/test_compose_containers.py), installed from the
# distribution only when missing: podman and runc (the runtime docker/containers.conf selects)
# to run containers, mmdebstrap to make the Python base image from Debian packages where no
# image registry answers. Never a downloaded binary. podman-compose comes from PyPI with the
# project's dev dependencies (make install). A machine with a working Docker needs none of it.
# As root on Debian this installs what is missing; elsewhere it only says what is missing.
set -euo pipefail
missing=()
for tool in podman runc mmdebstrap; do
    command -v "$tool" >/dev/null || missing+=("$tool")
done
if [ "${#missing[@]}" -eq 0 ]; then
    exit 0
fi
if command -v docker >/dev/null && docker info >/dev/null 2>&1; then
    exit 0  # Docker runs the scenario (and pulls the upstream images)
fi
exec "$(dirname "$0")/apt-install.sh" ci-containers "${missing[*]} missing" \
    podman runc uidmap fuse-overlayfs slirp4netns mmdebstrap
