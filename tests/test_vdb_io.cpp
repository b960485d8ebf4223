// OpenVDB import and export against OpenVDB itself: grids built and saved
// with its C++ API (normal and half float) are read back voxel by voxel
// against the grid's own answers, and files we write are read by its API and
// printed by vdb_print.
#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <string>

#include "ivol/binary16.hpp"
#include "ivol/error.hpp"
#include "test_support.hpp"
#include "vdb_grid.hpp"
#include "vdb_io.hpp"

namespace ivol::convert {
namespace {

using ivol::test::CommandResult;
using ivol::test::run_command;

void save(const std::string& path, const openvdb::GridPtrVec& grids) {
  openvdb::io::File file(path);
  file.write(grids);
  file.close();
}

// A float grid as a simulation would leave it: scattered active voxels
// (negative coordinates too), an active 8^3 tile, an inactive voxel that is
// not background, a non-zero background and a scaled, translated transform.
// Every value is a binary16 number, so that saving as half loses nothing.
openvdb::FloatGrid::Ptr make_reference_grid() {
  openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(-1.0f);
  grid->setName("density");
  auto& tree = grid->tree();
  tree.setValue(openvdb::Coord(-3, 2, 5), 1.25f);
  tree.setValue(openvdb::Coord(0, 0, 0), 0.5f);
  tree.setValue(openvdb::Coord(30, -4, 9), -0.75f);
  tree.setValue(openvdb::Coord(12, 11, 1), 2.0f);
  tree.setValueOff(openvdb::Coord(5, 5, 5), 7.0f);        // inactive, yet not background
  tree.addTile(1, openvdb::Coord(16, 0, 0), 2.5f, true);  // level 1: one leaf's worth, [16, 23] x [0, 7] x [0, 7]
  openvdb::math::Transform::Ptr transform = openvdb::math::Transform::createLinearTransform(0.25);
  transform->postTranslate(openvdb::Vec3d(1.0, 2.0, 3.0));
  grid->setTransform(transform);
  return grid;
}

// Checks every dense voxel against the grid's own accessor.
void expect_matches_grid(const VdbVolume& read, const openvdb::FloatGrid& grid) {
  const openvdb::CoordBBox box = grid.evalActiveVoxelBoundingBox();
  const openvdb::Coord extent = box.dim();
  ASSERT_EQ(read.volume.dims, (Dims{std::uint32_t(extent.x()), std::uint32_t(extent.y()), std::uint32_t(extent.z())}));
  ASSERT_EQ(read.active.size(), read.volume.voxel_count());
  ASSERT_EQ(read.from_tile.size(), read.volume.voxel_count());
  EXPECT_EQ(read.volume.type, SampleType::Float32);
  auto accessor = grid.getConstAccessor();
  const int leaf_depth = static_cast<int>(openvdb::FloatTree::DEPTH) - 1;
  std::uint64_t i = 0, bad = 0, active = 0, tiled = 0;
  for (int z = box.min().z(); z <= box.max().z(); ++z)
    for (int y = box.min().y(); y <= box.max().y(); ++y)
      for (int x = box.min().x(); x <= box.max().x(); ++x, ++i) {
        const openvdb::Coord c(x, y, z);
        const bool is_on = accessor.isValueOn(c);
        const bool in_tile = is_on && accessor.getValueDepth(c) != leaf_depth;
        active += is_on;
        tiled += in_tile;
        if ((read.volume.value(i) != accessor.getValue(c) || read.active[i] != is_on || read.from_tile[i] != in_tile) &&
            bad++ < 5)
          ADD_FAILURE() << "index " << c << ": value " << read.volume.value(i) << " vs " << accessor.getValue(c)
                        << ", active " << int(read.active[i]) << " vs " << is_on << ", tile " << int(read.from_tile[i])
                        << " vs " << in_tile;
      }
  EXPECT_EQ(bad, 0u);
  EXPECT_EQ(active, grid.activeVoxelCount());
  EXPECT_GT(tiled, 0u);
}

TEST(VdbRead, GridBuiltWithOpenVdbNormalAndHalf) {
  openvdb::initialize();
  for (bool half : {false, true}) {
    SCOPED_TRACE(half ? "half" : "float");
    openvdb::FloatGrid::Ptr grid = make_reference_grid();
    grid->setSaveFloatAsHalf(half);
    // A grid of another type first, and a second float grid after: the
    // default is the first float grid.
    openvdb::Int32Grid::Ptr labels = openvdb::Int32Grid::create(0);
    labels->setName("labels");
    labels->tree().setValue(openvdb::Coord(1, 1, 1), 3);
    openvdb::FloatGrid::Ptr other = openvdb::FloatGrid::create(0.0f);
    other->setName("temperature");
    other->tree().setValue(openvdb::Coord(100, 100, 100), 1.0f);
    const std::string path = ivol::test::temp_path(half ? "half.vdb" : "float.vdb");
    save(path, {labels, grid, other});

    const VdbVolume read = read_vdb(path);
    EXPECT_EQ(read.grid_name, "density");
    EXPECT_EQ(read.was_half, half);
    EXPECT_EQ(read.background, -1.0f);
    expect_matches_grid(read, *grid);
    // Spot checks by hand: the box is [-3, 30] x [-4, 11] x [0, 9].
    EXPECT_EQ(read.volume.dims, (Dims{34, 16, 10}));
    const auto at = [&](int x, int y, int z) { return ((z - 0) * 16 + (y + 4)) * 34 + (x + 3); };
    EXPECT_EQ(read.volume.value(at(-3, 2, 5)), 1.25);
    EXPECT_EQ(read.volume.value(at(20, 3, 7)), 2.5);
    EXPECT_EQ(read.from_tile[at(20, 3, 7)], 1);
    EXPECT_EQ(read.from_tile[at(12, 11, 1)], 0);
    EXPECT_EQ(read.active[at(5, 5, 5)], 0);
    EXPECT_EQ(read.volume.value(at(5, 5, 5)), 7.0);
    EXPECT_EQ(read.volume.value(at(4, 4, 4)), -1.0);  // background
    EXPECT_TRUE(read.volume.has_geometry);
    EXPECT_EQ(read.volume.voxel_size, (std::array<double, 3>{0.25, 0.25, 0.25}));
    // Centre of index (-3, -4, 0): (1, 2, 3) + 0.25 * (-3, -4, 0).
    EXPECT_EQ(read.volume.origin, (std::array<double, 3>{0.25, 1.0, 3.0}));

    const VdbVolume second = read_vdb(path, "temperature");
    EXPECT_EQ(second.volume.dims, (Dims{1, 1, 1}));
    EXPECT_EQ(second.volume.value(0), 1.0);
    EXPECT_EQ(second.volume.origin, (std::array<double, 3>{100, 100, 100}));
  }
}

TEST(VdbRead, AxisAlignedNonUniformScale) {
  openvdb::initialize();
  openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(0.0f);
  grid->setName("stretched");
  grid->tree().setValue(openvdb::Coord(2, 3, 4), 1.0f);
  grid->tree().setValue(openvdb::Coord(3, 3, 4), 2.0f);
  openvdb::math::Transform::Ptr transform = openvdb::math::Transform::createLinearTransform(1.0);
  transform->postScale(openvdb::Vec3d(0.5, 1.0, 2.0));
  grid->setTransform(transform);
  const std::string path = ivol::test::temp_path("stretched.vdb");
  save(path, {grid});
  const VdbVolume read = read_vdb(path);
  EXPECT_EQ(read.volume.dims, (Dims{2, 1, 1}));
  EXPECT_EQ(read.volume.voxel_size, (std::array<double, 3>{0.5, 1.0, 2.0}));
  EXPECT_EQ(read.volume.origin, (std::array<double, 3>{1.0, 3.0, 8.0}));
}

// u16 samples below 2048 (exact in binary16), zero on the x < 4 slab so that
// the active box starts at x = 4, and one uniform 8^3 block that pruning
// must turn into a tile.
DenseVolume make_volume_with_uniform_block() {
  const Dims dims{24, 16, 16};
  DenseVolume v = make_dense(dims, SampleType::UInt16);
  std::uint64_t i = 0;
  for (std::uint32_t z = 0; z < dims[2]; ++z)
    for (std::uint32_t y = 0; y < dims[1]; ++y)
      for (std::uint32_t x = 0; x < dims[0]; ++x, ++i) {
        std::uint16_t value = static_cast<std::uint16_t>((x * 7 + y * 131 + z * 1031) % 2000);
        if (x < 4) value = 0;
        if (x >= 8 && x < 16 && y < 8 && z >= 8) value = 500;
        std::memcpy(v.data.data() + 2 * i, &value, 2);
      }
  v.has_geometry = true;
  v.voxel_size = {0.5, 0.5, 0.5};
  v.origin = {1.0, 2.0, 3.0};
  v.unit = "um";
  return v;
}

openvdb::FloatGrid::Ptr read_with_openvdb(const std::string& path, const std::string& name) {
  openvdb::io::File file(path);
  file.open();
  openvdb::GridBase::Ptr base = file.readGrid(name);
  file.close();
  EXPECT_TRUE(base->isType<openvdb::FloatGrid>()) << base->type();
  return openvdb::gridPtrCast<openvdb::FloatGrid>(base);
}

TEST(VdbWrite, ReadByOpenVdbAndVdbPrint) {
  openvdb::initialize();
  const DenseVolume v = make_volume_with_uniform_block();
  for (bool half : {true, false}) {
    SCOPED_TRACE(half ? "half" : "float");
    const std::string path = ivol::test::temp_path(half ? "ours-half.vdb" : "ours.vdb");
    write_vdb(v, path, 0.0f, "ct", half);

    const openvdb::FloatGrid::Ptr grid = read_with_openvdb(path, "ct");
    ASSERT_TRUE(grid);
    EXPECT_EQ(grid->background(), 0.0f);
    EXPECT_EQ(grid->saveFloatAsHalf(), half);
    EXPECT_EQ(grid->getGridClass(), openvdb::GRID_UNKNOWN);  // values beyond [0, 1]: not a fog volume
    const auto unit = grid->getMetadata<openvdb::StringMetadata>("unit");
    ASSERT_TRUE(unit);
    EXPECT_EQ(unit->value(), "um");
    EXPECT_TRUE(grid->transform().isLinear());
    EXPECT_EQ(grid->transform().voxelSize(), openvdb::Vec3d(0.5, 0.5, 0.5));
    EXPECT_EQ(grid->transform().indexToWorld(openvdb::Coord(0, 0, 0)), openvdb::Vec3d(1.0, 2.0, 3.0));
    EXPECT_EQ(grid->transform().indexToWorld(openvdb::Coord(2, 4, 6)), openvdb::Vec3d(2.0, 4.0, 6.0));

    auto accessor = grid->getConstAccessor();
    std::uint64_t i = 0, expected_active = 0, bad = 0;
    for (std::uint32_t z = 0; z < v.dims[2]; ++z)
      for (std::uint32_t y = 0; y < v.dims[1]; ++y)
        for (std::uint32_t x = 0; x < v.dims[0]; ++x, ++i) {
          const openvdb::Coord c{static_cast<int>(x), static_cast<int>(y), static_cast<int>(z)};
          const bool should_be_on = v.value(i) != 0.0;
          expected_active += should_be_on;
          if ((accessor.getValue(c) != v.value(i) || accessor.isValueOn(c) != should_be_on) && bad++ < 5)
            ADD_FAILURE() << c << ": " << accessor.getValue(c) << " vs " << v.value(i);
        }
    EXPECT_EQ(bad, 0u);
    EXPECT_EQ(grid->activeVoxelCount(), expected_active);

    // The uniform block is a tile now, exactly where it was.
    std::vector<openvdb::CoordBBox> tiles;
    std::vector<float> tile_values;
    for (auto value = grid->cbeginValueOn(); value; ++value)
      if (!value.isVoxelValue()) {
        tiles.push_back(value.getBoundingBox());
        tile_values.push_back(*value);
      }
    ASSERT_EQ(tiles.size(), 1u);
    EXPECT_EQ(tiles[0], openvdb::CoordBBox(openvdb::Coord(8, 0, 8), openvdb::Coord(15, 7, 15)));
    EXPECT_EQ(tile_values[0], 500.0f);

    const auto printed = run_command("vdb_print -l " + path);
    EXPECT_EQ(printed.exit_code, 0) << printed.output;
    EXPECT_NE(printed.output.find("ct"), std::string::npos) << printed.output;
    EXPECT_NE(printed.output.find("float"), std::string::npos) << printed.output;

    // And back through our reader: the box of active voxels starts at x = 4.
    const VdbVolume back = read_vdb(path);
    EXPECT_EQ(back.volume.dims, (Dims{20, 16, 16}));
    EXPECT_EQ(back.volume.origin, (std::array<double, 3>{3.0, 2.0, 3.0}));
    EXPECT_EQ(back.volume.unit, "um");
    EXPECT_EQ(back.was_half, half);
    EXPECT_EQ(back.from_tile[(8 * 16 + 0) * 20 + (8 - 4)], 1);
  }
}

TEST(VdbWrite, HalfRoundsFloatsAndFogClass) {
  openvdb::initialize();
  DenseVolume v = make_dense({5, 4, 3}, SampleType::Float32);
  for (std::uint64_t i = 0; i < v.voxel_count(); ++i) {
    const float value = static_cast<float>(i) / 60.0f;  // in [0, 1), mostly not binary16 numbers
    std::memcpy(v.data.data() + 4 * i, &value, 4);
  }
  for (bool half : {true, false}) {
    const std::string path = ivol::test::temp_path(half ? "fog-half.vdb" : "fog.vdb");
    write_vdb(v, path, 0.0f, "density", half);
    const openvdb::FloatGrid::Ptr grid = read_with_openvdb(path, "density");
    EXPECT_EQ(grid->getGridClass(), openvdb::GRID_FOG_VOLUME);
    EXPECT_EQ(grid->transform().voxelSize(), openvdb::Vec3d(1, 1, 1));  // no geometry: identity
    auto accessor = grid->getConstAccessor();
    std::uint64_t i = 0;
    for (int z = 0; z < 3; ++z)
      for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 5; ++x, ++i) {
          const float value = static_cast<float>(v.value(i));
          const float expected = half ? ivol::binary16_to_float(ivol::float_to_binary16(value)) : value;
          EXPECT_EQ(accessor.getValue(openvdb::Coord(x, y, z)), expected) << x << " " << y << " " << z;
        }
  }
}

std::size_t files_in(const std::string& directory) {
  std::size_t count = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(directory)) ++count;
  return count;
}

void expect_error(const std::function<void()>& call, ErrorClass error_class, std::vector<std::string> parts) {
  try {
    call();
    ADD_FAILURE() << "no error";
  } catch (const ivol::Error& e) {
    EXPECT_EQ(e.error_class(), error_class) << e.what();
    for (const std::string& part : parts) EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
  }
}

TEST(VdbWrite, NeverLeavesAPartialFile) {
  const std::string directory = ivol::test::temp_path("staged");
  std::filesystem::create_directory(directory);
  const DenseVolume v = make_volume_with_uniform_block();
  write_vdb(v, directory + "/a.vdb", 0.0f);
  write_vdb(v, directory + "/a.vdb", 0.0f);  // replaced through a temporary too
  EXPECT_EQ(files_in(directory), 1u);
  expect_error([&] { write_vdb(v, directory + "/missing/a.vdb", 0.0f); }, ErrorClass::Io, {"missing"});
  expect_error([&] { write_vdb(v, directory + "/b.vdb", 0.0f, ""); }, ErrorClass::InvalidArgument, {"name"});
  EXPECT_EQ(files_in(directory), 1u);
}

TEST(VdbRead, ClearErrors) {
  openvdb::initialize();
  const std::string path = ivol::test::temp_path("grids.vdb");
  openvdb::FloatGrid::Ptr density = make_reference_grid();
  openvdb::Int32Grid::Ptr labels = openvdb::Int32Grid::create(0);
  labels->setName("labels");
  labels->tree().setValue(openvdb::Coord(1, 1, 1), 3);
  save(path, {labels, density});

  expect_error([&] { read_vdb(path, "pressure"); }, ErrorClass::InvalidArgument,
               {path, "'pressure'", "'labels' (int32)", "'density' (float)"});
  expect_error([&] { read_vdb(path, "labels"); }, ErrorClass::InvalidArgument, {path, "'labels'", "int32"});

  const std::string only_int = ivol::test::temp_path("int.vdb");
  save(only_int, {labels});
  expect_error([&] { read_vdb(only_int); }, ErrorClass::InvalidArgument, {"no float grid", "'labels' (int32)"});

  const std::string rotated = ivol::test::temp_path("rotated.vdb");
  openvdb::FloatGrid::Ptr turned = make_reference_grid();
  turned->transform().postRotate(0.3, openvdb::math::Z_AXIS);
  save(rotated, {turned});
  expect_error([&] { read_vdb(rotated); }, ErrorClass::InvalidArgument, {"'density'", "rotates"});

  const std::string frustum = ivol::test::temp_path("frustum.vdb");
  openvdb::FloatGrid::Ptr seen = make_reference_grid();
  seen->setTransform(openvdb::math::Transform::createFrustumTransform(
      openvdb::BBoxd(openvdb::Vec3d(0, 0, 0), openvdb::Vec3d(63, 63, 63)), 0.5, 2.0));
  save(frustum, {seen});
  expect_error([&] { read_vdb(frustum); }, ErrorClass::InvalidArgument, {"not linear"});

  const std::string empty = ivol::test::temp_path("empty.vdb");
  openvdb::FloatGrid::Ptr nothing = openvdb::FloatGrid::create(0.0f);
  nothing->setName("nothing");
  save(empty, {nothing});
  expect_error([&] { read_vdb(empty); }, ErrorClass::InvalidArgument, {"'nothing'", "no active voxel"});

  const std::string text = ivol::test::temp_path("text.vdb");
  std::ofstream(text) << "this is not a VDB file\n";
  expect_error([&] { read_vdb(text); }, ErrorClass::Malformed, {text, "not a VDB file"});
  expect_error([&] { read_vdb(ivol::test::temp_path("absent.vdb")); }, ErrorClass::Io, {"absent.vdb"});
}

}  // namespace
}  // namespace ivol::convert

// The dense copy walks the tree node by node and clips each node to the
// active box: tiles of every level (root 4096^3, upper 128^3, lower 8^3),
// inactive tiles and voxels with their own values inside the box, nodes
// that only partly meet it, at both ends of the 32-bit index space. Each
// voxel must equal what OpenVDB's accessor gives there.
TEST(VdbRead, DenseCopyMatchesTheAccessorAtTheIndexSpaceEdges) {
  openvdb::initialize();
  for (const int base : {0, std::numeric_limits<int>::min(), std::numeric_limits<int>::max() - 4095}) {
    SCOPED_TRACE(base);
    openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(-1.0f);
    openvdb::FloatTree& tree = grid->tree();
    const openvdb::Coord o(base, base, base);
    tree.addTile(1, o.offsetBy(8, 0, 0), 2.0f, /*active=*/true);     // a lower node's 8^3 tile
    tree.addTile(1, o.offsetBy(16, 0, 0), 3.0f, /*active=*/false);   // inactive, inside the box
    tree.setValueOn(o.offsetBy(3, 4, 5), 4.0f);
    tree.setValueOff(o.offsetBy(2, 2, 2), -0.0f);
    tree.setValueOn(o.offsetBy(29, 21, 13), std::numeric_limits<float>::quiet_NaN());
    tree.addTile(2, o.offsetBy(128, 0, 0), 5.0f, /*active=*/false);  // an upper node's 128^3 tile, outside
    const ivol::convert::VdbVolume out = ivol::convert::volume_from_grid(*grid, "edges", 0);
    // Active: the 8^3 tile (x 8..15, y 0..7, z 0..7) and two voxels.
    ASSERT_EQ(out.volume.dims, (ivol::Dims{27, 22, 14}));
    openvdb::FloatGrid::ConstAccessor look = grid->getConstAccessor();
    std::uint64_t i = 0, from_tile = 0, active = 0, inactive_tile_voxels = 0;
    for (int z = 0; z < 14; ++z)
      for (int y = 0; y < 22; ++y)
        for (int x = 0; x < 27; ++x, ++i) {
          const openvdb::Coord c = o.offsetBy(3 + x, y, z);
          const float want = look.getValue(c);
          ASSERT_EQ(std::memcmp(&want, out.volume.data.data() + 4 * i, 4), 0) << c;
          ASSERT_EQ(out.active[i] != 0, look.isValueOn(c)) << c;
          ASSERT_EQ(out.from_tile[i] != 0, look.isValueOn(c) && !look.isVoxel(c)) << c;
          from_tile += out.from_tile[i];
          active += out.active[i];
          inactive_tile_voxels += want == 3.0f;
        }
    EXPECT_EQ(from_tile, 512u);
    EXPECT_EQ(active, 514u);
    EXPECT_EQ(inactive_tile_voxels, 8u * 8 * 8);
  }
}
