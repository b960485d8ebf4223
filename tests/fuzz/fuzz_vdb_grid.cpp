// libFuzzer harness for ivol's side of the OpenVDB reader: volume_from_grid
// (tools/convert/vdb_grid.hpp), the dense copy of a float grid that is
// already in memory. The input is not a .vdb file but a recipe for a grid:
// its background, transform, metadata strings and a list of voxels, tiles
// and filled boxes anywhere in OpenVDB's 32-bit index space (INT_MIN and
// INT_MAX included). libopenvdb's file parser is fuzzed by fuzz_vdb.cpp at a
// few dozen inputs a second and is libopenvdb's own code, contained by the
// child process the converters read it in; this harness runs thousands of
// grids a second through the code that is ivol's.
//
// Each grid must either be refused with ivol::Error (any other exception is
// a finding) or come back as a dense volume that holds, bit for bit, what
// OpenVDB's own accessor gives at every voxel of the active bounding box,
// with the active and tile flags the accessor gives: a wrong copy aborts.
//   tests/fuzz/run_vdb_grid.sh
#include <openvdb/openvdb.h>

#include <algorithm>
#include <climits>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>

#include "ivol/error.hpp"
#include "vdb_grid.hpp"

namespace {

// Reads the recipe; past its end every read gives zeros.
class Recipe {
 public:
  Recipe(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
  bool done() const { return at_ >= size_; }
  template <typename T>
  T get() {
    T value{};
    const std::size_t n = std::min(sizeof(T), size_ - std::min(at_, size_));
    if (n) std::memcpy(&value, data_ + at_, n);
    at_ += sizeof(T);
    return value;
  }
  std::string text(std::size_t longest) {
    const std::size_t want = std::min<std::size_t>(get<std::uint16_t>(), longest);
    const std::size_t n = std::min(want, size_ - std::min(at_, size_));
    std::string s(reinterpret_cast<const char*>(data_) + std::min(at_, size_), n);
    at_ += n;
    return s;
  }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t at_ = 0;
};

// A coordinate near one of the places where 32-bit index arithmetic breaks,
// or anywhere.
int coordinate(Recipe& r) {
  static constexpr std::int64_t kAnchors[] = {0, INT_MIN, INT_MAX, -4096, 4096, 1 << 30, -(1 << 30), INT_MIN + 4096,
                                              INT_MAX - 4095};
  const std::uint8_t mode = r.get<std::uint8_t>();
  if (mode >= 0xF0) return r.get<std::int32_t>();
  const std::int64_t v = kAnchors[mode % std::size(kAnchors)] + r.get<std::int16_t>();
  return static_cast<int>(std::clamp<std::int64_t>(v, INT_MIN, INT_MAX));
}

openvdb::Coord coord(Recipe& r) {
  const int x = coordinate(r), y = coordinate(r), z = coordinate(r);
  return {x, y, z};
}

openvdb::math::Transform::Ptr transform(Recipe& r) {
  using openvdb::math::Transform;
  switch (r.get<std::uint8_t>() % 5) {
    case 0:
      return Transform::createLinearTransform(1.0);
    case 1: {
      Transform::Ptr t = Transform::createLinearTransform(1.0);
      const double sx = r.get<double>(), sy = r.get<double>(), sz = r.get<double>();
      // OpenVDB itself refuses a singular scale with an exception: not ivol's concern.
      try {
        t->postScale(openvdb::Vec3d(sx, sy, sz));
        t->postTranslate(openvdb::Vec3d(r.get<double>(), r.get<double>(), r.get<double>()));
      } catch (const openvdb::Exception&) {
        return Transform::createLinearTransform(1.0);
      }
      return t;
    }
    case 2: {
      Transform::Ptr t = Transform::createLinearTransform(0.5);
      try {
        t->postRotate(static_cast<double>(r.get<std::int8_t>()) / 64.0, openvdb::math::Axis(r.get<std::uint8_t>() % 3));
      } catch (const openvdb::Exception&) {
      }
      return t;
    }
    case 3: {
      Transform::Ptr t = Transform::createLinearTransform(1.0);
      try {
        t->postShear(static_cast<double>(r.get<std::int8_t>()) / 1e6, openvdb::math::X_AXIS, openvdb::math::Y_AXIS);
      } catch (const openvdb::Exception&) {
      }
      return t;
    }
    default:
      return Transform::createFrustumTransform(openvdb::BBoxd(openvdb::Vec3d(0), openvdb::Vec3d(8)), 0.5, 2.0, 1.0);
  }
}

[[noreturn]] void finding(const char* what) {
  std::fprintf(stderr, "fuzz_vdb_grid: %s\n", what);
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  openvdb::initialize();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Recipe r(data, size);
  std::uint32_t background_bits = r.get<std::uint32_t>();
  float background;
  std::memcpy(&background, &background_bits, 4);
  openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(background);
  grid->setName(r.text(64));
  grid->setSaveFloatAsHalf(r.get<std::uint8_t>() & 1);
  grid->setTransform(transform(r));
  const std::uint8_t strings = r.get<std::uint8_t>();
  static const char* kKeys[] = {"unit", "quantity", "value_unit", "provenance"};
  for (int k = 0; k < 4; ++k)
    if (strings & (1u << k)) grid->insertMeta(kKeys[k], openvdb::StringMetadata(r.text(k == 3 ? 60000 : 256)));
  if (strings & 0x10) {  // a key of the wrong type
    grid->removeMeta("quantity");
    grid->insertMeta("quantity", openvdb::FloatMetadata(1.0f));
  }

  openvdb::FloatGrid::Accessor access = grid->getAccessor();
  // Each upper node costs OpenVDB a 256 KiB table: 16 steps keep an input
  // cheap and still reach every level at several places.
  for (int op = 0; op < 16 && !r.done(); ++op) {
    const std::uint8_t kind = r.get<std::uint8_t>();
    const openvdb::Coord at = coord(r);
    float value;
    const std::uint32_t bits = r.get<std::uint32_t>();
    std::memcpy(&value, &bits, 4);
    switch (kind % 5) {
      case 0:
        access.setValueOn(at, value);
        break;
      case 1:
        access.setValueOff(at, value);
        break;
      case 2:
        // A tile of a lower internal node (8^3 or 128^3) or of the root (4096^3).
        // Through the tree, not the accessor: ValueAccessor3::addTile frees a
        // leaf its cache still points at (heap-use-after-free in libopenvdb).
        grid->tree().addTile(1 + (kind >> 3) % 3, at, value, (kind >> 5) & 1);
        access.clear();
        break;
      case 3: {
        // A small box filled with one value: tiles where it covers whole
        // nodes, voxels elsewhere.
        // RootNode::fill steps past INT_MAX (signed overflow in libopenvdb)
        // when a box reaches the last 4096^3 root tile: keep below it.
        const int ex = r.get<std::uint8_t>() & 63, ey = r.get<std::uint8_t>() & 63, ez = r.get<std::uint8_t>() & 63;
        constexpr int kTop = INT_MAX - 4096 - 256;
        const openvdb::Coord lo(std::min(at.x(), kTop), std::min(at.y(), kTop), std::min(at.z(), kTop));
        const openvdb::Coord hi(lo.x() + ex, lo.y() + ey, lo.z() + ez);
        grid->tree().fill(openvdb::CoordBBox(lo, hi), value, (kind >> 5) & 1);
        access.clear();
        break;
      }
      default:
        access.setActiveState(at, (kind >> 5) & 1);
        break;
    }
  }

  ivol::convert::VdbVolume out;
  try {
    out = ivol::convert::volume_from_grid(*grid, "fuzz.vdb: grid", std::uint64_t{1} << 16);
  } catch (const ivol::Error&) {
    return 0;
  }

  // The oracle: OpenVDB's accessor at every voxel of the active bounding box.
  const openvdb::CoordBBox box = grid->evalActiveVoxelBoundingBox();
  for (int a = 0; a < 3; ++a)
    if (out.volume.dims[a] != static_cast<std::uint64_t>(std::int64_t{box.max()[a]} - box.min()[a] + 1))
      finding("dims differ from the active bounding box");
  const std::uint64_t voxels = out.volume.voxel_count();
  if (out.volume.data.size() != voxels * 4 || out.active.size() != voxels || out.from_tile.size() != voxels)
    finding("buffer sizes differ from the dims");
  if (std::memcmp(&out.background, &background, 4) != 0) finding("background changed");
  openvdb::FloatGrid::ConstAccessor look = grid->getConstAccessor();
  std::uint64_t i = 0;
  for (std::int64_t z = box.min().z(); z <= box.max().z(); ++z)
    for (std::int64_t y = box.min().y(); y <= box.max().y(); ++y)
      for (std::int64_t x = box.min().x(); x <= box.max().x(); ++x, ++i) {
        const openvdb::Coord c(static_cast<int>(x), static_cast<int>(y), static_cast<int>(z));
        const float want = look.getValue(c);
        if (std::memcmp(&want, out.volume.data.data() + 4 * i, 4) != 0) finding("a value differs from the grid's");
        const bool on = look.isValueOn(c);
        if (out.active[i] != on) finding("an active flag differs from the grid's");
        if (out.from_tile[i] != (on && !look.isVoxel(c))) finding("a tile flag differs from the grid's");
      }
  return 0;
}
