// HDF5 import and export against the other side: files made by h5py are read
// with the values the Python script put there, files we write are checked by
// h5py (values, dtype, chunking, filters, attributes) and by h5dump.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

#include "hdf5_io.hpp"
#include "ivol/binary16.hpp"
#include "ivol/error.hpp"
#include "test_support.hpp"

namespace ivol::convert {
namespace {

using ivol::test::CommandResult;
using ivol::test::run_command;

// Runs a Python script (with h5py and numpy) given as text; argv[1] is `arg`.
CommandResult run_python(const std::string& script, const std::string& arg) {
  const std::string script_path = ivol::test::temp_path("script.py");
  std::ofstream(script_path) << "import sys\nimport numpy as np\nimport h5py\n" << script;
  return run_command(std::string(IVOL_PYTHON) + " " + script_path + " " + arg);
}

// The formulas both sides evaluate, with the same IEEE operations in the same
// order, so that the values agree bit for bit.
std::uint16_t u16_formula(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
  return static_cast<std::uint16_t>((x * 7 + y * 131 + z * 1031) % 65536);
}
float f32_formula(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
  return static_cast<float>(x / 3.0 + y * 0.5 - static_cast<double>(z));
}
const char* kPythonFormulas = R"(
def grid(nz, ny, nx):
    z, y, x = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing='ij')
    return x.astype(np.int64), y.astype(np.int64), z.astype(np.int64)
def u16_formula(nz, ny, nx):
    x, y, z = grid(nz, ny, nx)
    return ((x * 7 + y * 131 + z * 1031) % 65536).astype(np.uint16)
def f32_formula(nz, ny, nx):
    x, y, z = grid(nz, ny, nx)
    return (x / 3.0 + y * 0.5 - z.astype(np.float64)).astype(np.float32)
)";

template <typename Formula>
void expect_volume(const DenseVolume& v, const Dims& dims, Formula formula) {
  ASSERT_EQ(v.dims, dims);
  std::uint64_t i = 0, mismatches = 0;
  for (std::uint32_t z = 0; z < dims[2]; ++z)
    for (std::uint32_t y = 0; y < dims[1]; ++y)
      for (std::uint32_t x = 0; x < dims[0]; ++x, ++i)
        if (v.value(i) != static_cast<double>(formula(x, y, z)) && mismatches++ < 5)
          ADD_FAILURE() << "voxel (" << x << ", " << y << ", " << z << "): " << v.value(i)
                        << " != " << formula(x, y, z);
  EXPECT_EQ(mismatches, 0u);
}

TEST(Hdf5Read, DxchangeGzipChunkedU16FromH5py) {
  const std::string path = ivol::test::temp_path("dxchange.h5");
  const auto made = run_python(std::string(kPythonFormulas) + R"(
with h5py.File(sys.argv[1], 'w') as f:
    d = f.create_dataset('/exchange/data', data=u16_formula(11, 23, 37), chunks=(4, 8, 16),
                         compression='gzip', compression_opts=6, shuffle=True)
    d.attrs['pixel_size'] = 0.05
    d.attrs['units'] = 'mm'
    f.create_dataset('/exchange/theta', data=np.arange(10.0))
)",
                               path);
  ASSERT_EQ(made.exit_code, 0) << made.output;

  Hdf5SourceInfo source;
  const DenseVolume v = read_hdf5(path, "/exchange/data", &source);
  EXPECT_EQ(v.type, SampleType::UInt16);
  expect_volume(v, {37, 23, 11}, u16_formula);
  EXPECT_TRUE(v.has_geometry);
  EXPECT_EQ(v.voxel_size, (std::array<double, 3>{0.05, 0.05, 0.05}));
  EXPECT_EQ(v.origin, (std::array<double, 3>{0, 0, 0}));
  EXPECT_EQ(v.unit, "mm");
  EXPECT_EQ(source.stored_type, "u16");
  EXPECT_TRUE(source.chunked);
  EXPECT_EQ(source.chunk, (std::array<unsigned long long, 3>{4, 8, 16}));
  EXPECT_NE(source.filters.find("deflate"), std::string::npos) << source.filters;
  EXPECT_NE(source.filters.find("shuffle"), std::string::npos) << source.filters;
  // The default dataset is DXchange's.
  expect_volume(read_hdf5(path), {37, 23, 11}, u16_formula);
}

TEST(Hdf5Read, ContiguousF32ElsewhereWithGeometryFromH5py) {
  const std::string path = ivol::test::temp_path("contiguous.h5");
  const auto made = run_python(std::string(kPythonFormulas) + R"(
with h5py.File(sys.argv[1], 'w') as f:
    d = f.create_dataset('/volumes/recon/vol', data=f32_formula(5, 9, 70))
    assert d.chunks is None
    d.attrs['voxel_size'] = np.array([0.3, 0.2, 0.1])   # z, y, x
    d.attrs['origin'] = np.array([-1.5, 2.0, 4.25])     # z, y, x
    d.attrs['unit'] = np.bytes_('um')                   # fixed-length string
)",
                               path);
  ASSERT_EQ(made.exit_code, 0) << made.output;

  Hdf5SourceInfo source;
  const DenseVolume v = read_hdf5(path, "/volumes/recon/vol", &source);
  EXPECT_EQ(v.type, SampleType::Float32);
  expect_volume(v, {70, 9, 5}, f32_formula);
  EXPECT_TRUE(v.has_geometry);
  EXPECT_EQ(v.voxel_size, (std::array<double, 3>{0.1, 0.2, 0.3}));
  EXPECT_EQ(v.origin, (std::array<double, 3>{4.25, 2.0, -1.5}));
  EXPECT_EQ(v.unit, "um");
  EXPECT_FALSE(source.chunked);
  EXPECT_EQ(source.filters, "");
}

TEST(Hdf5Read, OtherSampleTypesFromH5py) {
  const std::string path = ivol::test::temp_path("types.h5");
  const auto made = run_python(std::string(kPythonFormulas) + R"(
with h5py.File(sys.argv[1], 'w') as f:
    u = u16_formula(3, 4, 5)
    f.create_dataset('u8', data=(u % 256).astype(np.uint8), chunks=(1, 2, 5), compression='gzip')
    f.create_dataset('i16', data=(u.astype(np.int32) - 30000).astype(np.int16))
    f.create_dataset('f16', data=f32_formula(3, 4, 5).astype(np.float16), compression='gzip')
    f.create_dataset('f64', data=f32_formula(3, 4, 5).astype(np.float64) / 7.0)
    f.create_dataset('big_endian', data=u16_formula(3, 4, 5).astype('>u2'))
    f.create_dataset('no_geometry', data=u16_formula(3, 4, 5))
)",
                               path);
  ASSERT_EQ(made.exit_code, 0) << made.output;
  const Dims dims{5, 4, 3};

  DenseVolume u8 = read_hdf5(path, "/u8");
  EXPECT_EQ(u8.type, SampleType::UInt8);
  expect_volume(u8, dims, [](auto x, auto y, auto z) { return u16_formula(x, y, z) % 256; });

  DenseVolume i16 = read_hdf5(path, "i16");
  EXPECT_EQ(i16.type, SampleType::Int16);
  expect_volume(i16, dims,
                [](auto x, auto y, auto z) { return static_cast<std::int16_t>(u16_formula(x, y, z) - 30000); });

  DenseVolume f16 = read_hdf5(path, "/f16");
  EXPECT_EQ(f16.type, SampleType::Float16);
  expect_volume(f16, dims, [](auto x, auto y, auto z) {
    return ivol::binary16_to_float(ivol::float_to_binary16(f32_formula(x, y, z)));
  });

  Hdf5SourceInfo source;
  DenseVolume f64 = read_hdf5(path, "/f64", &source);
  EXPECT_EQ(f64.type, SampleType::Float32);
  EXPECT_EQ(source.stored_type, "f64");
  EXPECT_TRUE(source.narrowed_to_f32);
  expect_volume(f64, dims,
                [](auto x, auto y, auto z) { return static_cast<float>(double(f32_formula(x, y, z)) / 7.0); });

  expect_volume(read_hdf5(path, "/big_endian"), dims, u16_formula);
  EXPECT_FALSE(read_hdf5(path, "/no_geometry").has_geometry);
}

// A volume of every sample type by the formulas, with or without geometry.
DenseVolume formula_volume(const Dims& dims, SampleType type) {
  DenseVolume v = make_dense(dims, type);
  std::uint64_t i = 0;
  for (std::uint32_t z = 0; z < dims[2]; ++z)
    for (std::uint32_t y = 0; y < dims[1]; ++y)
      for (std::uint32_t x = 0; x < dims[0]; ++x, ++i) {
        std::uint8_t* p = v.data.data() + i * sample_size(type);
        if (type == SampleType::UInt16) {
          const std::uint16_t value = u16_formula(x, y, z);
          std::memcpy(p, &value, 2);
        } else if (type == SampleType::Float32) {
          const float value = f32_formula(x, y, z);
          std::memcpy(p, &value, 4);
        } else if (type == SampleType::Float16) {
          const std::uint16_t value = ivol::float_to_binary16(f32_formula(x, y, z));
          std::memcpy(p, &value, 2);
        } else if (type == SampleType::Int16) {
          const auto value = static_cast<std::int16_t>(u16_formula(x, y, z) - 30000);
          std::memcpy(p, &value, 2);
        } else {
          *p = static_cast<std::uint8_t>(u16_formula(x, y, z) % 256);
        }
      }
  return v;
}

// h5py checks what write_hdf5 wrote; the script exits non-zero with the reason.
const char* kCheckWrittenFile = R"(
path, name, dtype, nz, ny, nx, geometry = sys.argv[1].split(',')
nz, ny, nx = int(nz), int(ny), int(nx)
with h5py.File(path, 'r') as f:
    d = f[name]
    assert d.shape == (nz, ny, nx), d.shape
    assert d.dtype == np.dtype(dtype), d.dtype
    assert d.dtype.byteorder in ('<', '=', '|'), d.dtype.byteorder
    assert d.chunks == (min(64, nz), min(64, ny), min(64, nx)), d.chunks
    assert d.compression == 'gzip', d.compression
    assert d.compression_opts == 4, d.compression_opts
    assert d.shuffle, 'no shuffle filter'
    data = d[()]
    if dtype == 'uint16':
        expected = u16_formula(nz, ny, nx)
    elif dtype == 'int16':
        expected = (u16_formula(nz, ny, nx).astype(np.int32) - 30000).astype(np.int16)
    elif dtype == 'uint8':
        expected = (u16_formula(nz, ny, nx) % 256).astype(np.uint8)
    else:
        expected = f32_formula(nz, ny, nx).astype(dtype)
    bad = np.argwhere(data != expected)
    assert len(bad) == 0, 'first bad voxel (z, y, x) %s: %s != %s' % (bad[0], data[tuple(bad[0])], expected[tuple(bad[0])])
    if geometry == 'yes':
        assert list(d.attrs['voxel_size']) == [0.5, 0.25, 0.125], d.attrs['voxel_size']
        assert list(d.attrs['origin']) == [3.0, 2.0, 1.0], d.attrs['origin']
        assert d.attrs['unit'] == 'um', repr(d.attrs['unit'])
    else:
        assert 'voxel_size' not in d.attrs and 'origin' not in d.attrs
print('ok')
)";

void check_with_h5py(const std::string& path, const std::string& name, const std::string& dtype, const Dims& dims,
                     bool geometry) {
  const std::string arg = path + "," + name + "," + dtype + "," + std::to_string(dims[2]) + "," +
                          std::to_string(dims[1]) + "," + std::to_string(dims[0]) + "," + (geometry ? "yes" : "no");
  const auto checked = run_python(std::string(kPythonFormulas) + kCheckWrittenFile, arg);
  EXPECT_EQ(checked.exit_code, 0) << checked.output;
}

TEST(Hdf5Write, ReadByH5pyAndH5dump) {
  struct Case {
    SampleType type;
    const char* dtype;
  };
  for (const Case& c :
       {Case{SampleType::UInt16, "uint16"}, Case{SampleType::Float32, "float32"}, Case{SampleType::Float16, "float16"},
        Case{SampleType::Int16, "int16"}, Case{SampleType::UInt8, "uint8"}}) {
    SCOPED_TRACE(c.dtype);
    const Dims dims{70, 9, 130};  // chunks clip to (64, 9, 64) in x and y, 2 and 3 chunks along x and z
    DenseVolume v = formula_volume(dims, c.type);
    v.has_geometry = true;
    v.voxel_size = {0.125, 0.25, 0.5};
    v.origin = {1.0, 2.0, 3.0};
    v.unit = "um";
    const std::string path = ivol::test::temp_path(std::string("written-") + c.dtype + ".h5");
    write_hdf5(v, path);
    check_with_h5py(path, "/exchange/data", c.dtype, dims, true);

    // And back through our reader, geometry included.
    const DenseVolume back = read_hdf5(path);
    EXPECT_EQ(back.type, c.type);
    EXPECT_EQ(back.data, v.data);
    EXPECT_TRUE(back.has_geometry);
    EXPECT_EQ(back.voxel_size, v.voxel_size);
    EXPECT_EQ(back.origin, v.origin);
    EXPECT_EQ(back.unit, "um");
  }

  const std::string path = ivol::test::temp_path("nested.h5");
  write_hdf5(formula_volume({3, 4, 5}, SampleType::UInt16), path, "/a/b/c/volume");
  check_with_h5py(path, "/a/b/c/volume", "uint16", {3, 4, 5}, false);
  const auto dumped = run_command("h5dump -H " + path);
  EXPECT_EQ(dumped.exit_code, 0) << dumped.output;
  EXPECT_NE(dumped.output.find("DATASET \"volume\""), std::string::npos) << dumped.output;
  EXPECT_NE(dumped.output.find("H5T_STD_U16LE"), std::string::npos) << dumped.output;
  EXPECT_NE(dumped.output.find("( 5, 4, 3 )"), std::string::npos) << dumped.output;
  EXPECT_FALSE(read_hdf5(path, "/a/b/c/volume").has_geometry);
}

std::size_t files_in(const std::string& directory) {
  std::size_t count = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(directory)) ++count;
  return count;
}

TEST(Hdf5Write, NeverLeavesAPartialFile) {
  const std::string directory = ivol::test::temp_path("staged");
  std::filesystem::create_directory(directory);
  const std::string path = directory + "/out.h5";
  const DenseVolume v = formula_volume({8, 8, 8}, SampleType::UInt16);

  // HDF5 refuses the name only once the temporary file exists: it must go.
  EXPECT_THROW(write_hdf5(v, path, "/exchange/."), ivol::Error);
  EXPECT_EQ(files_in(directory), 0u);

  write_hdf5(v, path);
  EXPECT_EQ(files_in(directory), 1u);
  // Replacing an existing file goes through a temporary too.
  write_hdf5(formula_volume({4, 4, 4}, SampleType::Float32), path);
  EXPECT_EQ(files_in(directory), 1u);
  EXPECT_EQ(read_hdf5(path).dims, (Dims{4, 4, 4}));

  try {
    write_hdf5(v, directory + "/missing-dir/out.h5");
    FAIL() << "wrote into a missing directory";
  } catch (const ivol::Error& e) {
    EXPECT_EQ(e.error_class(), ErrorClass::Io);
    EXPECT_NE(std::string(e.what()).find("missing-dir"), std::string::npos) << e.what();
  }
  EXPECT_THROW(write_hdf5(v, path, "/exchange/data", 10), ivol::Error);
}

// The error's class and that its message holds every one of `parts`.
void expect_error(const std::function<void()>& call, ErrorClass error_class, std::vector<std::string> parts) {
  try {
    call();
    ADD_FAILURE() << "no error";
  } catch (const ivol::Error& e) {
    EXPECT_EQ(e.error_class(), error_class) << e.what();
    for (const std::string& part : parts) EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
  }
}

TEST(Hdf5Read, ClearErrors) {
  const std::string path = ivol::test::temp_path("errors.h5");
  const auto made = run_python(R"(
with h5py.File(sys.argv[1], 'w') as f:
    f.create_dataset('/exchange/data_white', data=np.zeros((2, 3, 4), np.uint16))
    f.create_dataset('/exchange/data_dark', data=np.zeros((2, 3, 5), np.float32))
    f.create_dataset('/image', data=np.zeros((3, 4), np.uint16))
    f.create_dataset('/u32', data=np.zeros((2, 2, 2), np.uint32))
    f.create_dataset('/lzf', data=np.zeros((2, 2, 2), np.uint16), compression='lzf')
    f.create_dataset('/bad_size', data=np.zeros((2, 2, 2), np.uint16)).attrs['voxel_size'] = [1.0, 2.0]
    f.create_dataset('/negative_size', data=np.zeros((2, 2, 2), np.uint16)).attrs['pixel_size'] = -1.0
)",
                               path);
  ASSERT_EQ(made.exit_code, 0) << made.output;

  expect_error([&] { read_hdf5(path); }, ErrorClass::InvalidArgument,
               {path, "/exchange/data", "/exchange/data_white (shape 2x3x4)", "/exchange/data_dark (shape 2x3x5)"});
  expect_error([&] { read_hdf5(path, "/exchange"); }, ErrorClass::InvalidArgument, {"not a dataset"});
  expect_error([&] { read_hdf5(path, "/image"); }, ErrorClass::InvalidArgument, {path, "/image", "2-D"});
  expect_error([&] { read_hdf5(path, "/u32"); }, ErrorClass::InvalidArgument, {"/u32", "u32"});
  expect_error([&] { read_hdf5(path, "/lzf"); }, ErrorClass::InvalidArgument, {"/lzf", "filter", "lzf"});
  expect_error([&] { read_hdf5(path, "/bad_size"); }, ErrorClass::Malformed, {"voxel_size", "2 values"});
  expect_error([&] { read_hdf5(path, "/negative_size"); }, ErrorClass::Malformed, {"pixel_size", "positive"});

  const std::string not_hdf5 = ivol::test::temp_path("not.h5");
  std::ofstream(not_hdf5) << "this is a text file, not HDF5\n";
  expect_error([&] { read_hdf5(not_hdf5); }, ErrorClass::Malformed, {not_hdf5, "not an HDF5 file"});
  expect_error([&] { read_hdf5(ivol::test::temp_path("absent.h5")); }, ErrorClass::Io, {"absent.h5"});

  const std::string empty_file = ivol::test::temp_path("no3d.h5");
  ASSERT_EQ(run_python("h5py.File(sys.argv[1], 'w').create_dataset('x', data=np.zeros(3))", empty_file).exit_code, 0);
  expect_error([&] { read_hdf5(empty_file); }, ErrorClass::InvalidArgument, {"no 3-D dataset"});
}

}  // namespace
}  // namespace ivol::convert
