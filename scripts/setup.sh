#!/usr/bin/env bash
# SPDX-License-Identifier: LGPL-2.1-or-later
# Idempotent set-up on Debian 12: FreeCAD (Debian's freecad-python3), Xvfb, the runtime
# Python packages where FreeCAD finds them, and a .venv on FreeCAD's Python for the CLI
# and the tests. Fast when everything is already there.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
cd "$ROOT"
SYSTEM_PYTHON=/usr/bin/python3

missing=()
command -v freecadcmd >/dev/null 2>&1 || missing+=(freecad-python3)
command -v xvfb-run >/dev/null 2>&1 || missing+=(xvfb xauth)
command -v xdotool >/dev/null 2>&1 || missing+=(xdotool)  # real key events in the GUI tests
command -v chromium >/dev/null 2>&1 || missing+=(chromium)  # headless test of the batch summary page
$SYSTEM_PYTHON -c "import ensurepip, venv" >/dev/null 2>&1 || missing+=(python3-venv)
$SYSTEM_PYTHON -c "import numpy, scipy" >/dev/null 2>&1 || missing+=(python3-numpy python3-scipy)
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing Debian packages: ${missing[*]}"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO=sudo
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q "${missing[@]}" >/dev/null
fi

APPDATA=$(cd /tmp && freecadcmd -c "import FreeCAD; print('APPDATA=' + FreeCAD.getUserAppDataDir())" 2>/dev/null \
          | sed -n 's/^APPDATA=//p' | tail -n 1)
[ -n "$APPDATA" ] || { echo "setup: error: could not ask freecadcmd for its user data folder" >&2; exit 1; }
PACKAGES="${APPDATA%/}/AdditionalPythonPackages"
mkdir -p "$PACKAGES"

if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv on $SYSTEM_PYTHON (the Python FreeCAD is built for)"
  $SYSTEM_PYTHON -m venv --system-site-packages .venv
fi
SITE=$(.venv/bin/python -c "import sysconfig; print(sysconfig.get_paths()['purelib'])")
echo /usr/lib/freecad-python3/lib > "$SITE/freecad.pth"
echo "$PACKAGES" > "$SITE/polycube_runtime.pth"

stamp_value=$(cat requirements.txt requirements-dev.txt | sha256sum | cut -c1-16)
stamp_file=.venv/.polycube-setup-stamp
if [ "$(cat "$stamp_file" 2>/dev/null)" != "$stamp_value:$PACKAGES" ] || \
   ! .venv/bin/python -c "import trimesh, manifold3d, skimage.morphology, igl, threadpoolctl, numba, mumps, pytest, FreeCAD" >/dev/null 2>&1; then
  echo "setup: installing runtime packages into $PACKAGES"
  # --no-deps: numpy and scipy must stay Debian's (FreeCAD's own modules are built against them);
  # pip's warning that scikit-image's optional image-file readers are missing is expected.
  .venv/bin/pip install -q --disable-pip-version-check --no-deps --upgrade --target "$PACKAGES" \
    -r requirements.txt > .venv/pip-runtime.log 2>&1 || { cat .venv/pip-runtime.log >&2; exit 1; }
  echo "setup: installing test tools into .venv"
  .venv/bin/pip install -q --disable-pip-version-check -r requirements-dev.txt > .venv/pip-dev.log 2>&1 \
    || { cat .venv/pip-dev.log >&2; exit 1; }
  echo "$stamp_value:$PACKAGES" > "$stamp_file"
fi
.venv/bin/python -c "import numpy, scipy, trimesh, manifold3d, skimage.morphology, igl, threadpoolctl, numba, mumps, FreeCAD, Part" \
  || { echo "setup: error: the packages do not import in .venv" >&2; exit 1; }
(cd /tmp && freecadcmd -c "import trimesh, manifold3d, igl, threadpoolctl, numba, mumps; print('setup: FreeCAD sees trimesh', trimesh.__version__)" 2>/dev/null | grep -q "setup: FreeCAD sees") \
  || { echo "setup: error: freecadcmd cannot import the runtime packages from $PACKAGES" >&2; exit 1; }
# numba compiles the spatial queries once per machine (about 10 s) and caches them in core's __pycache__ folders
compiled=$(.venv/bin/python -c "from core.precompile import compile_now; print('%.1f' % compile_now())") \
  || { echo "setup: error: numba could not compile the spatial queries (core/precompile.py)" >&2; exit 1; }
case "$compiled" in 0.*) ;; *) echo "setup: compiled the spatial queries with numba in $compiled s" ;; esac
