#!/usr/bin/env bash
# What the tests need from the operating system, installed when missing (the first step of the
# README's test command, so of .ci/run): tests/test_gui.py runs sumo-gui (from the eclipse-sumo
# wheel) on a virtual X display; no PyPI package ships an X server, so Xvfb and the X11/GL
# libraries sumo-gui links come from the system's packages (Debian/Ubuntu: apt-get, as root or
# through sudo). Elsewhere it says what to install and fails: the GUI tests would fail anyway.
set -euo pipefail
PKGS="xvfb libgl1 libx11-6 libxext6 libxrender1"
missing=0
command -v Xvfb >/dev/null 2>&1 || missing=1
for lib in libGL.so.1 libX11.so.6 libXext.so.6 libXrender.so.1; do
  ldconfig -p 2>/dev/null | grep -q "$lib" || missing=1
done
[ "$missing" = 0 ] && exit 0
if command -v apt-get >/dev/null 2>&1; then
  if [ "$(id -u)" = 0 ]; then SUDO=""; elif command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else SUDO="none"; fi
  if [ "$SUDO" != none ]; then
    echo "tests/system_deps.sh: installing $PKGS (apt-get) for the sumo-gui tests" >&2
    $SUDO apt-get update -qq && $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $PKGS >/dev/null
    exit 0
  fi
fi
echo "tests/system_deps.sh: the sumo-gui tests need Xvfb and the X11/GL libraries (Debian: $PKGS); install them and run again" >&2
exit 1
