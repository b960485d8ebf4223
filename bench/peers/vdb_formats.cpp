// OpenVDB peers for peers_bench: a FloatGrid saved as half float, with blosc
// or zip, through OpenVDB's own io::File.
//
// With a keep mask the kept voxels are the active voxels and everything else
// is the inactive background (OpenVDB's sparse use: leaves exist only around
// the kept voxels); without one every voxel is active.
//
// Reads open the file with OpenVDB's default, delayed loading: it maps the
// file, reads the topology, and a box read (readGrid(name, bbox)) clips the
// tree before any leaf buffer is paged in, so only the leaves in the box are
// fetched. What is fetched is counted from the page cache (mincore), since
// page faults do not show in /proc/self/io.
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>

#include <string>

#include "peer_format.hpp"

namespace peers {

std::string vdb_version() { return openvdb::getLibraryAbiVersionString(); }

namespace {

const char* kGridName = "density";

class VdbFormat : public PeerFormat {
 public:
  VdbFormat(std::uint32_t compression, std::string codec) : compression_(compression), codec_(std::move(codec)) {
    openvdb::initialize();
  }
  std::string name() const override { return "OpenVDB " + codec_; }
  std::string details() const override { return "FloatGrid saved as half, " + codec_ + " + active mask"; }

  void write(const VolumeCase& volume, const std::string& path) override {
    openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(volume.background);
    {
      openvdb::FloatGrid::Accessor accessor = grid->getAccessor();
      const std::uint32_t n = volume.n;
      const float* values = volume.values->data();
      const std::uint8_t* keep = volume.keep ? volume.keep->data() : nullptr;
      // x innermost as the volume lies; the accessor caches the current leaf.
      for (std::uint32_t z = 0; z < n; ++z)
        for (std::uint32_t y = 0; y < n; ++y) {
          const std::uint64_t row = (std::uint64_t{z} * n + y) * n;
          for (std::uint32_t x = 0; x < n; ++x)
            if (!keep || keep[row + x])
              accessor.setValueOn(openvdb::Coord(static_cast<int>(x), static_cast<int>(y), static_cast<int>(z)),
                                  values[row + x]);
        }
    }
    grid->setName(kGridName);
    grid->setSaveFloatAsHalf(true);
    openvdb::io::File file(path);
    file.setCompression(compression_ | openvdb::io::COMPRESS_ACTIVE_MASK);
    file.write({grid});
    file.close();
  }

  std::vector<float> read_box(const std::string& path, std::uint32_t n, const ivol::Box& box) override {
    openvdb::io::File file(path);
    file.setCopyMaxBytes(0);  // map the file itself, not a private copy read in full
    file.open(/*delayLoad=*/true);
    const bool whole =
        box.lo == std::array<std::uint32_t, 3>{0, 0, 0} && box.hi == std::array<std::uint32_t, 3>{n, n, n};
    const openvdb::CoordBBox bbox(
        openvdb::Coord(static_cast<int>(box.lo[0]), static_cast<int>(box.lo[1]), static_cast<int>(box.lo[2])),
        openvdb::Coord(static_cast<int>(box.hi[0]) - 1, static_cast<int>(box.hi[1]) - 1,
                       static_cast<int>(box.hi[2]) - 1));
    openvdb::GridBase::Ptr base =
        whole ? file.readGrid(kGridName)
              : file.readGrid(kGridName, openvdb::BBoxd(bbox.min().asVec3d(), bbox.max().asVec3d()));
    file.close();
    openvdb::FloatGrid::Ptr grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
    std::vector<float> out(box.voxel_count());
    openvdb::tools::Dense<float, openvdb::tools::LayoutXYZ> dense(bbox, out.data());
    openvdb::tools::copyToDense(*grid, dense);
    return out;
  }

 private:
  std::uint32_t compression_;
  std::string codec_;
};

}  // namespace

std::vector<std::unique_ptr<PeerFormat>> vdb_formats() {
  std::vector<std::unique_ptr<PeerFormat>> formats;
  if (openvdb::io::Archive::hasBloscCompression())
    formats.push_back(std::make_unique<VdbFormat>(openvdb::io::COMPRESS_BLOSC, "blosc"));
  formats.push_back(std::make_unique<VdbFormat>(openvdb::io::COMPRESS_ZIP, "zip"));
  return formats;
}

}  // namespace peers
