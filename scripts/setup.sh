#!/usr/bin/env bash
# Installs everything trustseek needs on a fresh Debian machine, idempotently:
#   - Debian packages: chromium (browser tests, HTML report screenshots), fonts, a C compiler
#     and Python's headers (the package's compiled loops), and postgresql (the experiment
#     server's PostgreSQL tests start a throwaway cluster)
#   - a Python virtual environment in .venv with trustseek and its test extras, at the exact
#     versions of constraints.txt (scripts/lock.sh writes it)
#   - the web front end (npm ci + build), when web/ exists
set -euo pipefail
cd "$(dirname "$0")/.."

PY=${PYTHON:-python3}
UV_VERSION=0.13.9 # the installer of the Python packages

if ! command -v chromium >/dev/null 2>&1; then
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "setup: installing chromium from Debian packages"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver fonts-dejavu-core >/dev/null
  else
    echo "setup: chromium not found and cannot apt-get install it (need root); the browser tests (tests/web/test_browser.py, tests/report/test_report_browser.py) will fail until it is installed" >&2
  fi
fi

# a C compiler and Python's headers: the package's loops are compiled when it is installed
if ! command -v cc >/dev/null 2>&1 || [ ! -f "$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')/Python.h" ]; then
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "setup: installing a C compiler and Python's headers from Debian packages"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq gcc python3-dev >/dev/null
  else
    echo "setup: no C compiler or no Python headers, and cannot apt-get install them (need root); the install will fail" >&2
  fi
fi

if ! ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1; then
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "setup: installing postgresql from Debian packages"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq postgresql >/dev/null
  else
    echo "setup: PostgreSQL server not found and cannot apt-get install it (need root); PostgreSQL tests will be skipped" >&2
  fi
fi

if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  "$PY" -m venv .venv
fi
stamp=.venv/.trustseek-installed
# (again when an extension's source changed: pip builds the compiled extensions of setup.py)
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ constraints.txt -nt "$stamp" ] || [ setup.py -nt "$stamp" ] ||
  [ -n "$(find src \( -name '*.pyx' -o -name '*.pxd' \) -newer "$stamp" 2>/dev/null | head -1)" ]; then
  echo "setup: installing Python packages (the versions of constraints.txt)"
  # with uv (at its own pinned version): the same packages as pip's install of constraints.txt,
  # compiled to bytecode as pip does, in about a third of the time (27 s against 90 s on 2 cores);
  # pip's index and wheel folder, when the environment sets them, are uv's too.  Where uv cannot
  # install them (an index set only in pip's own configuration file, say), pip does.
  if ! { .venv/bin/python -m pip install -q "uv==$UV_VERSION" &&
    .venv/bin/uv pip install -q --compile-bytecode --python .venv/bin/python \
      ${PIP_INDEX_URL:+--index-url "$PIP_INDEX_URL"} ${PIP_FIND_LINKS:+--find-links "$PIP_FIND_LINKS"} \
      -c constraints.txt -e '.[all,test]'; }; then
    echo "setup: uv could not install the packages; installing them with pip" >&2
    .venv/bin/python -m pip install -q -c constraints.txt -e '.[all,test]'
  fi
  touch "$stamp"
fi

if [ -f web/package.json ]; then
  webstamp=web/node_modules/.trustseek-built
  if [ ! -f "$webstamp" ] || [ -n "$(find web/src web/package.json web/package-lock.json -newer "$webstamp" 2>/dev/null | head -1)" ]; then
    echo "setup: building the web front end"
    (cd web && npm ci --no-audit --no-fund --loglevel=error && npm run build --silent)
    touch "$webstamp"
  fi
fi
