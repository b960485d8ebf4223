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
  # .ivol files read over HTTP(S) by range (libformat)
  libcurl4-openssl-dev
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
  # the Python package (python/): ivol._ivol
  pybind11-dev python3-dev
  # the reference reader's checksums in C (format-spec/reference-reader; both paths tested)
  python3-crc32c python3-xxhash
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
echo "install-deps: installing ${missing[*]}" >&2
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
