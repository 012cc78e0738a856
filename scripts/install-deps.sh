#!/usr/bin/env bash
# Installs the Debian packages deformbench needs, only those missing. Safe to rerun.
# --tests adds what only the test suite needs (a single-node Slurm for dispatch_slurm_e2e).
set -euo pipefail
PACKAGES=(
  build-essential cmake ninja-build pkg-config git
  libeigen3-dev libsuitesparse-dev libbullet-dev libode-dev libgmsh-dev libqhull-dev
  libnanoflann-dev nlohmann-json3-dev libcli11-dev libssl-dev
  libcgal-dev libgmp-dev libmpfr-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  clang libclang-rt-14-dev llvm clang-format
  libopenblas0-serial liblapack3 liblapack-dev  # OpenBLAS's LAPACK: particle_bem's dense BEM solve
  python3-matplotlib python3-numpy
  libjs-three chromium python3-pil  # the report's 3D viewer (three.js) and its browser test
  openmpi-bin libopenmpi-dev
  libnlopt-dev libnlopt-cxx-dev  # deformbench calibrate
  calculix-ccx  # the calculix plugin: an independent nonlinear FEM (ccx), run as a child process
)
if [[ ${1:-} == --tests ]]; then PACKAGES+=(slurm-wlm munge); fi
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} Debian packages present"
  exit 0
fi
echo "install-deps: installing ${missing[*]}"
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
