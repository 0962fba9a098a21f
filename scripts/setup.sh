#!/usr/bin/env bash
# Installs the Debian 12 packages hsd needs (apt; sudo when not root). Idempotent:
# does nothing when everything is already installed. Nothing is downloaded at
# build time; everything comes from Debian.
set -euo pipefail
PKGS=(build-essential cmake ninja-build
      libtorch-dev libopencv-dev libopenexr-dev nlohmann-json3-dev catch2 libgloo-dev zlib1g-dev
      libopenblas0-pthread python3-torch
      libgdsii-dev python3-gdspy)  # two independent GDSII readers for the fabrication tests
missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  echo "setup: installing ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
# Debian's LibTorch multiplies matrices with whatever BLAS the alternatives point
# to; without OpenBLAS that is the reference BLAS (~17x slower). Say which one.
blas=$(readlink -f /usr/lib/x86_64-linux-gnu/libblas.so.3 2>/dev/null || true)
case "$blas" in
  *openblas*) ;;
  *) echo "setup: warning: BLAS is $blas, not OpenBLAS; matrix products will be slow" >&2 ;;
esac
