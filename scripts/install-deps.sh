#!/usr/bin/env bash
# Installs the Debian packages ivol needs to build and test. Idempotent and
# quick when everything is there; non-interactive.
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config
  libzstd-dev nlohmann-json3-dev libcli11-dev libtiff-dev libpng-dev
  # MetaImage and NRRD compressed samples
  zlib1g-dev
  libgtest-dev valgrind
  # SHA-256 of inputs and outputs (ivol verify --json, provenance): libcrypto
  libssl-dev
  # .ivol files read over HTTP(S) and s3:// by range (libformat); the remote
  # tests' real server (nginx) and the SigV4 check (botocore's signer)
  libcurl4-openssl-dev nginx-light python3-botocore
  libhdf5-dev libopenvdb-dev libboost-iostreams-dev
  hdf5-tools python3-h5py libopenvdb-tools libtiff-tools
  python3 python3-numpy python3-zstandard python3-tifffile
  ocl-icd-opencl-dev opencl-headers opencl-clhpp-headers pocl-opencl-icd clinfo libpugixml-dev
  # mpirun ivol recon: distributed reconstruction (docs/distributed.md)
  libopenmpi-dev openmpi-bin
  # bench/run_peers.sh: HDF5's blosc filter, the zstd CLI, plots
  hdf5-filter-plugin-blosc-serial zstd python3-matplotlib
  # cli_bad_input: OpenVDB grids at the edges of the index space; roundtrip_matrix
  python3-openvdb
  # the Python package (python/): ivol._ivol; python3-venv for the numpy 2
  # interpreter its tests also run under (below)
  pybind11-dev python3-dev python3-venv
  # the reference reader's checksums in C (format-spec/reference-reader; both paths tested)
  python3-crc32c python3-xxhash
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
if [ ${#missing[@]} -gt 0 ]; then
  echo "install-deps: installing ${missing[*]}" >&2
  export DEBIAN_FRONTEND=noninteractive
  $sudo apt-get update -qq
  $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# Users install numpy 2 from PyPI; Debian 12 has numpy 1.24 and pybind11
# 2.10, which predates numpy 2. The Python package's tests also run under an
# interpreter with numpy 2 from PyPI (ctest python_numpy2), a test tool, not
# a dependency of the product. Without network this is skipped with a
# warning, and CMake says the test is not registered.
numpy2=${IVOL_NUMPY2_VENV:-/opt/ivol-numpy2}
if [ ! -x "$numpy2/bin/python" ] || ! "$numpy2/bin/python" -c 'import numpy, sys; sys.exit(int(numpy.__version__.split(".")[0]) < 2)' 2>/dev/null; then
  echo "install-deps: numpy 2 test interpreter in $numpy2 (PyPI)" >&2
  if ! { $sudo /usr/bin/python3 -m venv "$numpy2" && $sudo "$numpy2/bin/pip" install -q --disable-pip-version-check "numpy>=2"; }; then
    echo "install-deps: warning: could not install numpy 2 from PyPI into $numpy2; ctest python_numpy2 will not run" >&2
    $sudo rm -rf "$numpy2"
  fi
fi
