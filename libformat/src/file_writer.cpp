#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zstd.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <memory>

#include "framing.hpp"
#include "ivol/crc32c.hpp"
#include "ivol/error.hpp"
#include "ivol/temporary_file.hpp"
#include "ivol/writer.hpp"
#include "layout.hpp"
#include "zstd_parts.hpp"

namespace ivol {
namespace {

[[noreturn]] void io_error(const std::string& path, const std::string& what) {
  throw Error(ErrorClass::Io, path + ": " + what + ": " + std::strerror(errno));
}

// 40 bytes (format 1.0 .. 1.2), or 80 with the volume descriptor (framed, 1.3).
std::vector<unsigned char> header_bytes(std::uint16_t minor, const VolumeLayout& volume, bool framed) {
  const std::uint32_t size = framed ? layout::kFramedHeaderSize : layout::kHeaderSize;
  std::vector<unsigned char> header(size, 0);
  std::memcpy(header.data(), layout::kSignature.data(), 8);
  layout::store<std::uint16_t>(header.data() + layout::kHeaderVersionMajor, layout::kVersionMajor);
  layout::store<std::uint16_t>(header.data() + layout::kHeaderVersionMinor, minor);
  layout::store<std::uint32_t>(header.data() + layout::kHeaderSizeField, size);
  if (framed) {
    layout::store<std::uint64_t>(header.data() + layout::kHeaderRequiredFeatures, layout::kFeatureFramedBlocks);
    const auto descriptor = detail::volume_descriptor(volume);
    std::memcpy(header.data() + layout::kHeaderDescriptor, descriptor.data(), descriptor.size());
  }
  layout::store<std::uint32_t>(header.data() + size - 4, crc32c(header.data(), size - 4));
  return header;
}

}  // namespace

EncodedBlock encode_block(Stream stream, unsigned level, std::uint64_t first_element, std::uint32_t element_count,
                          std::size_t width, const void* data, const WriteOptions& options) {
  EncodedBlock block;
  block.stream = stream;
  block.level = static_cast<std::uint8_t>(level);
  block.first_element = first_element;
  block.element_count = element_count;
  const std::size_t raw_size = std::size_t{element_count} * width;
  if (raw_size > layout::kMaxBlockDecodedBytes)
    throw Error(ErrorClass::InvalidArgument, "encode_block: a block may hold at most 64 MiB");
  // Elements wider than a byte: their bytes regrouped by position (spec §7,
  // codec 2), so that the slowly varying high bytes of values and node words
  // compress apart from the noisy low ones.
  const bool planes = options.compress && options.byte_planes && stream != Stream::Metadata && width > 1;
  // Kept per thread, grown only: every byte used is written first.
  thread_local std::vector<std::uint8_t> regrouped;
  if (planes) {
    if (regrouped.size() < raw_size) regrouped.resize(raw_size);
    const std::uint8_t* __restrict in = static_cast<const std::uint8_t*>(data);
    std::uint8_t* __restrict out = regrouped.data();
    const std::size_t n = element_count;
    // The usual widths with the width known to the compiler, which then
    // vectorises the loop (the generic one was 4 % of a conversion).
    if (width == 2) {
      for (std::size_t i = 0; i < n; ++i) out[i] = in[2 * i], out[n + i] = in[2 * i + 1];
    } else if (width == 4) {
      for (std::size_t i = 0; i < n; ++i)
        out[i] = in[4 * i], out[n + i] = in[4 * i + 1], out[2 * n + i] = in[4 * i + 2], out[3 * n + i] = in[4 * i + 3];
    } else {
      for (std::size_t i = 0; i < n; ++i)
        for (std::size_t p = 0; p < width; ++p) out[p * n + i] = in[i * width + p];
    }
  }
  if (options.compress) {
    const void* content = planes ? regrouped.data() : data;
    // One context per thread, reused: creating one costs more than a small block.
    thread_local std::unique_ptr<ZSTD_CCtx, decltype(&ZSTD_freeCCtx)> context(ZSTD_createCCtx(), ZSTD_freeCCtx);
    ZSTD_CCtx* cctx = context.get();
    if (!cctx) throw Error(ErrorClass::Io, "zstd: cannot create a compression context");
    ZSTD_CCtx_reset(cctx, ZSTD_reset_session_and_parameters);
    ZSTD_CCtx_setParameter(cctx, ZSTD_c_compressionLevel, options.zstd_level);
    ZSTD_CCtx_setParameter(cctx, ZSTD_c_checksumFlag, 1);
    ZSTD_CCtx_setParameter(cctx, ZSTD_c_contentSizeFlag, 1);
    std::size_t size;
    const bool plane_frames = planes && options.framed_blocks && options.zstd_level >= kPlaneFramesFromLevel &&
                              width <= 4 && element_count >= kPlaneFramesFromElements;
    if (plane_frames) {  // codec 5: a frame each, every plane starting afresh
      const std::uint8_t* r = regrouped.data();
      const std::size_t n = element_count;
      block.bytes.resize(width * ZSTD_compressBound(n));
      size = 0;
      for (std::size_t p = 0; p < width; ++p) {
        ZSTD_CCtx_reset(cctx, ZSTD_reset_session_only);
        const std::size_t frame =
            ZSTD_compress2(cctx, block.bytes.data() + size, block.bytes.size() - size, r + p * n, n);
        if (ZSTD_isError(frame))
          throw Error(ErrorClass::Io, std::string("zstd compression failed: ") + ZSTD_getErrorName(frame));
        size += frame;
      }
    } else if (planes && (width == 2 || width == 4)) {  // each plane ends a zstd block: entropy tables of its own
      const std::uint8_t* r = regrouped.data();
      const std::size_t n = element_count;
      size = width == 2
                 ? detail::compress_parts(cctx, {{r, n}, {r + n, n}}, block.bytes, 0)
                 : detail::compress_parts(cctx, {{r, n}, {r + n, n}, {r + 2 * n, n}, {r + 3 * n, n}}, block.bytes, 0);
    } else {
      block.bytes.resize(ZSTD_compressBound(raw_size));
      size = ZSTD_compress2(cctx, block.bytes.data(), block.bytes.size(), content, raw_size);
      if (ZSTD_isError(size))
        throw Error(ErrorClass::Io, std::string("zstd compression failed: ") + ZSTD_getErrorName(size));
    }
    if (size < raw_size) {
      block.bytes.resize(size);
      block.codec = plane_frames ? Codec::ZstdPlaneFrames : planes ? Codec::ZstdBytePlanes : Codec::Zstd;
    }
  }
  if (block.codec == Codec::Stored) {
    const auto* p = static_cast<const std::uint8_t*>(data);
    block.bytes.assign(p, p + raw_size);
  }
  block.crc = crc32c(block.bytes.data(), block.bytes.size());
  return block;
}

FileWriter::FileWriter(const std::string& path, const VolumeLayout& layout, bool framed)
    : path_(path), layout_(layout), framed_(framed) {
  remove_abandoned_temporaries(path);  // left by writers of this file that were killed
  fd_ = create_locked_temporary(path, temp_path_);

  // Unframed octree files stay version 1.0, so that 1.0 readers read them,
  // unless they use codec 2 (finish() then writes the header again).
  const std::uint16_t minor = framed_                                 ? layout::kVersionMinorFramed
                              : layout_.kind == StructureKind::Octree ? 0
                                                                      : layout::kVersionMinor;
  const auto header = header_bytes(minor, layout_, framed_);
  write_all(header.data(), header.size(), "header");
}

FileWriter::~FileWriter() {
  if (fd_ >= 0) ::close(fd_);
  if (!finished_ && !temp_path_.empty()) ::unlink(temp_path_.c_str());
}

void FileWriter::write_all(const void* data, std::size_t size, const char* what) {
  const auto* p = static_cast<const unsigned char*>(data);
  while (size > 0) {
    const ssize_t n = ::write(fd_, p, size);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) io_error(path_, std::string("cannot write the ") + what);
    p += n;
    size -= static_cast<std::size_t>(n);
    offset_ += static_cast<std::uint64_t>(n);
  }
#ifdef __linux__
  // Every 8 MiB, the kernel is asked to start writing them out (no wait):
  // finish()'s fsync then waits for the last few MiB only, not for the
  // whole file (it was a tenth of a 512³ conversion's wall time, the
  // cores idle). Advisory: the fsync reports any error.
  constexpr std::uint64_t kWritebackEvery = std::uint64_t{8} << 20;
  if (offset_ - writeback_from_ >= kWritebackEvery) {
    ::sync_file_range(fd_, static_cast<off_t>(writeback_from_), static_cast<off_t>(offset_ - writeback_from_),
                      SYNC_FILE_RANGE_WRITE);
    writeback_from_ = offset_;
  }
#endif
}

void FileWriter::append(const EncodedBlock& block) {
  if (finished_) throw Error(ErrorClass::InvalidArgument, path_ + ": append after finish");
  const std::uint64_t at = offset_;
  Entry entry{at,
              block.first_element,
              block.element_count,
              static_cast<std::uint32_t>(block.bytes.size()),
              block.crc,
              static_cast<std::uint8_t>(block.stream),
              static_cast<std::uint8_t>(block.codec),
              block.level,
              block.stream == Stream::StoredLevel || block.stream == Stream::EarlyMetadata ? layout::kFlagIgnorable
                                                                                           : std::uint8_t{0}};
  if (framed_) {
    // Framed here, not in encode_block, so that wherever a block was
    // compressed (another rank, block_encoder.hpp) the file is the same.
    if (block.bytes.size() > 0xFFFFFFFFu - layout::kBlockHeaderSize)
      throw Error(ErrorClass::InvalidArgument, path_ + ": a block too large to frame");
    BlockInfo info;
    info.stream = entry.stream;
    info.codec = entry.codec;
    info.level = entry.level;
    info.flags = entry.flags;
    info.first_element = entry.first_element;
    info.element_count = entry.element_count;
    const auto header = detail::block_header(info, entry.stored_size, block.crc);
    write_all(header.data(), header.size(), "block header");
    entry.stored_size += layout::kBlockHeaderSize;
    entry.crc = crc32c_extend(crc32c(header.data(), header.size()), block.bytes.data(), block.bytes.size());
  }
  write_all(block.bytes.data(), block.bytes.size(), "block");
  entries_.push_back(entry);
}

namespace {

// The metadata as its block holds it, within §11's limits.
std::string metadata_text(const Metadata& metadata, const std::string& path) {
  std::string json = metadata.to_json().dump();
  if (json.size() > layout::kMaxMetadataBytes)
    throw Error(ErrorClass::InvalidArgument, path + ": metadata exceeds 16 MiB");
  if (json_nesting_depth(json, kMaxMetadataDepth) > kMaxMetadataDepth)
    throw Error(ErrorClass::InvalidArgument, path + ": metadata nests arrays and objects deeper than " +
                                                 std::to_string(kMaxMetadataDepth) + " levels");
  return json;
}

}  // namespace

void FileWriter::write_metadata(const Metadata& metadata) {
  if (!metadata_json_.empty()) throw Error(ErrorClass::InvalidArgument, path_ + ": the metadata is written already");
  std::string json = metadata_text(metadata, path_);
  WriteOptions metadata_options;
  append(
      encode_block(Stream::Metadata, 0, 0, static_cast<std::uint32_t>(json.size()), 1, json.data(), metadata_options));
  metadata_json_ = std::move(json);
}

void FileWriter::write_early_metadata(const Metadata& metadata) {
  if (!framed_) return;  // salvage needs framed blocks (spec §18)
  if (!metadata_json_.empty())
    throw Error(ErrorClass::InvalidArgument, path_ + ": early metadata after the metadata itself");
  const std::string json = metadata_text(metadata, path_);
  WriteOptions metadata_options;
  append(encode_block(Stream::EarlyMetadata, 0, 0, static_cast<std::uint32_t>(json.size()), 1, json.data(),
                      metadata_options));
}

void FileWriter::finish(const Metadata& metadata, const std::vector<std::uint64_t>& inner_count) {
  if (inner_count.size() != layout_.depth + 1)
    throw Error(ErrorClass::InvalidArgument, path_ + ": the level table needs depth + 1 entries");
  if (metadata_json_.empty())
    write_metadata(metadata);
  else if (metadata.to_json().dump() != metadata_json_)
    throw Error(ErrorClass::InvalidArgument, path_ + ": finish() got other metadata than the file begins with");

  const std::uint64_t index_offset = offset_;
  const std::size_t level_bytes = 8 * inner_count.size();
  std::vector<unsigned char> index(layout::kIndexFixedSize + level_bytes + entries_.size() * layout::kBlockEntrySize);
  unsigned char* p = index.data();
  std::memcpy(p, layout::kIndexSignature.data(), 4);
  layout::store<std::uint32_t>(p + layout::kIndexFixedSizeField, layout::kIndexFixedSize);
  const auto descriptor = detail::volume_descriptor(layout_);  // the same bytes as in a framed header
  std::memcpy(p + layout::kIndexStructureKind, descriptor.data(), descriptor.size());
  layout::store<std::uint32_t>(p + layout::kIndexBlockCount, static_cast<std::uint32_t>(entries_.size()));
  layout::store<std::uint32_t>(p + layout::kIndexBlockEntrySize, layout::kBlockEntrySize);
  p += layout::kIndexFixedSize;
  for (std::uint64_t count : inner_count) layout::store<std::uint64_t>(p, count), p += 8;
  for (const Entry& e : entries_) {
    layout::store<std::uint64_t>(p + layout::kEntryFileOffset, e.file_offset);
    layout::store<std::uint64_t>(p + layout::kEntryFirstElement, e.first_element);
    layout::store<std::uint32_t>(p + layout::kEntryElementCount, e.element_count);
    layout::store<std::uint32_t>(p + layout::kEntryStoredSize, e.stored_size);
    layout::store<std::uint32_t>(p + layout::kEntryCrc, e.crc);
    p[layout::kEntryStream] = e.stream;
    p[layout::kEntryCodec] = e.codec;
    p[layout::kEntryFlags] = e.flags;
    p[layout::kEntryLevel] = e.level;
    p += layout::kBlockEntrySize;
  }
  write_all(index.data(), index.size(), "index");

  unsigned char footer[layout::kFooterSize] = {};
  layout::store<std::uint64_t>(footer + layout::kFooterIndexOffset, index_offset);
  layout::store<std::uint64_t>(footer + layout::kFooterIndexSize, index.size());
  layout::store<std::uint32_t>(footer + layout::kFooterIndexCrc, crc32c(index.data(), index.size()));
  layout::store<std::uint32_t>(footer + layout::kFooterCrc, crc32c(footer, layout::kFooterCrc));
  std::memcpy(footer + layout::kFooterEndSignature, layout::kEndSignature.data(), 8);
  write_all(footer, sizeof footer, "footer");

  // A block over byte planes (codec 2) needs a version 1.2 reader: say so.
  bool planes = false;
  for (const Entry& e : entries_) planes = planes || e.codec == static_cast<std::uint8_t>(Codec::ZstdBytePlanes);
  if (planes && !framed_) {
    const auto header = header_bytes(layout::kVersionMinorBytePlanes, layout_, false);
    if (::pwrite(fd_, header.data(), header.size(), 0) != static_cast<ssize_t>(header.size()))
      io_error(path_, "cannot write the header");
  }
  if (::fsync(fd_) != 0) io_error(path_, "cannot flush the file to disk");
  // Renamed while still open, so still locked: a cleaner never takes a
  // finished file for an abandoned one. Its bytes are on disk (fsync), so
  // closing can lose nothing.
  rename_into_place(temp_path_, path_);
  finished_ = true;
  ::close(fd_);
  fd_ = -1;
}

}  // namespace ivol
