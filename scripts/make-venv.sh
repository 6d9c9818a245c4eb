#!/usr/bin/env bash
# Make the virtual environment the Makefile installs rhbl into, from a given interpreter.
#
# usage: scripts/make-venv.sh PYTHON VENV
#   PYTHON  the interpreter to build it from (python3.11 or newer; a system python3 that is
#           "externally managed" (PEP 668) is fine: nothing is installed into it)
#   VENV    the directory (kept if it already holds a python with pip)
#
# On Debian and Ubuntu the venv module's pip bootstrap (ensurepip) comes in a separate package,
# python3-venv. Without it, this script falls back to a venv without pip, into which the
# system's own pip (python3-pip, 22.3 or newer for `pip --python`) installs pip; without either
# it stops and names the package to install.
set -euo pipefail

if [ $# -ne 2 ]; then
    echo "usage: $0 PYTHON VENV" >&2
    exit 2
fi
python=$1
venv=$2

if [ -x "$venv/bin/python" ] && "$venv/bin/python" -m pip --version >/dev/null 2>&1; then
    exit 0
fi
if ! command -v "$python" >/dev/null 2>&1; then
    echo "make: no Python interpreter '$python' (install Python 3.11 or newer, or run" \
         "make PYTHON=/path/to/python3.11 ...)" >&2
    exit 1
fi
if ! "$python" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
    echo "make: $python is Python $("$python" -c 'import platform; print(platform.python_version())'):" \
         "rhbl needs 3.11 or newer (run make PYTHON=/path/to/python3.11 ...)" >&2
    exit 1
fi

echo "make: creating the virtual environment $venv from $python"
err=$(mktemp)
trap 'rm -f "$err"' EXIT
if "$python" -m venv "$venv" >"$err" 2>&1; then
    exit 0
fi
cause=$(tail -n 3 "$err")
rm -rf "$venv"

# python3-venv missing (ensurepip unavailable): a venv without pip, and pip from the system's pip
if "$python" -m venv --without-pip "$venv" 2>/dev/null &&
   "$python" -m pip --help 2>/dev/null | grep -e '--python' >/dev/null &&
   "$python" -m pip --python "$venv/bin/python" install --quiet pip; then
    echo "make: $python has no ensurepip; pip was installed into $venv by the system's pip"
    exit 0
fi
rm -rf "$venv"
echo "make: cannot create a virtual environment with $python:" >&2
[ -n "$cause" ] && printf '  %s\n' "$cause" >&2
echo "make: on Debian or Ubuntu install the venv module's pip bootstrap first:" \
     "sudo apt-get install python3-venv" >&2
exit 1
