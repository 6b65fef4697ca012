#!/usr/bin/env bash
# Set up teleprev in .venv: finds Python 3.12 (pyenv's or one on PATH), installs uv if missing,
# and installs the locked dependencies (uv.lock) with the project in editable mode.
# Arguments go to `uv sync`: `bash scripts/setup.sh --extra ray` adds an optional extra (test.sh does).
set -euo pipefail
cd "$(dirname "$0")/.."

is_312() { [ -n "$1" ] && [ -x "$1" ] && "$1" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 12))' 2>/dev/null; }

PY=""
candidates=("${TELEPREV_PYTHON:-}" "$(command -v python3.12 2>/dev/null || true)")
if command -v pyenv >/dev/null 2>&1; then
  for v in "$(pyenv root)"/versions/3.12*/bin/python3.12; do candidates+=("$v"); done
fi
candidates+=("$HOME"/.pyenv/versions/3.12*/bin/python3.12 /usr/local/bin/python3.12 /usr/bin/python3.12)
for c in "${candidates[@]}"; do
  if is_312 "$c"; then PY="$c"; break; fi
done
if [ -z "$PY" ]; then
  echo "teleprev needs Python 3.12 (lerobot 0.6 requires it). Install one (e.g. 'pyenv install 3.12') or set TELEPREV_PYTHON." >&2
  exit 1
fi

if ! "$PY" -m uv --version >/dev/null 2>&1; then
  echo "installing uv for $PY" >&2
  "$PY" -m pip install --quiet --disable-pip-version-check uv
fi
# --inexact: an extra installed before (test.sh's ray) stays when this runs without it (demo.sh).
# TELEPREV_SETUP_DRY_RUN=1 only says what uv would change (tests/test_scripts.py).
if [ -n "${TELEPREV_SETUP_DRY_RUN:-}" ]; then
  exec "$PY" -m uv sync --frozen --inexact --python "$PY" --dry-run "$@"
fi
"$PY" -m uv sync --frozen --inexact --python "$PY" --quiet "$@"
# Compile every numba kernel (teleprev/kernels/) into numba's on-disk cache
# now, so that no record or eval pays the seconds of compiling; `teleprev --help` never loads them.
.venv/bin/python -c 'from teleprev.kernels import warm; warm()'
