#!/usr/bin/env bash
# Writes constraints.txt: the exact version of every Python package that scripts/setup.sh installs
# (pip's -c), resolved afresh to the newest versions that pyproject.toml accepts, in a throwaway
# virtual environment.  Run it to move the project to newer dependencies, then run the tests
# (make test) and the reproduction (make reproduce) on the new versions before committing both.
set -euo pipefail
cd "$(dirname "$0")/.."

PY=${PYTHON:-python3}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$PY" -m venv "$tmp/venv"
"$tmp/venv/bin/python" -m pip install -q -e '.[all,test]'
{
  echo "# The exact versions scripts/setup.sh installs (pip install -c constraints.txt): make test and"
  echo "# make reproduce run on the same packages on every machine and day.  pyproject.toml keeps the"
  echo "# ranges that an install of the package itself accepts.  Written by scripts/lock.sh with"
  echo "# $("$tmp/venv/bin/python" -c 'import platform; print("Python", platform.python_version())'); do not edit by hand."
  "$tmp/venv/bin/python" -m pip freeze --exclude-editable | grep -v -i '^trustseek[= ]'
} > constraints.txt.new
mv constraints.txt.new constraints.txt
echo "lock: wrote constraints.txt ($(grep -c '==' constraints.txt) packages)"
