// What running libhdf5 in a child process (tools/isolated/isolated_worker.hpp)
// costs: the same HDF5 files read slab by slab, and a DXchange scan read
// band by band as ivol recon does, through the in-process readers and
// through the isolated ones, alternating, in one run.
//
//   hdf5_isolation_bench [--size N] [--views V] [--detector D] [--repeats R]
// The files are written with h5py (Debian's /usr/bin/python3) in a temporary
// folder.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "hdf5_io.hpp"
#include "isolated_worker.hpp"
#include "projection_io.hpp"

namespace {

using namespace ivol::convert;

double seconds_of(const std::function<void()>& work) {
  const auto start = std::chrono::steady_clock::now();
  work();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void read_volume(std::unique_ptr<SlabReader> reader, std::uint32_t slab) {
  const DenseVolume& shape = reader->shape();
  std::vector<std::uint8_t> buffer(std::size_t{slab} * shape.dims[0] * shape.dims[1] * sample_size(shape.type));
  for (std::uint32_t z = 0; z < shape.dims[2]; z += slab)
    reader->read(z, std::min(slab, shape.dims[2] - z), buffer.data());
}

void read_scan(ProjectionReader& scan, int band) {
  std::vector<float> rows(static_cast<std::size_t>(band) * scan.columns());
  for (int r = 0; r < scan.rows(); r += band)
    for (std::size_t v = 0; v < scan.view_count(); ++v)
      scan.read_rows(v, r, std::min(scan.rows(), r + band), rows.data());
}

}  // namespace

int main(int argc, char** argv) {
  ivol::convert::serve_if_worker_process();  // libhdf5's child is this binary again
  int size = 512, views = 360, detector = 512, repeats = 3;
  for (int a = 1; a + 1 < argc; a += 2) {
    const std::string name = argv[a];
    const int value = std::atoi(argv[a + 1]);
    if (name == "--size")
      size = value;
    else if (name == "--views")
      views = value;
    else if (name == "--detector")
      detector = value;
    else if (name == "--repeats")
      repeats = value;
  }
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "ivol-hdf5-isolation-bench";
  std::filesystem::create_directories(dir);
  const std::string make = "/usr/bin/python3 - " + dir.string() + " " + std::to_string(size) + " " +
                           std::to_string(views) + " " + std::to_string(detector) + R"( <<'PY'
import sys, numpy as np, h5py
d, n, views, det = sys.argv[1], *map(int, sys.argv[2:])
rng = np.random.default_rng(1)
z, y, x = np.ogrid[:n, :n, :n]
v = (1000 + 30000 * (((x - n/2)**2 + (y - n/2)**2 + (z - n/2)**2) < (n/3)**2)).astype(np.uint16)
v += rng.integers(0, 64, size=v.shape, dtype=np.uint16)
with h5py.File(d + "/plain.h5", "w") as f: f.create_dataset("/exchange/data", data=v)
with h5py.File(d + "/gzip.h5", "w") as f: f.create_dataset("/exchange/data", data=v, chunks=(32, 64, 64), compression="gzip", compression_opts=1, shuffle=True)
p = rng.random((views, det, det), dtype=np.float32)
with h5py.File(d + "/scan.h5", "w") as f: f.create_dataset("/exchange/data", data=p, chunks=(1, 16, det))
PY)";
  if (std::system(make.c_str()) != 0) return 1;
  std::printf(
      "# %d^3 uint16 volume read in 32-slice slabs; DXchange scan of %d views of %d^2 float32 read in 16-row bands of "
      "every view\n",
      size, views, detector);
  std::printf("%-22s %12s %12s %8s\n", "input", "in process s", "isolated s", "ratio");
  for (const char* name : {"plain.h5", "gzip.h5", "scan.h5"}) {
    const std::string path = (dir / name).string();
    std::vector<double> here, there;
    for (int r = 0; r < repeats; ++r) {
      if (std::string(name) == "scan.h5") {
        here.push_back(seconds_of([&] {
          read_scan(*open_dxchange_projections_in_process(path, {true, 1e-3}).projections, 16);
        }));
        there.push_back(seconds_of([&] { read_scan(*open_dxchange_projections(path, {true, 1e-3}).projections, 16); }));
      } else {
        here.push_back(seconds_of([&] { read_volume(open_hdf5_slabs_in_process(path), 32); }));
        there.push_back(seconds_of([&] { read_volume(open_hdf5_slabs(path), 32); }));
      }
    }
    const double a = *std::min_element(here.begin(), here.end()), b = *std::min_element(there.begin(), there.end());
    std::printf("%-22s %12.3f %12.3f %8.3f\n", name, a, b, b / a);
  }
  std::filesystem::remove_all(dir);
  return 0;
}
