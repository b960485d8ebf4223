// One zstd frame of several parts (byte planes, a mask and byte planes),
// each part ending a zstd block, so that each gets entropy tables of its
// own: the noisy low bytes of CT values then no longer share a Huffman
// table with the slowly varying high bytes. The frame is an ordinary frame
// (Frame_Content_Size, one frame, no dictionary): readers see no difference.
// Measured (bench/RESULTS.md, issue 22): 5-8 % smaller blocks at zstd 3.
#pragma once

#include <zstd.h>

#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <vector>

namespace ivol::detail {

struct ZstdPart {
  const std::uint8_t* data;
  std::size_t size;
};

// Compresses the parts, in order, as one frame into `out` from `offset` on
// (resized to fit), with `cctx`'s parameters (the caller sets level,
// checksum and content size); returns the frame's size. Never larger than
// ZSTD_compressBound of the whole: where the flushes would make it so, the
// parts are compressed as one run instead. The frame is made in the
// thread's frame_scratch and `out` grows by its size only: zero-filling
// `out` at the bound first, and the page faults of that fresh memory, were
// a twentieth of a binary16 conversion's time.
std::size_t compress_parts(ZSTD_CCtx* cctx, std::initializer_list<ZstdPart> parts, std::vector<std::uint8_t>& out,
                           std::size_t offset);

// A buffer of at least `size` bytes, the calling thread's, kept for its
// next call (grown where too small, never zero-filled): for output whose
// size is known only once made.
std::uint8_t* frame_scratch(std::size_t size);

// The calling thread's zstd decompression context, made on first use and
// kept; throws Error(LimitExceeded) where zstd cannot allocate one (under an
// address-space cap), rather than hand zstd a null context, which crashed.
ZSTD_DCtx* thread_decompression_context();

}  // namespace ivol::detail
