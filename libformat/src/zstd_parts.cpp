#include "zstd_parts.hpp"

#include <memory>
#include <string>

#include "ivol/error.hpp"

namespace ivol::detail {
namespace {

void check(std::size_t code) {
  if (ZSTD_isError(code))
    throw Error(ErrorClass::Io, std::string("zstd compression failed: ") + ZSTD_getErrorName(code));
}

}  // namespace

std::uint8_t* frame_scratch(std::size_t size) {
  thread_local std::unique_ptr<std::uint8_t[]> buffer;
  thread_local std::size_t capacity = 0;
  if (capacity < size) {
    buffer.reset();
    buffer.reset(new std::uint8_t[size]);  // not zero-filled: zstd writes what is read back
    capacity = size;
  }
  return buffer.get();
}

std::size_t compress_parts(ZSTD_CCtx* cctx, std::initializer_list<ZstdPart> parts, std::vector<std::uint8_t>& out,
                           std::size_t offset) {
  std::size_t total = 0;
  for (const ZstdPart& p : parts) total += p.size;
  const std::size_t bound = ZSTD_compressBound(total);
  // Room for a block header per flush beyond the bound, so that the
  // flushed frame never runs out of room before it can be compared.
  const std::size_t room = bound + 8 * parts.size() + 64;
  std::uint8_t* const frame = frame_scratch(room);
  check(ZSTD_CCtx_setPledgedSrcSize(cctx, total));
  ZSTD_outBuffer dst{frame, room, 0};
  std::size_t left = parts.size();
  for (const ZstdPart& p : parts) {
    const ZSTD_EndDirective mode = --left == 0 ? ZSTD_e_end : ZSTD_e_flush;
    if (p.size == 0 && mode == ZSTD_e_flush) continue;
    ZSTD_inBuffer src{p.data, p.size, 0};
    std::size_t remaining;
    do {
      remaining = ZSTD_compressStream2(cctx, &dst, &src, mode);
      check(remaining);
      if (remaining != 0 && dst.pos == dst.size) throw Error(ErrorClass::Io, "zstd: the frame outgrew its buffer");
    } while (remaining != 0 || src.pos < src.size);
  }
  std::size_t size = dst.pos;
  if (size > bound) {
    // The flushes' block headers took it past the bound: one run instead.
    std::vector<std::uint8_t> whole;
    whole.reserve(total);
    for (const ZstdPart& p : parts) whole.insert(whole.end(), p.data, p.data + p.size);
    ZSTD_CCtx_reset(cctx, ZSTD_reset_session_only);
    size = ZSTD_compress2(cctx, frame, bound, whole.data(), whole.size());
    check(size);
  }
  out.resize(offset);
  out.insert(out.end(), frame, frame + size);
  return size;
}

ZSTD_DCtx* thread_decompression_context() {
  thread_local std::unique_ptr<ZSTD_DCtx, decltype(&ZSTD_freeDCtx)> context(nullptr, ZSTD_freeDCtx);
  if (!context) context.reset(ZSTD_createDCtx());  // again, where an earlier try failed
  if (!context) throw Error(ErrorClass::LimitExceeded, "zstd cannot allocate a decompression context: out of memory");
  return context.get();
}

}  // namespace ivol::detail
