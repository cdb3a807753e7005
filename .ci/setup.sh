#!/usr/bin/env bash
# Shared set-up for the README's two commands: Debian packages (only those missing), a virtual
# environment in .venv and the project installed into it. Safe to run again; it only does what is missing.
# Sourced by .ci/demo and .ci/test; sets VENV_PY.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${STUDYAPP_VENV:-$ROOT/.venv}"

# Debian/Ubuntu packages the app and its tests use at run time:
#  python3-venv: the virtual environment; libportaudio2: sounddevice; libegl1/libegl-mesa0/libgl1-mesa-dri:
#  headless OpenGL (EGL on Mesa llvmpipe); libosmesa6: the OSMesa fallback; xvfb + xdotool + imagemagick:
#  the window tests; pulseaudio (+utils, alsa plugins): a null audio sink on machines without a sound card;
#  fonts-wqy-microhei: a CJK font, so designs in Chinese render (and their test has a font to find);
#  postgresql: the tests of the PostgreSQL results backend start a throw-away server from its binaries;
#  chromium + chromium-driver: the headless browser (and its WebDriver) the study server's real-browser test
#  drives through selenium (tests/web/test_web_browser.py).
DEB_PKGS=(python3 python3-venv python3-pip libportaudio2 libegl1 libegl-mesa0 libgl1-mesa-dri libglx-mesa0
          libosmesa6 xvfb xauth xdotool imagemagick pulseaudio pulseaudio-utils libasound2-plugins
          fonts-wqy-microhei postgresql chromium chromium-driver)
missing=()
if command -v dpkg-query >/dev/null 2>&1; then
  for p in "${DEB_PKGS[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
fi
# A Python from elsewhere (pyenv, a distribution other than Debian's) already brings venv and pip.
if [ ${#missing[@]} -gt 0 ] && python3 -c 'import venv, ensurepip' >/dev/null 2>&1; then
  keep=(); for p in "${missing[@]}"; do case "$p" in python3|python3-venv|python3-pip) ;; *) keep+=("$p");; esac; done
  missing=("${keep[@]+"${keep[@]}"}")
fi
if [ ${#missing[@]} -gt 0 ]; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && command -v sudo >/dev/null 2>&1 && SUDO="sudo"
  echo "[setup] installing Debian packages: ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

if [ ! -x "$VENV/bin/python" ]; then
  echo "[setup] creating virtual environment $VENV"
  python3 -m venv "$VENV"
fi
VENV_PY="$VENV/bin/python"
stamp="$VENV/.studyapp-installed"
if [ ! -f "$stamp" ] || [ "$ROOT/pyproject.toml" -nt "$stamp" ]; then
  echo "[setup] installing studyapp and its dependencies into $VENV"
  "$VENV_PY" -m pip install -q --upgrade pip
  "$VENV_PY" -m pip install -q -e "$ROOT[all,test]"   # every extra: CI tests them all
  touch "$stamp"
fi
export VENV_PY
