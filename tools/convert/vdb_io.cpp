#include "vdb_io.hpp"
#include "vdb_grid.hpp"

#include <openvdb/io/Archive.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/Prune.h>
#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <new>
#include <utility>

#include "ivol/error.hpp"
#include "sizes.hpp"
#include "staged_file.hpp"
#include "volume_metadata.hpp"

namespace ivol::convert {
namespace {

// The dense layout of DenseVolume: x fastest, then y, then z.
using DenseFloats = openvdb::tools::Dense<float, openvdb::tools::LayoutXYZ>;

std::string grid_context(const std::string& path, const std::string& grid_name) {
  return path + ": grid '" + grid_name + "'";
}

// "name (float), labels (int32)" for messages.
std::string describe_grids(const openvdb::GridPtrVec& grids) {
  if (grids.empty()) return "the file holds no grid";
  std::string text = "grids in the file: ";
  for (std::size_t i = 0; i < grids.size(); ++i)
    text += (i ? ", " : "") + std::string("'") + grids[i]->getName() + "' (" + grids[i]->valueType() + ")";
  return text;
}

// Voxel size and origin from a linear, axis-aligned transform; anything else
// cannot be a DenseVolume without resampling.
void read_geometry(const openvdb::math::Transform& transform, const openvdb::Coord& min, const std::string& context,
                   DenseVolume& volume) {
  if (!transform.isLinear())
    throw Error(ErrorClass::InvalidArgument,
                context + ": the transform is not linear (" + transform.mapType() + "); only scale and translation");
  openvdb::Mat4d matrix;
  try {
    // getAffineMap inverts the matrix and throws when it is singular (a
    // scale of 1e-310 in a file, found by fuzz_vdb_grid).
    matrix = transform.baseMap()->getAffineMap()->getMat4();
  } catch (const openvdb::Exception& e) {
    throw Error(ErrorClass::InvalidArgument,
                context + ": the transform cannot be used (" + transform.mapType() + ", OpenVDB: " + e.what() + ")");
  }
  // OpenVDB multiplies row vectors: row i of the 3x3 part is the image of axis i.
  const double largest = std::max({std::abs(matrix[0][0]), std::abs(matrix[1][1]), std::abs(matrix[2][2])});
  for (int row = 0; row < 3; ++row)
    for (int column = 0; column < 3; ++column)
      if (row != column && std::abs(matrix[row][column]) > 1e-12 * largest)
        throw Error(ErrorClass::InvalidArgument, context + ": the transform rotates or shears the grid (" +
                                                     transform.mapType() + "); only scale and translation");
  for (int axis = 0; axis < 3; ++axis) {
    const double scale = matrix[axis][axis];
    if (!(scale > 0) || !std::isfinite(scale))
      throw Error(ErrorClass::InvalidArgument, context + ": the transform mirrors or collapses axis " +
                                                   std::string(1, "xyz"[axis]) + " (scale " + std::to_string(scale) +
                                                   ")");
    volume.voxel_size[axis] = scale;
  }
  const openvdb::Vec3d origin = transform.indexToWorld(min);
  volume.origin = {origin.x(), origin.y(), origin.z()};
  volume.has_geometry = true;
}

// Opens the file, turning OpenVDB's exceptions into ours.
void open_vdb(openvdb::io::File& file, const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw Error(ErrorClass::Io, path + ": cannot open: no such file");
  try {
    file.open(/*delayLoad=*/false);
  } catch (const openvdb::Exception& e) {
    throw Error(ErrorClass::Malformed, path + ": not a VDB file (OpenVDB: " + e.what() + ")");
  }
}

openvdb::FloatGrid::Ptr choose_float_grid(openvdb::io::File& file, const std::string& path,
                                          const std::string& grid_name) {
  openvdb::GridPtrVecPtr grids;
  try {
    grids = file.readAllGridMetadata();
  } catch (const openvdb::Exception& e) {
    throw Error(ErrorClass::Malformed, path + ": cannot read the grid descriptions (OpenVDB: " + e.what() + ")");
  }
  openvdb::GridBase::Ptr chosen;
  for (const openvdb::GridBase::Ptr& grid : *grids) {
    if (grid_name.empty() ? grid->isType<openvdb::FloatGrid>() : grid->getName() == grid_name) {
      chosen = grid;
      break;
    }
  }
  if (!chosen) {
    if (grid_name.empty())
      throw Error(ErrorClass::InvalidArgument, path + ": no float grid; " + describe_grids(*grids));
    throw Error(ErrorClass::InvalidArgument,
                grid_context(path, grid_name) + " does not exist; " + describe_grids(*grids));
  }
  const std::string context = grid_context(path, chosen->getName());
  if (!chosen->isType<openvdb::FloatGrid>())
    throw Error(ErrorClass::InvalidArgument, context + " holds " + chosen->valueType() + " values (" + chosen->type() +
                                                 "); only float grids convert");
  try {
    return openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid(chosen->getName()));
  } catch (const openvdb::Exception& e) {
    throw Error(ErrorClass::Malformed, context + ": cannot read the grid (OpenVDB: " + e.what() + ")");
  } catch (const std::bad_alloc&) {
    // libopenvdb allocates what the file's block headers claim (a blosc
    // block of 1 TiB in a 20 KB file, found by fuzz_vdb) before reading it.
    throw Error(ErrorClass::LimitExceeded, context + ": libopenvdb could not allocate what the grid's data claim (a " +
                                               "block larger than memory: a damaged or hostile file; the file is " +
                                               std::to_string(std::filesystem::file_size(path)) + " bytes)");
  }
}

// Calls visit(coord, dense index) for every voxel of a volume of `dims`, x fastest.
template <typename Visit>
void for_each_voxel(const Dims& dims, Visit&& visit) {
  std::uint64_t i = 0;
  for (std::uint32_t z = 0; z < dims[2]; ++z)
    for (std::uint32_t y = 0; y < dims[1]; ++y)
      for (std::uint32_t x = 0; x < dims[0]; ++x, ++i)
        visit(openvdb::Coord(static_cast<int>(x), static_cast<int>(y), static_cast<int>(z)), i);
}

// Copies the grid's values over the dense box (the background where the
// tree holds nothing) and marks the active voxels, and which of them an
// active tile covers. The tree is walked node by node and a node that does
// not meet the box is skipped whole, so the work is in proportion to the
// box and the nodes that meet it, not to every tile slot of the tree (a
// grid's value iterator visits all 32768 slots of every upper node, and
// every slot of an upper node that meets the box would cost as much).
// Coordinates are widened to 64 bits: a grid may sit anywhere in OpenVDB's
// 32-bit index space, and tools::copyToDense loops forever near INT_MIN and
// writes out of bounds when the box spans 2^31.
class DenseCopy {
 public:
  DenseCopy(const openvdb::CoordBBox& box, VdbVolume& out)
      : min_{box.min().x(), box.min().y(), box.min().z()},
        max_{box.max().x(), box.max().y(), box.max().z()},
        nx_(out.volume.dims[0]),
        ny_(out.volume.dims[1]),
        dense_(reinterpret_cast<float*>(out.volume.data.data())),
        out_(out) {}

  void copy(const openvdb::FloatGrid& grid) {
    std::fill_n(dense_, out_.volume.voxel_count(), grid.background());
    using Root = openvdb::FloatTree::RootNodeType;
    using Upper = Root::ChildNodeType;
    const Root& root = grid.tree().root();
    for (auto tile = root.cbeginValueAll(); tile; ++tile) fill_tile(tile.getCoord(), Upper::DIM, *tile, tile.isValueOn());
    for (auto upper = root.cbeginChildOn(); upper; ++upper) {
      if (!fill_tiles(*upper)) continue;
      for (auto lower = upper->cbeginChildOn(); lower; ++lower) {
        if (!fill_tiles(*lower)) continue;
        for (auto leaf = lower->cbeginChildOn(); leaf; ++leaf) copy_leaf(*leaf);
      }
    }
  }

 private:
  using Leaf = openvdb::FloatTree::LeafNodeType;

  std::uint64_t index(std::int64_t x, std::int64_t y, std::int64_t z) const {
    return static_cast<std::uint64_t>(((z - min_[2]) * ny_ + (y - min_[1])) * nx_ + (x - min_[0]));
  }
  // The part of the cube [origin, origin + side) inside the box.
  bool clip(const openvdb::Coord& origin, openvdb::Index side, std::int64_t lo[3], std::int64_t hi[3]) const {
    bool inside = true;
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::max<std::int64_t>(origin[a], min_[a]);
      hi[a] = std::min<std::int64_t>(std::int64_t{origin[a]} + side - 1, max_[a]);
      inside = inside && lo[a] <= hi[a];
    }
    return inside;
  }
  // Fills the tiles of an internal node that meet the box, visiting only
  // the slots that do; false when the node does not meet the box.
  template <typename Node>
  bool fill_tiles(const Node& node) {
    constexpr std::int64_t side = Node::ChildNodeType::DIM;
    const openvdb::Coord origin = node.origin();
    std::int64_t lo[3], hi[3];
    if (!clip(origin, Node::DIM, lo, hi)) return false;
    std::int64_t first[3], last[3];
    for (int a = 0; a < 3; ++a) {
      first[a] = (lo[a] - origin[a]) / side;
      last[a] = (hi[a] - origin[a]) / side;
    }
    for (std::int64_t i = first[0]; i <= last[0]; ++i)
      for (std::int64_t j = first[1]; j <= last[1]; ++j)
        for (std::int64_t k = first[2]; k <= last[2]; ++k) {
          const openvdb::Coord slot(static_cast<int>(origin[0] + i * side), static_cast<int>(origin[1] + j * side),
                                    static_cast<int>(origin[2] + k * side));
          if (node.isChildMaskOn(Node::coordToOffset(slot))) continue;
          fill_tile(slot, side, node.getValue(slot), node.isValueOn(slot));
        }
    return true;
  }
  void fill_tile(const openvdb::Coord& origin, openvdb::Index side, float value, bool on) {
    std::int64_t lo[3], hi[3];
    if (!clip(origin, side, lo, hi)) return;
    const auto length = static_cast<std::ptrdiff_t>(hi[0] - lo[0] + 1);
    for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
      for (std::int64_t y = lo[1]; y <= hi[1]; ++y) {
        const auto row = static_cast<std::ptrdiff_t>(index(lo[0], y, z));
        std::fill_n(dense_ + row, length, value);
        std::fill_n(out_.active.begin() + row, length, on);
        std::fill_n(out_.from_tile.begin() + row, length, on);
      }
  }
  void copy_leaf(const Leaf& leaf) {
    const openvdb::Coord origin = leaf.origin();
    std::int64_t lo[3], hi[3];
    if (!clip(origin, Leaf::DIM, lo, hi)) return;
    for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
      for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
        for (std::int64_t x = lo[0]; x <= hi[0]; ++x) {
          const openvdb::Index offset = Leaf::coordToOffset(
              openvdb::Coord(static_cast<int>(x), static_cast<int>(y), static_cast<int>(z)));
          const std::uint64_t i = index(x, y, z);
          dense_[i] = leaf.getValue(offset);
          out_.active[i] = leaf.isValueOn(offset);
          out_.from_tile[i] = 0;
        }
  }

  std::int64_t min_[3], max_[3];
  std::int64_t nx_, ny_;
  float* dense_;
  VdbVolume& out_;
};

// Writes as io::File::write does, the same bytes, but to a stream of ours
// whose state is checked: File::write ignores write errors, and on a full
// disk left a truncated file that was then renamed into place.
class CheckedArchive final : public openvdb::io::Archive {
 public:
  void write_to(std::ostream& stream, const openvdb::GridCPtrVec& grids) const {
    Archive::write(stream, grids, /*seekable=*/true);
  }
};

}  // namespace

double vdb_output_bytes(const Dims& dims) {
  using Leaf = openvdb::FloatTree::LeafNodeType;
  using Upper = openvdb::FloatTree::RootNodeType::ChildNodeType;
  using Lower = Upper::ChildNodeType;
  constexpr double kAllocationOverhead = 16;  // glibc's header per block
  auto nodes = [&](openvdb::Index log2_side) {
    double count = 1;
    for (std::uint32_t extent : dims) count *= std::ceil(static_cast<double>(extent) / double(1u << log2_side));
    return count;
  };
  // A leaf is an object and its buffer; copyFromDense keeps a block record
  // (a box, the leaf's pointer, a tile value) for each until it inserts them.
  const double leaf = sizeof(Leaf) + Leaf::SIZE * sizeof(float) + 2 * kAllocationOverhead +
                      sizeof(openvdb::CoordBBox) + sizeof(void*) + sizeof(std::pair<float, bool>);
  const double tree = nodes(Leaf::TOTAL) * leaf + nodes(Lower::TOTAL) * (sizeof(Lower) + kAllocationOverhead) +
                      nodes(Upper::TOTAL) * (sizeof(Upper) + kAllocationOverhead + 64 /* the root's map entry */);
  double voxels = 1;
  for (std::uint32_t extent : dims) voxels *= extent;
  return voxels * sizeof(float) + tree;
}

VdbVolume read_vdb(const std::string& path, const std::string& grid_name, std::uint64_t memory_bytes) {
  openvdb::initialize();
  openvdb::io::File file(path);
  open_vdb(file, path);
  const openvdb::FloatGrid::Ptr grid = choose_float_grid(file, path, grid_name);
  file.close();
  return volume_from_grid(*grid, grid_context(path, grid->getName()), memory_bytes);
}

VdbVolume volume_from_grid(const openvdb::FloatGrid& grid, const std::string& context, std::uint64_t memory_bytes) {
  VdbVolume out;
  out.grid_name = grid.getName();
  out.background = grid.background();
  out.was_half = grid.saveFloatAsHalf();

  const openvdb::CoordBBox box = grid.evalActiveVoxelBoundingBox();
  if (box.empty()) throw Error(ErrorClass::InvalidArgument, context + " has no active voxel: nothing to convert");
  // Extents in 64 bits: Coord's 32-bit dim() wraps to 0 for a box spanning
  // 2^32 voxels.
  Dims dims{};
  std::string span;
  for (int a = 0; a < 3; ++a) {
    const std::int64_t extent = std::int64_t{box.max()[a]} - std::int64_t{box.min()[a]} + 1;
    span += std::string(a ? ", " : "") + std::to_string(box.min()[a]) + ".." + std::to_string(box.max()[a]);
    if (extent > std::numeric_limits<std::uint32_t>::max())
      throw Error(ErrorClass::LimitExceeded, context + ": the active voxels span " + std::to_string(extent) +
                                                 " voxels along " + std::string(1, "xyz"[a]) +
                                                 "; a dense volume holds at most 2^32 - 1 per axis");
    dims[a] = static_cast<std::uint32_t>(extent);
  }
  // Geometry first: a refused transform should not cost a large allocation.
  DenseVolume geometry;
  read_geometry(grid.transform(), box.min(), context, geometry);
  geometry.voxel_size_from = "OpenVDB transform";
  geometry.origin_from = "OpenVDB transform at the first active voxel";
  if (const auto unit = grid.getMetadata<openvdb::StringMetadata>("unit")) {
    geometry.unit = unit->value();
    geometry.unit_from = "OpenVDB grid metadata unit";
  }
  const std::pair<const char*, std::string*> texts[] = {
      {"quantity", &geometry.quantity}, {"value_unit", &geometry.value_unit}, {"provenance", &geometry.provenance}};
  for (const auto& [key, field] : texts)
    if (const auto text = grid.getMetadata<openvdb::StringMetadata>(key)) *field = text->value();
  if (!geometry.quantity.empty() || !geometry.value_unit.empty())
    geometry.quantity_from = "OpenVDB grid metadata quantity, value_unit";
  // A grid ivol wrote from a volume of unknown voxel size has an identity
  // transform that means nothing.
  if (voxel_size_marked_unknown(geometry.provenance)) geometry.has_geometry = false;

  // The grid is read whole: float32 samples and two flags per voxel.
  const std::string what = context + ": the active bounding box (" + span + "), " + dims_text(dims) + " voxels,";
  const std::uint64_t voxels = volume_voxels(dims, what);
  require_within_budget(checked_mul(voxels, 6, what), memory_budget(memory_bytes), what + " as a dense volume");
  out.volume = make_dense(dims, SampleType::Float32);
  checked_resize(out.active, voxels, what + " (active flags)");
  checked_resize(out.from_tile, voxels, what + " (tile flags)");
  DenseVolume shape = shape_of(geometry);
  shape.dims = out.volume.dims;
  shape.type = out.volume.type;
  shape.data = std::move(out.volume.data);
  out.volume = std::move(shape);
  // The byte buffer comes from operator new, aligned for float.
  DenseCopy(box, out).copy(grid);
  return out;
}

std::unique_ptr<SlabReader> open_vdb_slabs_in_process(const std::string& path, const std::string& grid_name,
                                                      VdbSourceInfo* source, std::uint64_t memory_bytes) {
  VdbVolume read = read_vdb(path, grid_name, memory_bytes);
  if (source) *source = VdbSourceInfo{read.grid_name, read.background, read.was_half};
  return memory_slabs(std::move(read.volume));
}

LossTally write_vdb(const DenseVolume& volume, const std::string& path, float background, const std::string& grid_name,
                    bool half, const std::function<void(const LossTally&)>& check) {
  const std::string context = grid_context(path, grid_name);
  if (grid_name.empty()) throw Error(ErrorClass::InvalidArgument, path + ": the grid needs a name");
  for (std::uint32_t extent : volume.dims) {
    if (extent == 0) throw Error(ErrorClass::InvalidArgument, context + ": the volume is empty");
    if (extent > static_cast<std::uint32_t>(std::numeric_limits<std::int32_t>::max()))
      throw Error(ErrorClass::InvalidArgument, context + ": an extent exceeds OpenVDB's 32-bit index space");
  }
  if (volume.data.size() != volume.voxel_count() * sample_size(volume.type))
    throw Error(ErrorClass::InvalidArgument, context + ": the volume's data size does not match its dimensions");
  if (volume.has_geometry)
    for (double size : volume.voxel_size)
      if (!(size > 0) || !std::isfinite(size))
        throw Error(ErrorClass::InvalidArgument, context + ": the voxel size must be positive and finite");

  openvdb::initialize();
  // A float32 volume is used where it lies (its bytes come from operator
  // new, aligned for float): a copy would add 4 bytes a voxel to what
  // vdb_output_bytes counts.
  std::vector<float> converted;
  if (volume.type != SampleType::Float32) converted = volume.to_float();
  const float* values =
      converted.empty() ? reinterpret_cast<const float*>(volume.data.data()) : converted.data();
  const std::uint64_t voxel_count = volume.voxel_count();
  const openvdb::CoordBBox box(openvdb::Coord(0, 0, 0), openvdb::Coord(static_cast<int>(volume.dims[0]) - 1,
                                                                       static_cast<int>(volume.dims[1]) - 1,
                                                                       static_cast<int>(volume.dims[2]) - 1));
  openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(background);
  {
    const DenseFloats dense(box, const_cast<float*>(values));  // copyFromDense only reads it
    openvdb::tools::copyFromDense(dense, *grid, /*tolerance=*/0.0f);
  }
  // copyFromDense compares values, not bits, and takes a NaN for the
  // background: give every voxel the grid does not hold bit for bit its own
  // active value (-0 against a background of +0, NaNs).
  {
    openvdb::FloatGrid::Accessor access = grid->getAccessor();
    for_each_voxel(volume.dims, [&](const openvdb::Coord& c, std::uint64_t i) {
      const float held = access.getValue(c);
      if (std::memcmp(&held, &values[i], 4) != 0) access.setValueOn(c, values[i]);
    });
  }
  openvdb::tools::prune(grid->tree());
  LossTally loss;
  {
    openvdb::FloatGrid::ConstAccessor access = grid->getConstAccessor();
    for_each_voxel(volume.dims, [&](const openvdb::Coord& c, std::uint64_t i) {
      const float held = access.getValue(c);
      std::uint32_t want, got;
      std::memcpy(&want, &values[i], 4);
      std::memcpy(&got, &held, 4);
      if (want == got) return;
      if (std::isnan(held) && std::isnan(values[i])) {
        ++loss.voxels;
        ++loss.nan_payloads;
      } else if (held == values[i]) {
        ++loss.voxels;
        ++loss.signed_zeros;
      } else {
        loss.add(values[i], held);
      }
    });
  }
  if (half) tally_encoding(ValueEncoding::Binary16, values, voxel_count, loss);
  if (check) check(loss);

  openvdb::math::Transform::Ptr transform = openvdb::math::Transform::createLinearTransform(1.0);
  if (volume.has_geometry) {
    transform->postScale(openvdb::Vec3d(volume.voxel_size[0], volume.voxel_size[1], volume.voxel_size[2]));
    transform->postTranslate(openvdb::Vec3d(volume.origin[0], volume.origin[1], volume.origin[2]));
  }
  grid->setTransform(transform);
  grid->setName(grid_name);
  const bool fog = background == 0.0f && std::all_of(values, values + voxel_count,
                                                     [](float value) { return value >= 0.0f && value <= 1.0f; });
  grid->setGridClass(fog ? openvdb::GRID_FOG_VOLUME : openvdb::GRID_UNKNOWN);
  grid->setCreator("ivol");
  if (volume.has_geometry) grid->insertMeta("unit", openvdb::StringMetadata(volume.unit));
  const std::pair<const char*, const std::string*> texts[] = {
      {"quantity", &volume.quantity}, {"value_unit", &volume.value_unit}, {"provenance", &volume.provenance}};
  for (const auto& [key, text] : texts)
    if (!text->empty()) grid->insertMeta(key, openvdb::StringMetadata(*text));
  grid->setSaveFloatAsHalf(half);
  converted = {};

  StagedFile staged(path);
  std::ofstream stream(staged.temp_path(), std::ios::binary | std::ios::trunc);
  if (!stream) throw Error(ErrorClass::Io, context + ": cannot open a temporary file: " + std::strerror(errno));
  try {
    CheckedArchive().write_to(stream, {grid});
  } catch (const openvdb::Exception& e) {
    throw Error(ErrorClass::Io, context + ": cannot write (OpenVDB: " + e.what() + ")");
  }
  // A stream that failed makes no more system calls, so errno still holds
  // the reason of the write that failed (ENOSPC on a full disk).
  int failure = stream ? 0 : errno;
  if (stream) {
    errno = 0;
    stream.flush();
    if (!stream) failure = errno;
  }
  if (!stream) throw Error(ErrorClass::Io, context + ": cannot write: " + std::strerror(failure ? failure : EIO));
  const std::streamoff written = stream.tellp();
  stream.close();
  if (stream.fail()) throw Error(ErrorClass::Io, context + ": cannot close the file: " + std::strerror(errno));
  // The file must hold every byte the archive wrote.
  struct stat st {};
  if (::stat(staged.temp_path().c_str(), &st) != 0 || st.st_size != written)
    throw Error(ErrorClass::Io, context + ": the file holds " + std::to_string(st.st_size) + " bytes of the " +
                                    std::to_string(written) + " written");
  staged.commit();
  return loss;
}

}  // namespace ivol::convert
