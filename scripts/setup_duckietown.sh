#!/usr/bin/env bash
# One command for the Duckietown virtualenv (.venv-duckietown) that `crossing-iil --env duckietown` needs.
#
#   scripts/setup_duckietown.sh            # after the README's install (.venv with '.[train,dev]')
#   MAIN_VENV=/path/to/.venv scripts/setup_duckietown.sh   # borrow torch & co. from another venv
#
# duckietown-gym-daffy 6.1.34 needs pyglet 1.5.x and numpy < 1.24 (its dynamics build a ragged
# array), while the project's .venv has numpy 2; so it gets its own venv, which borrows torch,
# gymnasium, pytest and the editable crossing_assist from the main venv through a .pth file.
# As root with apt-get, it also installs the EGL/Mesa libraries for headless rendering.
# About 4 min of pip (sdist builds) and ~850 MB on disk. Idempotent: re-running only checks.
set -euo pipefail
REPO="$(cd "$(dirname "$0")/.." && pwd)"
MAIN_VENV="${MAIN_VENV:-$REPO/.venv}"
DT_VENV="${DT_VENV:-$REPO/.venv-duckietown}"
PY="${PYTHON:-python3.11}"

main_site="$("$MAIN_VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])' 2>/dev/null)" || {
  echo "error: $MAIN_VENV/bin/python not found; install the project first (README) or set MAIN_VENV" >&2; exit 2; }
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  if ! dpkg -s libegl1 libegl-mesa0 libgl1-mesa-dri libglu1-mesa >/dev/null 2>&1; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
      libegl1 libegl-mesa0 libgl1-mesa-dri libglu1-mesa >/dev/null
  fi
fi
[ -x "$DT_VENV/bin/python" ] || "$PY" -m venv "$DT_VENV"
"$DT_VENV/bin/pip" install -q "duckietown-gym-daffy==6.1.34" "pyglet>=1.5,<1.6" "numpy<1.24"
dt_site="$("$DT_VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
printf '%s\n' "$main_site" "$REPO" > "$dt_site/zz_main_venv.pth"
"$DT_VENV/bin/python" - <<'PY'
from crossing_assist.iil.envs.duckietown import duckietown_available
ok, why = duckietown_available()
if not ok:
    raise SystemExit(f"error: Duckietown still unavailable: {why}")
print("duckietown: ready")
PY
echo "done: $DT_VENV (run: $DT_VENV/bin/python -m crossing_assist.iil.cli run --env duckietown ...)"
