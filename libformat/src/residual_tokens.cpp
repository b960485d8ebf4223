// Entropy coder 2 of codec 3 (spec §7.2.1). The encoder runs the model
// forward, as the decoder will, noting each voxel's frequency and
// cumulative frequency, then codes the voxels backwards (rANS is last in,
// first out) so that the decoder reads the stream front to back.
#include "residual_tokens.hpp"

#include <array>
#include <cstring>
#include <string>

#include "ivol/error.hpp"

namespace ivol::detail {
namespace {

constexpr unsigned kContexts = 12;
constexpr int kTokens = 32;
constexpr unsigned kPrecision = 12;  // every table sums to 2^12
constexpr std::uint32_t kTotal = 1u << kPrecision;
constexpr std::uint32_t kStateLow = 1u << 23;  // a state lies in [2^23, 2^32) between symbols
constexpr std::uint32_t kCountStart = 1;       // every token's count before the brick
constexpr std::uint32_t kCountStep = 16;       // added to a token's count each time it occurs
constexpr std::uint32_t kRefreshEvery = 128;   // tables made again every 128 tokens of a context,
                                               // and sooner at its start (next_refresh)

[[noreturn]] void bad(const std::string& what) {
  throw Error(ErrorClass::Malformed, "codec 3, entropy coder 2: " + what);
}

unsigned bit_length(unsigned v) { return v == 0 ? 0 : 32 - static_cast<unsigned>(__builtin_clz(v)); }

// A residual's token: 0 and 1 themselves, else 2b − 2 plus the bit after the
// leading one (b its bit length), 2 .. 31.
unsigned token_of(unsigned z) {
  if (z < 2) return z;
  const unsigned b = bit_length(z);
  return 2 * b - 2 + ((z >> (b - 2)) & 1);
}

// The bit length of the residuals a token stands for.
constexpr unsigned token_bit_length(unsigned t) { return t < 2 ? t : (t >> 1) + 1; }
constexpr std::array<std::uint8_t, kTokens> kBitLength = [] {
  std::array<std::uint8_t, kTokens> b{};
  for (unsigned t = 0; t < kTokens; ++t) b[t] = static_cast<std::uint8_t>(token_bit_length(t));
  return b;
}();

// After the m-th token of a context its table is made again when m is a
// power of two from 4 on or a multiple of 128: quickly while the counts say
// little, then at a fixed pace. The next such m after `seen`.
std::uint32_t next_refresh(std::uint32_t seen) {
  return seen < 4 ? 4 : seen < kRefreshEvery ? 2 * seen : seen + kRefreshEvery;
}

// One context's adaptive counts and the table made from them.
struct ContextModel {
  std::array<std::uint32_t, kTokens> count;
  std::array<std::uint16_t, kTokens> freq;
  std::array<std::uint16_t, kTokens + 1> start;  // cumulative frequencies
  std::uint64_t total = 0;
  std::uint32_t seen = 0;
  std::uint32_t refresh_at = next_refresh(0);

  ContextModel() {
    count.fill(kCountStart);
    total = std::uint64_t{kCountStart} * kTokens;
    make_table();
  }

  // freq[t] = max(1, floor(count[t]·R / 2^32)) with R = floor(2^44 / total)
  // (one division a table); what that leaves over or takes beyond 2^12 goes
  // to the largest freq (the lowest token on a tie).
  void make_table() {
    const std::uint64_t scale = (std::uint64_t{1} << 44) / total;
    std::uint32_t sum = 0;
    unsigned largest = 0;
    for (unsigned t = 0; t < kTokens; ++t) {
      const std::uint64_t f = (count[t] * scale) >> 32;
      freq[t] = static_cast<std::uint16_t>(f == 0 ? 1 : f);
      sum += freq[t];
      if (freq[t] > freq[largest]) largest = t;
    }
    freq[largest] = static_cast<std::uint16_t>(freq[largest] + kTotal - sum);
    start[0] = 0;
    for (unsigned t = 0; t < kTokens; ++t) start[t + 1] = static_cast<std::uint16_t>(start[t] + freq[t]);
  }

  // Counts token t; true when the table was made again.
  bool note(unsigned t) {
    count[t] += kCountStep;
    total += kCountStep;
    if (++seen != refresh_at) return false;
    refresh_at = next_refresh(seen);
    make_table();
    return true;
  }
};

// A decoder's model: the same, and which token each of the 2^12 slots is.
struct DecoderModel : ContextModel {
  std::array<std::uint8_t, kTotal> token_at;
  DecoderModel() { fill(); }
  void fill() {
    for (unsigned t = 0; t < kTokens; ++t) std::memset(token_at.data() + start[t], static_cast<int>(t), freq[t]);
  }
};

std::uint32_t read_u32(const std::uint8_t* p) {
  return std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 | std::uint32_t{p[3]} << 24;
}

void put_u32(std::uint8_t* p, std::uint32_t v) {
  for (int k = 0; k < 4; ++k) p[k] = static_cast<std::uint8_t>(v >> (8 * k));
}

// The contexts of a row of voxels from the bit lengths of the tokens in the
// row before it along y (`up`) and along z (`back`), 0 outside the brick:
// s = 2·up(x) + back(x) + up(x − 1) + up(x + 1), context min(11, (s + 2) / 5).
// Only earlier rows count, not the voxel before along x: the contexts of a
// whole row are known before its first token is decoded, so the decoder's
// loop carries only the rANS states from voxel to voxel (and these contexts
// compressed better than ones with the x neighbour, bench/RESULTS.md).
void row_contexts(const std::uint8_t* up, const std::uint8_t* back, std::uint32_t nx, std::uint8_t* contexts) {
  for (std::uint32_t x = 0; x < nx; ++x) {
    const unsigned left = x ? up[x - 1] : 0, right = x + 1 < nx ? up[x + 1] : 0;
    const unsigned c = (2 * up[x] + back[x] + left + right + 2) / 5;
    contexts[x] = static_cast<std::uint8_t>(c < kContexts - 1 ? c : kContexts - 1);
  }
}

// Visits a brick's rows in raster order with each row's contexts:
// visit(i, contexts, lengths + i) for the row starting at voxel i, which
// sets the bit lengths of its tokens.
template <class Visit>
void walk_rows(const BrickDims& d, std::uint8_t* lengths, Visit&& visit) {
  const std::size_t sy = d[0], sz = std::size_t{d[0]} * d[1];
  std::vector<std::uint8_t> zeros(d[0]), contexts(d[0]);
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y, i += d[0]) {
      row_contexts(y ? lengths + i - sy : zeros.data(), z ? lengths + i - sz : zeros.data(), d[0], contexts.data());
      visit(i, contexts.data(), lengths + i);
    }
}

}  // namespace

bool encode_residual_tokens(const std::uint16_t* residuals, const BrickDims& dims, std::size_t limit,
                            std::vector<std::uint8_t>& out) {
  const std::size_t n = std::size_t{dims[0]} * dims[1] * dims[2];
  std::array<ContextModel, kContexts> models;
  std::vector<std::uint8_t> lengths(n);
  std::vector<std::uint32_t> coded(n);  // freq << 16 | start, per voxel
  std::vector<std::uint8_t> below;      // the bits below the tokens, LSB first
  below.reserve(n);
  std::uint64_t pending = 0;
  unsigned pending_bits = 0;
  walk_rows(dims, lengths.data(), [&](std::size_t row, const std::uint8_t* contexts, std::uint8_t* row_lengths) {
    for (std::uint32_t x = 0; x < dims[0]; ++x) {
      const unsigned z = residuals[row + x], t = token_of(z), b = kBitLength[t];
      ContextModel& m = models[contexts[x]];
      coded[row + x] = std::uint32_t{m.freq[t]} << 16 | m.start[t];
      m.note(t);
      row_lengths[x] = static_cast<std::uint8_t>(b);
      if (b > 2) {
        pending |= std::uint64_t{z & ((1u << (b - 2)) - 1)} << pending_bits;
        for (pending_bits += b - 2; pending_bits >= 8; pending_bits -= 8, pending >>= 8)
          below.push_back(static_cast<std::uint8_t>(pending));
      }
    }
  });
  if (pending_bits) below.push_back(static_cast<std::uint8_t>(pending));

  // rANS, two states taking the voxels in turn, written from the back.
  const std::size_t room = 8 + 2 * n;
  if (4 + 8 + below.size() > limit) return false;
  std::vector<std::uint8_t> stream(room);
  std::uint8_t* const begin = stream.data();
  std::uint8_t* p = begin + room;
  std::array<std::uint32_t, 2> state{kStateLow, kStateLow};
  for (std::size_t i = n; i-- > 0;) {
    std::uint32_t& x = state[i & 1];
    const std::uint32_t f = coded[i] >> 16, s = coded[i] & 0xFFFF;
    const std::uint32_t x_max = ((kStateLow >> kPrecision) << 8) * f;
    while (x >= x_max) {
      if (p == begin + 8) return false;  // larger than the residuals' two bytes a voxel
      *--p = static_cast<std::uint8_t>(x);
      x >>= 8;
    }
    x = ((x / f) << kPrecision) + x % f + s;
  }
  p -= 8;
  put_u32(p, state[0]);
  put_u32(p + 4, state[1]);
  const std::size_t rans_size = static_cast<std::size_t>(begin + room - p);
  if (4 + rans_size + below.size() > limit) return false;
  const std::size_t at = out.size();
  out.resize(at + 4 + rans_size + below.size());
  put_u32(out.data() + at, static_cast<std::uint32_t>(rans_size));
  std::memcpy(out.data() + at + 4, p, rans_size);
  if (!below.empty()) std::memcpy(out.data() + at + 4 + rans_size, below.data(), below.size());
  return true;
}

void decode_residual_tokens(const std::uint8_t* data, std::size_t size, const BrickDims& dims, std::uint8_t* planes) {
  const std::size_t n = std::size_t{dims[0]} * dims[1] * dims[2];
  if (size < 4) bad("the " + std::to_string(size) + " bytes after the codec header hold no stream length");
  const std::uint32_t rans_size = read_u32(data);
  if (rans_size < 8 || rans_size > size - 4)
    bad("the rANS stream's length " + std::to_string(rans_size) + " is not within 8 .. " + std::to_string(size - 4));
  const std::uint8_t* p = data + 4;
  const std::uint8_t* const end = p + rans_size;
  std::array<std::uint32_t, 2> state{read_u32(p), read_u32(p + 4)};
  p += 8;
  // An encoder's states stay below 2^31 (its renormalisation keeps them
  // under 2^19·f before a step of at most ·2^12 / f): one coding per brick.
  for (std::uint32_t x : state)
    if (x < kStateLow || x >= (1u << 31))
      bad("an initial rANS state " + std::to_string(x) + " is not in 2^23 .. 2^31 - 1");

  // The bits below the tokens follow the rANS stream, LSB first. The two
  // states take the voxels in turn: `current` decodes, then the two swap.
  const std::uint8_t* q = end;
  const std::uint8_t* const q_end = data + size;
  std::uint64_t pending = 0;
  unsigned pending_bits = 0;
  std::vector<DecoderModel> models(kContexts);
  std::vector<std::uint8_t> lengths(n);
  std::uint32_t current = state[0], other = state[1];
  walk_rows(dims, lengths.data(), [&](std::size_t row, const std::uint8_t* contexts, std::uint8_t* row_lengths) {
    for (std::uint32_t x = 0; x < dims[0]; ++x) {
      DecoderModel& m = models[contexts[x]];
      const std::uint32_t slot = current & (kTotal - 1);
      const unsigned t = m.token_at[slot];
      current = m.freq[t] * (current >> kPrecision) + slot - m.start[t];
      while (current < kStateLow) {
        if (p == end) bad("the rANS stream ends before the brick's last voxel");
        current = current << 8 | *p++;
      }
      std::swap(current, other);
      if (m.note(t)) m.fill();
      const unsigned b = kBitLength[t];
      row_lengths[x] = static_cast<std::uint8_t>(b);
      unsigned r = t;  // a token of bit length 2 or less is its residual
      if (b > 2) {
        const unsigned e = b - 2;
        while (pending_bits < e) {
          if (q == q_end) bad("the bits below the tokens end before the brick's last voxel");
          pending |= std::uint64_t{*q++} << pending_bits;
          pending_bits += 8;
        }
        r = (2 + (t & 1)) << e | static_cast<unsigned>(pending & ((1u << e) - 1));
        pending >>= e;
        pending_bits -= e;
      }
      planes[row + x] = static_cast<std::uint8_t>(r);
      planes[n + row + x] = static_cast<std::uint8_t>(r >> 8);
    }
  });
  if (p != end) bad(std::to_string(end - p) + " bytes of the rANS stream are left after the brick's last voxel");
  if (current != kStateLow || other != kStateLow) bad("the rANS states do not end at 2^23");
  if (q != q_end) bad(std::to_string(q_end - q) + " bytes are left after the bits below the brick's last token");
  if (pending != 0) bad("the padding bits after the last residual's bits are not 0");
}

}  // namespace ivol::detail
