// ivol against the formats and tools users would pick instead (issue 9).
//
//   peers_bench storage --size N --phantom NAME... --work DIR
//       For each phantom: the noisy scan reconstructed with the dense FDK
//       (cached in DIR), then every format writes it and reads back the whole
//       volume, a z-slice, an x-slice, a 64^3 region and a 1/8-resolution
//       preview. Two fidelities, each the same for every format in it:
//         "object": the voxels within 3 voxels of the object (above half of
//           Otsu's threshold) kept exactly as binary16; the rest may be
//           dropped (ivol: mean-valued octree leaves; OpenVDB: inactive
//           background) or set to the background (HDF5, TIFF: they cannot
//           drop voxels);
//         "all": every voxel as binary16 (and raw float32 as the reference).
//       One JSON line per format and fidelity on stdout.
//   peers_bench recon --size N --phantom NAME --export DIR
//       Dense and octree FDK of the noisy scan, timed; exports what RTK and
//       the accuracy check need (bench/run_peers.sh runs them).
//   peers_bench stack --size N --phantom NAME --work DIR --out DIR
//       The cached volume quantised to uint16, as an uncompressed TIFF stack
//       (DIR/stack/) and the same bytes raw (DIR/volume.u16), for the
//       conversion benchmark.
//
// Each read opens the file anew, after its pages were written back and
// dropped from the page cache (posix_fadvise DONTNEED): times are cold reads.
// Bytes read are counted two ways: what the library asked for with
// read()/pread() (/proc/self/io rchar; it counts a re-read twice, e.g. an
// ifstream refilling its buffer after a seek), and what the read brought into
// the page cache (mincore afterwards; distinct pages, the kernel's readahead
// included). Writes end in the page cache; they are not synced.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "ivol/binary16.hpp"
#include "ivol/keep_mask.hpp"
#include "peers/peer_format.hpp"
#include "peers/scan.hpp"

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

struct Measured {
  double seconds = 0;
  std::uint64_t bytes = 0;       // asked for by read()/pread() calls (rchar)
  std::uint64_t cold_bytes = 0;  // fetched into the page cache (mincore)
  std::vector<float> values;
};

// Every read starts with the file out of the page cache: its time is a cold
// read, and what is in the cache afterwards is what it fetched.
template <class Read>
Measured measure(const std::string& path, Read&& read) {
  Measured m;
  peers::flush_and_evict(path);
  const std::uint64_t before = peers::bytes_read_by_process();
  const auto start = Clock::now();
  m.values = read();
  m.seconds = since(start);
  m.bytes = peers::bytes_read_by_process() - before;
  m.cold_bytes = peers::bytes_in_page_cache(path);
  return m;
}

// The 64^3 region a user would look at: of the boxes on a 32-voxel grid, the
// one holding the most kept voxels (on the object, where files are densest).
ivol::Box busiest_region(const std::vector<std::uint8_t>& keep, std::uint32_t n) {
  ivol::Box best{{0, 0, 0}, {64, 64, 64}};
  std::uint64_t best_count = 0;
  for (std::uint32_t z = 0; z + 64 <= n; z += 32)
    for (std::uint32_t y = 0; y + 64 <= n; y += 32)
      for (std::uint32_t x = 0; x + 64 <= n; x += 32) {
        std::uint64_t count = 0;
        for (std::uint32_t k = z; k < z + 64; ++k)
          for (std::uint32_t j = y; j < y + 64; ++j) {
            const std::uint8_t* row = keep.data() + (std::uint64_t{k} * n + j) * n + x;
            count += static_cast<std::uint64_t>(std::count(row, row + 64, std::uint8_t{1}));
          }
        if (count > best_count) {
          best_count = count;
          best = ivol::Box{{x, y, z}, {x + 64, y + 64, z + 64}};
        }
      }
  return best;
}

// Largest |read - expected| over the voxels that must survive.
double max_error(const std::vector<float>& read, const std::vector<float>& expected,
                 const std::vector<std::uint8_t>* keep) {
  if (read.size() != expected.size()) return INFINITY;
  double worst = 0;
  for (std::size_t i = 0; i < read.size(); ++i)
    if (!keep || (*keep)[i]) worst = std::max(worst, std::abs(double(read[i]) - expected[i]));
  return worst;
}

std::string json_box(const ivol::Box& b) {
  char text[96];
  std::snprintf(text, sizeof text, "[%u, %u, %u, %u, %u, %u]", b.lo[0], b.lo[1], b.lo[2], b.hi[0], b.hi[1], b.hi[2]);
  return text;
}

void run_format(peers::PeerFormat& format, const peers::VolumeCase& volume, const std::string& fidelity,
                const std::string& phantom, const std::string& work, const ivol::Box& region,
                const std::vector<float>& float32_volume) {
  const std::uint32_t n = volume.n;
  std::string stem = format.name();
  std::replace(stem.begin(), stem.end(), ' ', '_');
  const std::string path = work + "/" + stem + "_" + fidelity;
  std::filesystem::remove_all(path);
  const bool is_float32 = format.name() == "raw float32";
  peers::VolumeCase input = volume;
  if (is_float32) input.values = &float32_volume;  // the reconstruction as it came

  const auto start = Clock::now();
  format.write(input, path);
  const double write_seconds = since(start);
  const std::uint64_t file_bytes = peers::bytes_on_disk(path);

  const Measured all = measure(path, [&] { return format.read_box(path, n, ivol::Box{{0, 0, 0}, {n, n, n}}); });
  const double error = max_error(all.values, *input.values, volume.keep);
  const Measured slice_z = measure(path, [&] {
    return format.read_box(path, n, ivol::Box{{0, 0, n / 2}, {n, n, n / 2 + 1}});
  });
  const Measured slice_x = measure(path, [&] {
    return format.read_box(path, n, ivol::Box{{n / 2, 0, 0}, {n / 2 + 1, n, n}});
  });
  const Measured box = measure(path, [&] { return format.read_box(path, n, region); });
  const Measured preview = measure(path, [&] { return format.read_preview(path, n, 8); });
  std::filesystem::remove_all(path);

  const double float32_bytes = 4.0 * volume.voxel_count();
  std::printf(
      "{\"kind\": \"storage\", \"phantom\": \"%s\", \"size\": %u, \"fidelity\": \"%s\", \"format\": \"%s\", "
      "\"details\": \"%s\", \"file_bytes\": %llu, \"vs_float32\": %.3f, \"write_s\": %.4f, \"max_error_kept\": %.3g, "
      "\"read_all_s\": %.4f, \"read_all_bytes\": %llu, \"read_all_cold\": %llu, \"slice_z_s\": %.4f, "
      "\"slice_z_bytes\": %llu, \"slice_z_cold\": %llu, \"slice_x_s\": %.4f, \"slice_x_bytes\": %llu, "
      "\"slice_x_cold\": %llu, \"region_s\": %.4f, \"region_bytes\": %llu, \"region_cold\": %llu, "
      "\"region\": %s, \"preview_s\": %.4f, \"preview_bytes\": %llu, \"preview_cold\": %llu, "
      "\"preview_voxels\": %zu}\n",
      phantom.c_str(), n, fidelity.c_str(), format.name().c_str(), format.details().c_str(),
      static_cast<unsigned long long>(file_bytes), float32_bytes / file_bytes, write_seconds, error, all.seconds,
      static_cast<unsigned long long>(all.bytes), static_cast<unsigned long long>(all.cold_bytes), slice_z.seconds,
      static_cast<unsigned long long>(slice_z.bytes), static_cast<unsigned long long>(slice_z.cold_bytes),
      slice_x.seconds, static_cast<unsigned long long>(slice_x.bytes),
      static_cast<unsigned long long>(slice_x.cold_bytes), box.seconds, static_cast<unsigned long long>(box.bytes),
      static_cast<unsigned long long>(box.cold_bytes), json_box(region).c_str(), preview.seconds,
      static_cast<unsigned long long>(preview.bytes), static_cast<unsigned long long>(preview.cold_bytes),
      preview.values.size());
  std::fflush(stdout);
}

void storage(const std::vector<std::string>& phantoms, const peers::ScanSetup& setup, const std::string& work,
             const std::vector<std::string>& only) {
  const std::uint32_t n = setup.size;
  std::filesystem::create_directories(work);
  std::fprintf(stderr, "peers_bench: OpenVDB %s, HDF5 %s (blosc filter %s), %s\n", peers::vdb_version().c_str(),
               peers::hdf5_version().c_str(), peers::hdf5_blosc_available() ? "available" : "NOT available",
               peers::tiff_version().c_str());
  for (const std::string& phantom : phantoms) {
    const std::vector<float> reconstructed = peers::reconstructed_volume(phantom, setup, work + "/cache");
    // Every format holds binary16: round once, here, so that all keep the
    // same values bit for bit where they keep a voxel.
    std::vector<float> rounded(reconstructed.size());
    for (std::size_t i = 0; i < rounded.size(); ++i)
      rounded[i] = ivol::binary16_to_float(ivol::float_to_binary16(reconstructed[i]));
    const ivol::Dims dims{n, n, n};
    const float otsu = ivol::otsu_threshold(rounded.data(), rounded.size());
    const std::vector<std::uint8_t> keep = ivol::threshold_keep_mask(rounded.data(), dims, 0.5f * otsu, 3);
    double air_sum = 0;
    std::uint64_t kept = 0;
    for (std::size_t i = 0; i < keep.size(); ++i) {
      if (keep[i])
        ++kept;
      else
        air_sum += rounded[i];
    }
    const float background = ivol::binary16_to_float(
        ivol::float_to_binary16(static_cast<float>(air_sum / std::max<double>(1.0, double(keep.size() - kept)))));
    const ivol::Box region = busiest_region(keep, n);
    std::printf(
        "{\"kind\": \"volume\", \"phantom\": \"%s\", \"size\": %u, \"otsu\": %.5g, \"keep_threshold\": %.5g, "
        "\"margin\": 3, \"kept_voxels\": %llu, \"kept_share\": %.5f, \"background\": %.5g, \"region\": %s}\n",
        phantom.c_str(), n, otsu, 0.5 * otsu, static_cast<unsigned long long>(kept), double(kept) / keep.size(),
        background, json_box(region).c_str());
    std::fflush(stdout);

    auto wanted = [&](const peers::PeerFormat& f) {
      return only.empty() || std::find(only.begin(), only.end(), f.name()) != only.end();
    };
    for (const bool keep_mode : {true, false}) {
      peers::VolumeCase volume;
      volume.n = n;
      volume.values = &rounded;
      volume.keep = keep_mode ? &keep : nullptr;
      volume.background = background;
      std::vector<std::unique_ptr<peers::PeerFormat>> formats;
      auto append = [&](std::vector<std::unique_ptr<peers::PeerFormat>> more) {
        for (auto& f : more) formats.push_back(std::move(f));
      };
      append(peers::ivol_formats(keep_mode));
      append(peers::vdb_formats());
      append(peers::hdf5_formats());
      append(peers::tiff_formats());
      if (!keep_mode) append(peers::raw_formats());
      for (auto& format : formats)
        if (wanted(*format))
          run_format(*format, volume, keep_mode ? "object" : "all", phantom, work, region, reconstructed);
    }
  }
}

void stack(const std::string& phantom, const peers::ScanSetup& setup, const std::string& work, const std::string& out) {
  const std::vector<float> volume = peers::reconstructed_volume(phantom, setup, work + "/cache");
  const auto [lo, hi] = std::minmax_element(volume.begin(), volume.end());
  const double scale = 65535.0 / std::max(1e-12, double(*hi - *lo));
  std::vector<std::uint16_t> quantised(volume.size());
  for (std::size_t i = 0; i < volume.size(); ++i)
    quantised[i] = static_cast<std::uint16_t>(std::lround((volume[i] - *lo) * scale));
  std::filesystem::remove_all(out);
  peers::write_uint16_tiff_stack(quantised, setup.size, out + "/stack");
  std::ofstream raw(out + "/volume.u16", std::ios::binary);
  raw.write(reinterpret_cast<const char*>(quantised.data()), static_cast<std::streamsize>(quantised.size() * 2));
  std::printf("{\"kind\": \"stack\", \"phantom\": \"%s\", \"size\": %u, \"raw_bytes\": %zu}\n", phantom.c_str(),
              setup.size, quantised.size() * 2);
}

int usage() {
  std::fprintf(stderr,
               "usage: peers_bench storage --size N [--phantom NAME]... [--format NAME]... --work DIR\n"
               "       peers_bench recon --size N --phantom NAME --export DIR\n"
               "       peers_bench stack --size N --phantom NAME --work DIR --out DIR\n"
               "options for all: --views V --detector D --photons P\n");
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) return usage();
  const std::string command = argv[1];
  peers::ScanSetup setup;
  setup.detector = 0;
  std::vector<std::string> phantoms;
  std::vector<std::string> formats;
  std::string work = "/tmp/ivol-peers", export_dir, out;
  for (int a = 2; a < argc; ++a) {
    const std::string arg = argv[a];
    if (a + 1 >= argc) return usage();
    const std::string value = argv[++a];
    if (arg == "--size")
      setup.size = static_cast<std::uint32_t>(std::stoul(value));
    else if (arg == "--views")
      setup.views = std::stoul(value);
    else if (arg == "--detector")
      setup.detector = std::stoi(value);
    else if (arg == "--photons")
      setup.photons = std::stod(value);
    else if (arg == "--phantom")
      phantoms.push_back(value);
    else if (arg == "--format")
      formats.push_back(value);
    else if (arg == "--work")
      work = value;
    else if (arg == "--export")
      export_dir = value;
    else if (arg == "--out")
      out = value;
    else
      return usage();
  }
  if (setup.detector == 0) setup.detector = static_cast<int>(setup.size * 3 / 2);
  if (phantoms.empty()) phantoms = {"pencil-holder", "connector-board", "computer-board", "thin-pipe", "lattice-part"};
  try {
    if (command == "storage") {
      storage(phantoms, setup, work, formats);
    } else if (command == "recon") {
      if (export_dir.empty()) return usage();
      peers::reconstruction_run(phantoms.front(), setup, export_dir);
    } else if (command == "stack") {
      if (out.empty()) return usage();
      stack(phantoms.front(), setup, work, out);
    } else {
      return usage();
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "peers_bench: %s\n", e.what());
    return 2;
  }
  return 0;
}
