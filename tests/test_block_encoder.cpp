// WriteOptions::encoder (ivol/block_encoder.hpp): a writer whose blocks are
// compressed elsewhere, in batches, writes the same file bit for bit as one
// that compresses them itself, for every writer that compresses blocks
// (write_octree, the streaming octree writer, the grid structures); and an
// encoder's failure fails the write and leaves nothing behind.
#include <gtest/gtest.h>

#include <filesystem>
#include <random>
#include <stdexcept>

#include "ivol/block_encoder.hpp"
#include "ivol/build.hpp"
#include "ivol/streaming_writer.hpp"
#include "ivol/structures.hpp"
#include "test_support.hpp"

namespace {

using namespace ivol;

// Compresses each batch one block at a time, last block first, as another
// process would (with a fresh options object holding only what travels).
class ReversingEncoder final : public BlockEncoder {
 public:
  explicit ReversingEncoder(std::size_t batch, bool fail = false) : batch_(batch), fail_(fail) {}
  std::size_t batch_blocks() const override { return batch_; }
  std::vector<EncodedBlock> encode(const std::vector<RawBlock>& batch, const WriteOptions& options) override {
    if (fail_) throw std::runtime_error("rank 1: compressing blocks for rank 0: no");
    WriteOptions remote;
    remote.zstd_level = options.zstd_level;
    remote.compress = options.compress;
    remote.byte_planes = options.byte_planes;
    remote.threads = 1;
    std::vector<EncodedBlock> out(batch.size());
    for (std::size_t i = batch.size(); i-- > 0;) out[i] = encode_blocks(&batch[i], 1, remote).front();
    ++batches;
    blocks += batch.size();
    return out;
  }
  std::size_t batches = 0;
  std::size_t blocks = 0;

 private:
  std::size_t batch_;
  bool fail_;
};

std::vector<std::uint8_t> write_streamed(const std::vector<float>& volume, const Dims& dims, const std::string& path,
                                         std::shared_ptr<BlockEncoder> encoder) {
  StreamingOptions options;
  options.write.block_bytes = 512;
  options.write.encoder = std::move(encoder);
  options.slab_slices = 8;
  StreamingOctreeWriter writer(path, dims, options);
  const std::uint64_t slice = std::uint64_t{dims[0]} * dims[1];
  while (writer.next_slab_count() > 0) writer.add_slab(volume.data() + writer.next_slab_first() * slice);
  writer.finish(Metadata{});
  return test::read_bytes(path);
}

TEST(BlockEncoder, StreamingOctreeSameBytes) {
  const Dims dims{40, 33, 29};
  std::mt19937_64 rng(10);
  const std::vector<float> volume = test::random_volume(dims, rng, 0.05, 5);
  const auto here = write_streamed(volume, dims, test::temp_path("here.ivol"), nullptr);
  for (std::size_t batch : {1, 7, 64}) {
    auto encoder = std::make_shared<ReversingEncoder>(batch);
    const auto elsewhere = write_streamed(volume, dims, test::temp_path("elsewhere.ivol"), encoder);
    EXPECT_EQ(here, elsewhere) << "batches of " << batch;
    EXPECT_GT(encoder->blocks, 10u);
    EXPECT_GE(encoder->batches, encoder->blocks / batch);
  }
}

TEST(BlockEncoder, OctreeAndGridStructuresSameBytes) {
  const Dims dims{32, 32, 24};
  std::mt19937_64 rng(11);
  const std::vector<float> volume = test::random_volume(dims, rng, 0.05, 5);
  const BuildResult built = build_octree(volume.data(), dims, BuildOptions{});
  WriteOptions write;
  write.block_bytes = 256;
  write_octree(built.octree, Metadata{}, test::temp_path("octree-here.ivol"), write);
  write.encoder = std::make_shared<ReversingEncoder>(5);
  write_octree(built.octree, Metadata{}, test::temp_path("octree-elsewhere.ivol"), write);
  EXPECT_EQ(test::read_bytes(test::temp_path("octree-here.ivol")),
            test::read_bytes(test::temp_path("octree-elsewhere.ivol")));

  NeedMask mask;
  mask.dims = dims;
  mask.factor = 8;
  mask.cells = {4, 4, 3};
  mask.need.assign(4 * 4 * 3, 0);
  mask.need[5] = mask.need[22] = 1;
  for (StructureKind kind : {StructureKind::Nested, StructureKind::Rectilinear, StructureKind::Regular}) {
    GenerationOptions generation;
    generation.nested_cell = 8;
    std::unique_ptr<VoxelStructure> structure = generate_structure(kind, mask, generation);
    for (std::size_t v = 0; v < structure->values().size(); ++v) structure->values()[v] = volume[v % volume.size()];
    StreamingOptions options;
    options.write.block_bytes = 256;
    write_structure(*structure, test::temp_path("grid-here.ivol"), Metadata{}, options);
    auto encoder = std::make_shared<ReversingEncoder>(3);
    options.write.encoder = encoder;
    write_structure(*structure, test::temp_path("grid-elsewhere.ivol"), Metadata{}, options);
    EXPECT_EQ(test::read_bytes(test::temp_path("grid-here.ivol")),
              test::read_bytes(test::temp_path("grid-elsewhere.ivol")))
        << "kind " << static_cast<int>(kind);
    EXPECT_GT(encoder->blocks, 0u);
  }
}

TEST(BlockEncoder, FailureFailsTheWriteAndLeavesNothing) {
  const Dims dims{24, 24, 16};
  std::mt19937_64 rng(12);
  const std::vector<float> volume = test::random_volume(dims, rng, 0.05, 5);
  const std::string path = test::temp_path("failed.ivol");
  std::filesystem::remove(path);
  EXPECT_THROW(write_streamed(volume, dims, path, std::make_shared<ReversingEncoder>(4, true)), std::runtime_error);
  EXPECT_FALSE(std::filesystem::exists(path));
  for (const auto& entry : std::filesystem::directory_iterator(test::temp_dir()))
    EXPECT_EQ(entry.path().filename().string().find(".failed.ivol.tmp-"), std::string::npos) << entry.path();
}

}  // namespace
