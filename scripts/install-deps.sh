#!/usr/bin/env bash
# Installs every build and test dependency of lapflow from Debian 12 packages.
# Used by the README's set-up commands and by .ci/run. Run as root.
set -euo pipefail
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends \
  build-essential cmake ninja-build pkg-config git \
  libcgal-dev libeigen3-dev libgmp-dev libmpfr-dev \
  libopenmesh-dev \
  libopenimageio-dev openimageio-tools libopenexr-dev \
  libembree-dev \
  libtbb-dev \
  libopenvdb-dev libboost-iostreams-dev libblosc-dev \
  libcli11-dev libfmt-dev libtomlplusplus-dev nlohmann-json3-dev \
  libgtest-dev libgmock-dev libstb-dev fonts-dejavu-core ffmpeg gnuplot-nox \
  clang libclang-rt-14-dev \
  nodejs blender \
  >/dev/null
