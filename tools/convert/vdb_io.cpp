#include "vdb_io.hpp"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/Prune.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>

#include "ivol/error.hpp"
#include "staged_file.hpp"

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
  const openvdb::Mat4d matrix = transform.baseMap()->getAffineMap()->getMat4();
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
  }
}

// Marks active voxels, and which of them an active tile covers, over the
// dense box.
void mark_active(const openvdb::FloatGrid& grid, const openvdb::CoordBBox& box, VdbVolume& out) {
  const openvdb::Coord min = box.min();
  const std::uint64_t nx = out.volume.dims[0], ny = out.volume.dims[1];
  auto index = [&](const openvdb::Coord& c) {
    return (static_cast<std::uint64_t>(c.z() - min.z()) * ny + static_cast<std::uint64_t>(c.y() - min.y())) * nx +
           static_cast<std::uint64_t>(c.x() - min.x());
  };
  for (auto value = grid.cbeginValueOn(); value; ++value) {
    if (value.isVoxelValue()) {
      out.active[index(value.getCoord())] = 1;
      continue;
    }
    openvdb::CoordBBox tile;
    value.getBoundingBox(tile);
    tile.intersect(box);
    for (int z = tile.min().z(); z <= tile.max().z(); ++z)
      for (int y = tile.min().y(); y <= tile.max().y(); ++y) {
        const std::uint64_t row = index(openvdb::Coord(tile.min().x(), y, z));
        const std::uint64_t length = static_cast<std::uint64_t>(tile.max().x() - tile.min().x() + 1);
        std::fill_n(out.active.begin() + static_cast<std::ptrdiff_t>(row), length, 1);
        std::fill_n(out.from_tile.begin() + static_cast<std::ptrdiff_t>(row), length, 1);
      }
  }
}

}  // namespace

VdbVolume read_vdb(const std::string& path, const std::string& grid_name) {
  openvdb::initialize();
  openvdb::io::File file(path);
  open_vdb(file, path);
  const openvdb::FloatGrid::Ptr grid = choose_float_grid(file, path, grid_name);
  file.close();

  VdbVolume out;
  out.grid_name = grid->getName();
  const std::string context = grid_context(path, out.grid_name);
  out.background = grid->background();
  out.was_half = grid->saveFloatAsHalf();

  const openvdb::CoordBBox box = grid->evalActiveVoxelBoundingBox();
  if (box.empty()) throw Error(ErrorClass::InvalidArgument, context + " has no active voxel: nothing to convert");
  const openvdb::Coord extent = box.dim();
  const Dims dims{static_cast<std::uint32_t>(extent.x()), static_cast<std::uint32_t>(extent.y()),
                  static_cast<std::uint32_t>(extent.z())};
  // Geometry first: a refused transform should not cost a large allocation.
  DenseVolume geometry;
  read_geometry(grid->transform(), box.min(), context, geometry);
  if (const auto unit = grid->getMetadata<openvdb::StringMetadata>("unit")) geometry.unit = unit->value();

  try {
    out.volume = make_dense(dims, SampleType::Float32);
    out.active.assign(out.volume.voxel_count(), 0);
    out.from_tile.assign(out.volume.voxel_count(), 0);
  } catch (const std::exception&) {  // bad_alloc, or length_error past the address space
    throw Error(ErrorClass::LimitExceeded, context + ": the active bounding box, " + std::to_string(dims[0]) + "x" +
                                               std::to_string(dims[1]) + "x" + std::to_string(dims[2]) +
                                               " voxels, does not fit in memory as a dense volume");
  }
  out.volume.voxel_size = geometry.voxel_size;
  out.volume.origin = geometry.origin;
  out.volume.unit = geometry.unit;
  out.volume.has_geometry = true;
  // The byte buffer comes from operator new, aligned for float; OpenVDB
  // writes the samples straight into it.
  DenseFloats dense(box, reinterpret_cast<float*>(out.volume.data.data()));
  openvdb::tools::copyToDense(*grid, dense);
  mark_active(*grid, box, out);
  return out;
}

void write_vdb(const DenseVolume& volume, const std::string& path, float background, const std::string& grid_name,
               bool half) {
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
  std::vector<float> values = volume.to_float();
  const openvdb::CoordBBox box(openvdb::Coord(0, 0, 0), openvdb::Coord(static_cast<int>(volume.dims[0]) - 1,
                                                                       static_cast<int>(volume.dims[1]) - 1,
                                                                       static_cast<int>(volume.dims[2]) - 1));
  openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(background);
  {
    const DenseFloats dense(box, values.data());
    openvdb::tools::copyFromDense(dense, *grid, /*tolerance=*/0.0f);
  }
  openvdb::tools::prune(grid->tree());

  openvdb::math::Transform::Ptr transform = openvdb::math::Transform::createLinearTransform(1.0);
  if (volume.has_geometry) {
    transform->postScale(openvdb::Vec3d(volume.voxel_size[0], volume.voxel_size[1], volume.voxel_size[2]));
    transform->postTranslate(openvdb::Vec3d(volume.origin[0], volume.origin[1], volume.origin[2]));
  }
  grid->setTransform(transform);
  grid->setName(grid_name);
  const bool fog = background == 0.0f && std::all_of(values.begin(), values.end(),
                                                     [](float value) { return value >= 0.0f && value <= 1.0f; });
  grid->setGridClass(fog ? openvdb::GRID_FOG_VOLUME : openvdb::GRID_UNKNOWN);
  grid->setCreator("ivol");
  grid->insertMeta("unit", openvdb::StringMetadata(volume.unit));
  grid->setSaveFloatAsHalf(half);
  values = {};

  StagedFile staged(path);
  try {
    openvdb::io::File file(staged.temp_path());
    file.write({grid});
    file.close();
  } catch (const openvdb::Exception& e) {
    throw Error(ErrorClass::Io, context + ": cannot write (OpenVDB: " + e.what() + ")");
  }
  staged.commit();
}

}  // namespace ivol::convert
