// Entropy coder 3 of codec 3 (spec §7.2.2). The encoder counts each
// context's tokens, stores the frequencies it chose, then codes the voxels
// from the last (rANS is last in, first out) so that the decoder reads the
// words front to back; the decoder takes the tokens row by row (in vector
// registers where it can, residual_lanes_avx2.cpp) and the bits below
// them once all are known.
#include "residual_lanes.hpp"

#include <algorithm>
#include <cstring>
#include <string>

#include "ivol/error.hpp"

namespace ivol::detail {
namespace {

constexpr unsigned kContexts = kTokenContexts;
constexpr unsigned kTokens = kTokenCount;
constexpr unsigned kLanes = kLaneCount;
constexpr std::uint32_t kStateLow = kLaneStateLow;
constexpr unsigned kFixedHeader = 4 * kLanes + 4;  // the states and W

[[noreturn]] void bad(const std::string& what) {
  throw Error(ErrorClass::Malformed, "codec 3, entropy coder 3: " + what);
}

std::uint32_t read_u32(const std::uint8_t* p) {
  return std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 | std::uint32_t{p[3]} << 24;
}

void put_u32(std::uint8_t* p, std::uint32_t v) {
  for (int k = 0; k < 4; ++k) p[k] = static_cast<std::uint8_t>(v >> (8 * k));
}

// Each context's frequencies f_t and cumulative frequencies s_t.
struct Tables {
  std::array<std::array<std::uint16_t, kTokens>, kContexts> freq{}, start{};
  void make_starts() {
    for (unsigned k = 0; k < kContexts; ++k)
      for (unsigned t = 0, s = 0; t < kTokens; s += freq[k][t], ++t) start[k][t] = static_cast<std::uint16_t>(s);
  }
};

// Bits LSB first (§7.2.2's tables, §7.2.1's bits below).
class BitWriter {
 public:
  explicit BitWriter(std::vector<std::uint8_t>& out) : out_(out) {}
  void put(std::uint32_t value, unsigned count) {  // count ≤ 32
    pending_ |= std::uint64_t{value} << pending_bits_;
    for (pending_bits_ += count; pending_bits_ >= 8; pending_bits_ -= 8, pending_ >>= 8)
      out_.push_back(static_cast<std::uint8_t>(pending_));
  }
  void flush() {
    if (pending_bits_) out_.push_back(static_cast<std::uint8_t>(pending_));
    pending_ = 0, pending_bits_ = 0;
  }

 private:
  std::vector<std::uint8_t>& out_;
  std::uint64_t pending_ = 0;
  unsigned pending_bits_ = 0;
};

class BitReader {
 public:
  BitReader(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
  std::uint32_t get(unsigned count) {  // count ≤ 32
    std::uint32_t value = 0;
    for (unsigned k = 0; k < count; ++k, ++position_) {
      if (position_ / 8 >= size_) bad("the payload ends within the tables");
      value |= std::uint32_t{(data_[position_ / 8] >> (position_ % 8)) & 1u} << k;
    }
    return value;
  }
  // The bytes read, the last one whole; its bits after the tables MUST be 0.
  std::size_t finish() {
    if (position_ % 8 != 0 && (data_[position_ / 8] >> (position_ % 8)) != 0)
      bad("the padding bits after the tables are not 0");
    return (position_ + 7) / 8;
  }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t position_ = 0;
};

// Frequencies in proportion to the counts, each token that occurs at least
// 1, what that leaves over or takes beyond 4096 to the most frequent token.
void choose_frequencies(const std::array<std::array<std::uint32_t, kTokens>, kContexts>& counts, Tables& tables) {
  for (unsigned k = 0; k < kContexts; ++k) {
    std::uint64_t total = 0;
    for (std::uint32_t c : counts[k]) total += c;
    auto& f = tables.freq[k];
    if (total == 0) {
      f.fill(static_cast<std::uint16_t>(kTableTotal / kTokens));  // §7.2.2's table of an unused context
      continue;
    }
    std::uint32_t sum = 0;
    unsigned largest = 0;
    for (unsigned t = 0; t < kTokens; ++t) {
      const std::uint32_t c = counts[k][t];
      f[t] =
          c == 0 ? 0 : static_cast<std::uint16_t>(std::max<std::uint64_t>(1, std::uint64_t{c} * kTableTotal / total));
      sum += f[t];
      if (c > counts[k][largest]) largest = t;
    }
    // The largest keeps at least 4096/32 − 31 ≥ 97: at most 31 others were raised to 1.
    f[largest] = static_cast<std::uint16_t>(f[largest] + kTableTotal - sum);
  }
  tables.make_starts();
}

void write_tables(const std::array<std::array<std::uint32_t, kTokens>, kContexts>& counts, const Tables& tables,
                  std::vector<std::uint8_t>& out) {
  BitWriter bits(out);
  for (unsigned k = 0; k < kContexts; ++k) {
    std::uint32_t present = 0;
    for (unsigned t = 0; t < kTokens; ++t)
      if (counts[k][t]) present |= 1u << t;
    bits.put(present != 0, 1);
    if (!present) continue;
    bits.put(present, 32);
    const unsigned last = 31 - static_cast<unsigned>(__builtin_clz(present));
    for (unsigned t = 0; t < last; ++t) {
      if (!(present >> t & 1)) continue;
      const std::uint32_t f = tables.freq[k][t];  // 1 .. 4095
      const unsigned a = 31 - static_cast<unsigned>(__builtin_clz(f));
      bits.put(a, 4);
      bits.put(f - (1u << a), a);
    }
  }
  bits.flush();
}

// Parses §7.2.2's tables from the payload's start; returns their bytes.
std::size_t read_tables(const std::uint8_t* data, std::size_t size, Tables& tables) {
  BitReader bits(data, size);
  for (unsigned k = 0; k < kContexts; ++k) {
    auto& f = tables.freq[k];
    if (bits.get(1) == 0) {
      f.fill(static_cast<std::uint16_t>(kTableTotal / kTokens));
      continue;
    }
    const std::uint32_t present = bits.get(32);
    if (present == 0) bad("context " + std::to_string(k) + " is used but has no token present");
    const unsigned last = 31 - static_cast<unsigned>(__builtin_clz(present));
    std::uint32_t sum = 0;
    for (unsigned t = 0; t < kTokens; ++t) {
      f[t] = 0;
      if (!(present >> t & 1) || t == last) continue;
      const unsigned a = bits.get(4);
      if (a > 11)
        bad("context " + std::to_string(k) + ", token " + std::to_string(t) + ": a = " + std::to_string(a) +
            " exceeds 11");
      f[t] = static_cast<std::uint16_t>((1u << a) + bits.get(a));
      sum += f[t];
    }
    if (sum >= kTableTotal)
      bad("context " + std::to_string(k) + ": the frequencies before the last sum to " + std::to_string(sum) +
          ", leaving none of 4096 for token " + std::to_string(last));
    f[last] = static_cast<std::uint16_t>(kTableTotal - sum);
  }
  tables.make_starts();
  return bits.finish();
}

// The packed slot words of every context, for the vector decoder.
void make_slot_words(const Tables& tables, LaneSlotWords& slots) {
  slots.words.resize(std::size_t{kContexts} * kTableTotal);
  for (unsigned k = 0; k < kContexts; ++k) {
    std::uint32_t* at = slots.words.data() + std::size_t{k} * kTableTotal;
    for (unsigned t = 0; t < kTokens; ++t) {
      const std::uint32_t f = tables.freq[k][t], head = t | f << 5;
      for (std::uint32_t j = 0; j < f; ++j) *at++ = head | j << 18;
    }
  }
}

// The scalar decoder's lookup: which token each slot of a context is, made
// for a context when a voxel first needs it.
struct TokenLookup {
  std::array<std::array<std::uint8_t, kTableTotal>, kContexts> token_at;
  std::array<bool, kContexts> made{};
  const std::uint8_t* of(const Tables& tables, unsigned k) {
    if (!made[k]) {
      for (unsigned t = 0; t < kTokens; ++t)
        std::memset(token_at[k].data() + tables.start[k][t], static_cast<int>(t), tables.freq[k][t]);
      made[k] = true;
    }
    return token_at[k].data();
  }
};

// Bricks this small decode in scalar code: making 12 × 4096 slot words
// would cost more than the vectors save.
constexpr std::size_t kVectorFromVoxels = 4096;

}  // namespace

bool encode_residual_lanes(const std::uint16_t* residuals, const BrickDims& dims, std::size_t limit,
                           std::vector<std::uint8_t>& out) {
  const std::size_t n = std::size_t{dims[0]} * dims[1] * dims[2];
  // Kept per thread: every element is written before it is read.
  thread_local std::vector<std::uint8_t> tokens, lengths, contexts;
  thread_local std::vector<std::uint16_t> words;
  tokens.resize(n);
  lengths.resize(n);
  contexts.resize(n);
  tokens_of(residuals, n, tokens.data(), lengths.data());
  std::array<std::array<std::uint32_t, kTokens>, kContexts> counts{};
  walk_rows(dims, lengths.data(), [&](std::size_t row, const std::uint8_t* row_contexts, std::uint8_t*) {
    std::memcpy(contexts.data() + row, row_contexts, dims[0]);
    for (std::uint32_t x = 0; x < dims[0]; ++x) ++counts[row_contexts[x]][tokens[row + x]];
  });
  Tables tables;
  choose_frequencies(counts, tables);
  // Written after what `out` holds, and cut off again if over the limit.
  const std::size_t start = out.size();
  auto refuse = [&] {
    out.resize(start);
    return false;
  };
  write_tables(counts, tables, out);
  const std::size_t tables_size = out.size() - start;
  if (tables_size + kFixedHeader > limit) return refuse();

  // rANS from the last voxel, voxel i on state i mod 32, at most a word a
  // voxel: the words are written from the back of room for n of them.
  std::array<std::uint32_t, kLanes> x;
  x.fill(kStateLow);
  words.resize(n);
  std::uint16_t* const words_end = words.data() + n;
  std::uint16_t* w = words_end;
  // The voxels after the last whole 32 here, those before in vectors
  // where the processor has AVX2.
  const std::size_t vector_chunks = lane_rows_avx2_available() ? n / kLanes : 0;
  for (std::size_t i = n; i-- > kLanes * vector_chunks;) {
    const unsigned k = contexts[i], t = tokens[i];
    const std::uint32_t f = tables.freq[k][t], s = tables.start[k][t];
    std::uint32_t state = x[i % kLanes];
    const bool out = std::uint64_t{state} >= std::uint64_t{f} << 20;
    w[-1] = static_cast<std::uint16_t>(state);  // kept only when out: w moves over it
    w -= out;
    state >>= 16 * out;
    const std::uint32_t q = divide_by_frequency(state, f);
    x[i % kLanes] = (q << kTableBits) + (state - q * f) + s;
  }
  if (vector_chunks) {
    LaneSymbols symbols;
    for (unsigned k = 0; k < kContexts; ++k)
      for (unsigned t = 0; t < kTokens; ++t)
        symbols[k * kTokens + t] = tables.freq[k][t] | std::uint32_t{tables.start[k][t]} << 16;
    w = encode_lane_chunks_avx2(symbols, contexts.data(), tokens.data(), vector_chunks, x, w);
  }
  const std::size_t word_count = static_cast<std::size_t>(words_end - w);
  if (tables_size + kFixedHeader + 2 * word_count > limit) return refuse();
  // The bits below, LSB first, as coder 2 packs them, and the 8 bytes
  // put_bits_below may write past them: `out` is zero-filled only as far
  // as it is used (at 2n bytes, that and its page faults were a twentieth
  // of a conversion's time).
  const std::size_t bits_at = start + tables_size + kFixedHeader + 2 * word_count;
  const std::size_t bits_size = static_cast<std::size_t>((count_bits_below(tokens.data(), n) + 7) / 8);
  if (bits_at - start + bits_size > limit) return refuse();
  out.resize(bits_at + bits_size + 8);
  std::uint8_t* const at = out.data() + start + tables_size;
  for (unsigned l = 0; l < kLanes; ++l) put_u32(at + 4 * l, x[l]);
  put_u32(at + 4 * kLanes, static_cast<std::uint32_t>(word_count));
  for (std::size_t j = 0; j < word_count; ++j) {
    at[kFixedHeader + 2 * j] = static_cast<std::uint8_t>(w[j]);
    at[kFixedHeader + 2 * j + 1] = static_cast<std::uint8_t>(w[j] >> 8);
  }
  std::uint8_t* const to = put_bits_below(tokens.data(), residuals, n, out.data() + bits_at);
  out.resize(static_cast<std::size_t>(to - out.data()));
  if (out.size() - start > limit) return refuse();
  return true;
}

void decode_residual_lanes(const std::uint8_t* data, std::size_t size, const BrickDims& dims,
                           std::uint16_t* residuals) {
  const std::size_t n = std::size_t{dims[0]} * dims[1] * dims[2];
  Tables tables;
  const std::size_t tables_size = read_tables(data, size, tables);
  if (size - tables_size < kFixedHeader)
    bad("the payload ends within the states or W (" + std::to_string(size - tables_size) + " bytes after the tables)");
  LaneDecoderState state;
  const std::uint8_t* p = data + tables_size;
  for (unsigned l = 0; l < kLanes; ++l) {
    state.x[l] = read_u32(p + 4 * l);
    if (state.x[l] < kStateLow)
      bad("initial state " + std::to_string(l) + " is " + std::to_string(state.x[l]) + ", below 2^16");
  }
  const std::uint64_t word_count = read_u32(p + 4 * kLanes);
  p += kFixedHeader;
  const std::size_t left = size - static_cast<std::size_t>(p - data);
  if (2 * word_count > left)
    bad("W = " + std::to_string(word_count) + " words exceed the " + std::to_string(left) + " bytes left");
  state.words = p;
  state.words_end = p + 2 * word_count;

  // The tokens, row by row: in vector registers where the rows allow,
  // then (or else) in scalar code.
  thread_local std::vector<std::uint8_t> tokens, lengths;  // each written before it is read
  tokens.resize(n);
  lengths.resize(n);
  const std::uint32_t nx = dims[0];
  const std::size_t rows = std::size_t{dims[1]} * dims[2];
  std::size_t row = 0;
  if (nx % kLanes == 0 && n >= kVectorFromVoxels && lane_rows_avx2_available()) {
    thread_local LaneSlotWords slots;
    make_slot_words(tables, slots);
    row = decode_lane_rows_avx2(slots, dims, 0, state, tokens.data(), lengths.data());
  }
  if (row < rows) {
    TokenLookup lookup;
    walk_rows(
        dims, lengths.data(),
        [&](std::size_t i, const std::uint8_t* contexts, std::uint8_t* row_lengths) {
          for (std::uint32_t x = 0; x < nx; ++x) {
            const unsigned k = contexts[x];
            std::uint32_t& xs = state.x[(i + x) % kLanes];
            const std::uint32_t slot = xs & (kTableTotal - 1);
            const unsigned t = lookup.of(tables, k)[slot];
            xs = tables.freq[k][t] * (xs >> kTableBits) + slot - tables.start[k][t];
            if (xs < kStateLow) {
              if (state.words == state.words_end) bad("the word stream ends before the brick's last voxel");
              xs = xs << 16 | std::uint32_t{state.words[0]} | std::uint32_t{state.words[1]} << 8;
              state.words += 2;
            }
            tokens[i + x] = static_cast<std::uint8_t>(t);
            row_lengths[x] = static_cast<std::uint8_t>(token_bit_length(t));
          }
        },
        row);
  }
  if (state.words != state.words_end)
    bad(std::to_string((state.words_end - state.words) / 2) + " words are left after the brick's last voxel");
  for (unsigned l = 0; l < kLanes; ++l)
    if (state.x[l] != kStateLow)
      bad("state " + std::to_string(l) + " ends at " + std::to_string(state.x[l]) + ", not 2^16");

  // The bits below, to the payload's end: exactly the bytes their count
  // needs, the last one's unused high bits 0.
  const std::uint8_t* const bits = state.words_end;
  const std::size_t stream = size - static_cast<std::size_t>(bits - data);
  const std::uint64_t needed = count_bits_below(tokens.data(), n);
  const std::uint64_t needed_bytes = (needed + 7) / 8;
  if (needed_bytes > stream) bad("the bits below the tokens end before the brick's last voxel");
  if (needed_bytes < stream)
    bad(std::to_string(stream - needed_bytes) + " bytes are left after the bits below the brick's last token");
  if (needed % 8 != 0 && (bits[needed_bytes - 1] >> (needed % 8)) != 0)
    bad("the padding bits after the last residual's bits are not 0");
  take_bits_below(tokens.data(), n, bits, stream, residuals);
}

}  // namespace ivol::detail
