// Entropy coder 2 of codec 3 (spec §7.2.1). The encoder runs the model
// forward, as the decoder will, noting each voxel's frequency and
// cumulative frequency, then codes the voxels backwards (rANS is last in,
// first out) so that the decoder reads the stream front to back.
#include "residual_tokens.hpp"

#include <algorithm>
#include <array>
#include <cstring>
#include <string>

#include "ivol/error.hpp"
#include "token_contexts.hpp"

namespace ivol::detail {
namespace {

constexpr unsigned kContexts = kTokenContexts;
constexpr unsigned kTokens = kTokenCount;
constexpr unsigned kPrecision = kTableBits;
constexpr std::uint32_t kTotal = kTableTotal;
constexpr std::uint32_t kStateLow = 1u << 23;  // a state lies in [2^23, 2^32) between symbols
constexpr std::uint32_t kCountStart = 1;       // every token's count before the brick
constexpr std::uint32_t kCountStep = 16;       // added to a token's count each time it occurs
constexpr std::uint32_t kRefreshEvery = 128;   // tables made again every 128 tokens of a context,
                                               // and sooner at its start (next_refresh)

[[noreturn]] void bad(const std::string& what) {
  throw Error(ErrorClass::Malformed, "codec 3, entropy coder 2: " + what);
}

// What a token says of its residual: its bit length, how many bits below
// its two leading bits follow in the stream (e = length − 2, at most 14),
// and the residual's leading bits, so that residual = lead << e | the e
// bits (tokens of length 2 or less are their residual: e = 0).
struct TokenBits {
  std::uint8_t length, below, lead;
};
constexpr std::array<TokenBits, kTokens> kTokenBits = [] {
  std::array<TokenBits, kTokens> bits{};
  for (unsigned t = 0; t < kTokens; ++t) {
    const unsigned b = token_bit_length(t);
    bits[t] = {static_cast<std::uint8_t>(b), static_cast<std::uint8_t>(b > 2 ? b - 2 : 0),
               static_cast<std::uint8_t>(b > 2 ? 2 + (t & 1) : t)};
  }
  return bits;
}();
// The same for the decoder, in one word that stays in a register: length
// in bits 0–7, e in bits 8–15, lead << e in bits 16–31.
constexpr std::array<std::uint32_t, kTokens> kTokenWord = [] {
  std::array<std::uint32_t, kTokens> words{};
  for (unsigned t = 0; t < kTokens; ++t) {
    const TokenBits b = kTokenBits[t];
    words[t] = b.length | std::uint32_t{b.below} << 8 | (std::uint32_t{b.lead} << b.below) << 16;
  }
  return words;
}();

// After the m-th token of a context its table is made again when m is a
// power of two from 4 on or a multiple of 128: quickly while the counts say
// little, then at a fixed pace. The next such m after `seen`.
std::uint32_t next_refresh(std::uint32_t seen) {
  return seen < 4 ? 4 : seen < kRefreshEvery ? 2 * seen : seen + kRefreshEvery;
}

// One context's adaptive counts and the table made from them. Their sum is
// not kept: it follows from how many tokens the context has seen.
struct ContextModel {
  std::array<std::uint32_t, kTokens> count;
  std::array<std::uint16_t, kTokens> freq;
  std::array<std::uint16_t, kTokens + 1> start;  // cumulative frequencies
  std::uint32_t seen = 0;
  std::uint32_t refresh_at = next_refresh(0);

  ContextModel() {
    count.fill(kCountStart);
    make_table();
  }

  // freq[t] = max(1, floor(count[t]·R / 2^32)) with R = floor(2^44 / total)
  // (one division a table); what that leaves over or takes beyond 2^12 goes
  // to the largest freq (the lowest token on a tie).
  void make_table() {
    const std::uint64_t total = std::uint64_t{kCountStart} * kTokens + std::uint64_t{kCountStep} * seen;
    const std::uint64_t scale = (std::uint64_t{1} << 44) / total;
    std::uint32_t sum = 0, largest_freq = 0;
    unsigned largest = 0;
    for (unsigned t = 0; t < kTokens; ++t) {
      const std::uint64_t scaled = (count[t] * scale) >> 32;
      const auto f = static_cast<std::uint32_t>(scaled == 0 ? 1 : scaled);
      freq[t] = static_cast<std::uint16_t>(f);
      sum += f;
      // The largest so far in a register, not read back from freq[]: the
      // comparisons then chain through no load.
      if (f > largest_freq) largest = t, largest_freq = f;
    }
    freq[largest] = static_cast<std::uint16_t>(largest_freq + kTotal - sum);
    start[0] = 0;
    for (unsigned t = 0; t < kTokens; ++t) start[t + 1] = static_cast<std::uint16_t>(start[t] + freq[t]);
  }

  // Counts token t; true when the table was made again.
  bool note(unsigned t) {
    count[t] += kCountStep;
    if (++seen != refresh_at) return false;
    refresh_at = next_refresh(seen);
    make_table();
    return true;
  }
};

// A decoder's model: the same, and which token each of the 2^12 slots is.
struct DecoderModel : ContextModel {
  std::array<std::uint8_t, kTotal> token_at;
  std::array<std::uint16_t, kTokens + 1> filled;  // the starts token_at holds
  DecoderModel() {
    for (unsigned t = 0; t < kTokens; ++t) std::memset(token_at.data() + start[t], static_cast<int>(t), freq[t]);
    filled = start;
  }
  // The table is made again every 128 tokens of a context, and by then its
  // starts have mostly moved by a few slots: only the slots whose token
  // changed are written, those of each token's new range outside its old
  // one. (Writing all 4096, with 32 calls of memset, took a sixth of the
  // decoder's time.)
  void fill() {
    for (unsigned t = 0; t < kTokens; ++t) {
      const unsigned from = start[t], to = start[t + 1], old_from = filled[t], old_to = filled[t + 1];
      const auto token = static_cast<std::uint8_t>(t);
      for (unsigned s = from; s < std::min(to, old_from); ++s) token_at[s] = token;
      for (unsigned s = std::max(from, old_to); s < to; ++s) token_at[s] = token;
    }
    filled = start;
  }
};

std::uint32_t read_u32(const std::uint8_t* p) {
  return std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 | std::uint32_t{p[3]} << 24;
}

// A little-endian 64-bit word as loaded by memcpy, in the host's order.
std::uint64_t le64(std::uint64_t v) {
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
  return __builtin_bswap64(v);
#else
  return v;
#endif
}

void put_u32(std::uint8_t* p, std::uint32_t v) {
  for (int k = 0; k < 4; ++k) p[k] = static_cast<std::uint8_t>(v >> (8 * k));
}

}  // namespace

bool encode_residual_tokens(const std::uint16_t* residuals, const BrickDims& dims, std::size_t limit,
                            std::vector<std::uint8_t>& out) {
  const std::size_t n = std::size_t{dims[0]} * dims[1] * dims[2];
  std::array<ContextModel, kContexts> models;
  // Kept per thread: every element is written before it is read, and a
  // brick's buffers, made anew and zeroed for every brick, cost more than
  // the work on small ones.
  thread_local std::vector<std::uint8_t> tokens, lengths, below, stream;
  thread_local std::vector<std::uint32_t> coded;  // freq << 16 | start, per voxel
  tokens.resize(n);
  lengths.resize(n);
  coded.resize(n);
  tokens_of(residuals, n, tokens.data(), lengths.data());
  // The lengths are all known: the walk only reads them.
  walk_rows(dims, lengths.data(), [&](std::size_t row, const std::uint8_t* contexts, std::uint8_t*) {
    for (std::uint32_t x = 0; x < dims[0]; ++x) {
      const unsigned t = tokens[row + x];
      ContextModel& m = models[contexts[x]];
      coded[row + x] = std::uint32_t{m.freq[t]} << 16 | m.start[t];
      m.note(t);
    }
  });
  // The bits below the tokens, LSB first (at most 14 a voxel).
  below.resize(static_cast<std::size_t>((count_bits_below(tokens.data(), n) + 7) / 8) + 8);
  const std::size_t below_size =
      static_cast<std::size_t>(put_bits_below(tokens.data(), residuals, n, below.data()) - below.data());

  // rANS, two states taking the voxels in turn, written from the back.
  const std::size_t room = 8 + 2 * n;
  if (4 + 8 + below_size > limit) return false;
  stream.resize(room);
  std::uint8_t* const begin = stream.data();
  std::uint8_t* p = begin + room;
  // One voxel's step on state x: its 0–2 bytes out, then the token in.
  bool room_left = true;
  auto step = [&](std::uint32_t& x, std::uint32_t code) {
    const std::uint32_t f = code >> 16, s = code & 0xFFFF;
    const std::uint32_t x_max = ((kStateLow >> kPrecision) << 8) * f;
    // At most two bytes: a state is below 2^31 and x_max at least 2^19.
    if (p - begin >= 8 + 2) {
      // Without branches, whose outcome the data decides: the byte below p
      // is written either way and kept only when p moves over it.
      const std::uint32_t first = x >= x_max;
      p[-1] = static_cast<std::uint8_t>(x);
      p -= first;
      x >>= 8 * first;
      const std::uint32_t second = x >= x_max;
      p[-1] = static_cast<std::uint8_t>(x);
      p -= second;
      x >>= 8 * second;
    } else {
      while (x >= x_max) {
        if (p == begin + 8) {  // larger than the residuals' two bytes a voxel
          room_left = false;
          return;
        }
        *--p = static_cast<std::uint8_t>(x);
        x >>= 8;
      }
    }
    const std::uint32_t q = divide_by_frequency(x, f);
    x = (q << kPrecision) + (x - q * f) + s;
  };
  // Voxel i on state i mod 2, from the last; the two states as locals, not
  // an array indexed by i (whose loads and stores chained each step to the
  // one before: 10-15 % of the encoding time).
  std::uint32_t x0 = kStateLow, x1 = kStateLow;
  std::size_t i = n;
  if (i & 1) step(x0, coded[--i]);
  for (; i > 0 && room_left; i -= 2) {
    step(x1, coded[i - 1]);
    step(x0, coded[i - 2]);
  }
  if (!room_left) return false;
  p -= 8;
  put_u32(p, x0);
  put_u32(p + 4, x1);
  const std::size_t rans_size = static_cast<std::size_t>(begin + room - p);
  if (4 + rans_size + below_size > limit) return false;
  const std::size_t at = out.size();
  out.resize(at + 4 + rans_size + below_size);
  put_u32(out.data() + at, static_cast<std::uint32_t>(rans_size));
  std::memcpy(out.data() + at + 4, p, rans_size);
  if (below_size) std::memcpy(out.data() + at + 4 + rans_size, below.data(), below_size);
  return true;
}

void decode_residual_tokens(const std::uint8_t* data, std::size_t size, const BrickDims& dims,
                            std::uint16_t* residuals) {
  const std::size_t n = std::size_t{dims[0]} * dims[1] * dims[2];
  if (size < 4) bad("the " + std::to_string(size) + " bytes after the codec header hold no stream length");
  const std::uint32_t rans_size = read_u32(data);
  if (rans_size < 8 || rans_size > size - 4)
    bad("the rANS stream's length " + std::to_string(rans_size) + " is not within 8 .. " + std::to_string(size - 4));
  const std::uint8_t* p = data + 4;
  const std::uint8_t* const end = p + rans_size;
  std::uint32_t current = read_u32(p), other = read_u32(p + 4);
  p += 8;
  // An encoder's states stay below 2^31 (its renormalisation keeps them
  // under 2^19·f before a step of at most ·2^12 / f): one coding per brick.
  // A decoder's do too, whatever the bytes: from X < 2^31 a step leaves
  // f·floor(X / 2^12) + (slot − s) < 2^31, and renormalising shifts in
  // bytes only while X < 2^23.
  for (std::uint32_t x : {current, other})
    if (x < kStateLow || x >= (1u << 31))
      bad("an initial rANS state " + std::to_string(x) + " is not in 2^23 .. 2^31 - 1");

  // The bits below the tokens follow the rANS stream, LSB first: `pending`
  // holds the next `pending_bits` of them, q the first byte not yet in it.
  // The two states take the voxels in turn: `current` decodes, then the
  // two swap.
  const std::uint8_t* q = end;
  const std::uint8_t* const q_end = data + size;
  std::uint64_t pending = 0;
  unsigned pending_bits = 0;
  std::vector<DecoderModel> models(kContexts);
  thread_local std::vector<std::uint8_t> lengths;  // each written before it is read
  lengths.resize(n);
  walk_rows(dims, lengths.data(), [&](std::size_t row, const std::uint8_t* contexts, std::uint8_t* row_lengths) {
    // Locals, so that the loops keep them in registers.
    std::uint32_t x_now = current, x_next = other;
    const std::uint8_t* in = p;
    const std::uint8_t* bits_in = q;
    std::uint64_t bits = pending;
    unsigned bit_count = pending_bits;
    std::uint16_t* const out = residuals + row;
    const std::uint32_t nx = dims[0];
    // Voxel x's token, its state's step, and what the token says
    // (kTokenWord); the caller renormalises the state and supplies the bits
    // below.
    auto token = [&](std::uint32_t x) {
      DecoderModel& m = models[contexts[x]];
      const std::uint32_t slot = x_now & (kTotal - 1);
      const unsigned t = m.token_at[slot];
      x_now = m.freq[t] * (x_now >> kPrecision) + slot - m.start[t];
      if (m.note(t)) m.fill();
      const std::uint32_t word = kTokenWord[t];
      row_lengths[x] = static_cast<std::uint8_t>(word);
      return word;
    };
    auto below = [](std::uint32_t word) { return (word >> 8) & 0xFF; };
    auto take_bits = [&](std::uint32_t x, std::uint32_t word) {
      const unsigned e = below(word);
      out[x] = static_cast<std::uint16_t>((word >> 16) | static_cast<unsigned>(bits & ((1u << e) - 1)));
      bits >>= e;
      bit_count -= e;
    };
    // A voxel takes at most two bytes of the rANS stream (a step leaves X ≥
    // 2^11) and 14 bits below its token. Where the row's share of both
    // surely remains, the loop reads without bounds checks: the bits are
    // topped up to 56 or more every four voxels, without branches, and each
    // state takes its 0–2 bytes at once, their number from two compares. The
    // branches left are the model's refreshes and the loops'.
    if (static_cast<std::size_t>(end - in) >= 2 * std::size_t{nx} + 2 &&
        static_cast<std::size_t>(q_end - bits_in) >= 2 * std::size_t{nx} + 16) {
      for (std::uint32_t x = 0; x < nx; x += 4) {
        // Bits above bit_count may come in too: they are the bytes after
        // the ones counted, in their places, and a later refill ORs the same
        // bits over them.
        std::uint64_t word;
        std::memcpy(&word, bits_in, 8);
        bits |= le64(word) << bit_count;
        bits_in += (63 - bit_count) >> 3;
        bit_count |= 56;
        const std::uint32_t stop = nx - x < 4 ? nx : x + 4;
        for (std::uint32_t v = x; v < stop; ++v) {
          const std::uint32_t word = token(v);
          // Two compares rather than a count of leading zeros: a shorter
          // chain from one state to its next.
          const unsigned k = static_cast<unsigned>(x_now < kStateLow) + static_cast<unsigned>(x_now < (kStateLow >> 8));
          const std::uint32_t next = std::uint32_t{in[0]} << 8 | in[1];
          x_now = x_now << (8 * k) | next >> (16 - 8 * k);
          in += k;
          std::swap(x_now, x_next);
          take_bits(v, word);
        }
      }
    } else {
      for (std::uint32_t x = 0; x < nx; ++x) {
        const std::uint32_t word = token(x);
        while (x_now < kStateLow) {
          if (in == end) bad("the rANS stream ends before the brick's last voxel");
          x_now = x_now << 8 | *in++;
        }
        std::swap(x_now, x_next);
        for (; bit_count <= 56 && bits_in != q_end; bit_count += 8) bits |= std::uint64_t{*bits_in++} << bit_count;
        if (bit_count < below(word)) bad("the bits below the tokens end before the brick's last voxel");
        take_bits(x, word);
      }
    }
    current = x_now, other = x_next;
    p = in, q = bits_in, pending = bits, pending_bits = bit_count;
  });
  if (p != end) bad(std::to_string(end - p) + " bytes of the rANS stream are left after the brick's last voxel");
  if (current != kStateLow || other != kStateLow) bad("the rANS states do not end at 2^23");
  const std::size_t left = static_cast<std::size_t>(q_end - q) + pending_bits / 8;
  if (left != 0) bad(std::to_string(left) + " bytes are left after the bits below the brick's last token");
  if (pending != 0) bad("the padding bits after the last residual's bits are not 0");
}

}  // namespace ivol::detail
