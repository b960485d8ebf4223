// Codec 6 (spec §7.4). The encoder runs the models forward, as the decoder
// will, noting each voxel's frequency and start, then codes the voxels
// backwards (rANS is last in, first out) so that the decoder reads the
// stream front to back.
#include "ivol/top_byte_codec.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <string>

#include "ivol/error.hpp"

namespace ivol {
namespace {

constexpr unsigned kContexts = 128;            // 4 sign counts × 32 magnitude classes
constexpr unsigned kNibbleContexts = 256;      // mode 1: the voxel's own top byte
constexpr unsigned kPrecision = 16;            // every table sums to 2^16
constexpr std::uint32_t kStateLow = 1u << 23;  // the state lies in [2^23, 2^31) between symbols
constexpr std::uint32_t kCountStep = 16;       // added to a symbol's count each time it occurs (start 1)
constexpr std::uint32_t kRefreshEvery = 128;   // as entropy coder 2 of codec 3 (§7.2.1)
constexpr unsigned kLookupShift = 8;           // the decoder's coarse table for bytes: a slot in 256

[[noreturn]] void bad(const std::string& what) { throw Error(ErrorClass::Malformed, "codec 6: " + what); }

std::uint32_t next_refresh(std::uint32_t seen) {
  return seen < 4 ? 4 : seen < kRefreshEvery ? 2 * seen : seen + kRefreshEvery;
}

// One context's adaptive counts over an alphabet of A symbols and the table
// made from them (§7.4).
template <unsigned A>
struct Model {
  std::array<std::uint32_t, A> count;
  std::array<std::uint32_t, A> freq;
  std::array<std::uint32_t, A + 1> start;
  std::uint32_t seen = 0;
  std::uint32_t refresh_at = next_refresh(0);

  // Every count 1: the table is 2^16 / A each (make_table's result for
  // these counts, written out).
  Model() {
    count.fill(1);
    freq.fill((1u << kPrecision) / A);
    for (unsigned s = 0; s <= A; ++s) start[s] = s * ((1u << kPrecision) / A);
  }

  // freq[s] = max(1, floor(count[s]·R / 2^32)), R = floor(2^48 / total);
  // what that leaves over or takes beyond 2^16 goes to the largest freq (the
  // lowest symbol on a tie). It stays at least 2^16 / A − A > 1.
  void make_table() {
    const std::uint64_t total = std::uint64_t{A} + std::uint64_t{kCountStep} * seen;
    const std::uint64_t scale = (std::uint64_t{1} << 48) / total;
    // Three loops the compiler vectorises: the frequencies and their sum,
    // the largest, then the first symbol that has it.
    // max(1, ·) without a branch: which symbols round to 0 is the data's
    // choice, and a branch on it mispredicted on most refreshes.
    std::uint32_t sum = 0;
    for (unsigned s = 0; s < A; ++s) {
      const auto scaled = static_cast<std::uint32_t>((count[s] * scale) >> 32);
      freq[s] = scaled + static_cast<std::uint32_t>(scaled == 0);
      sum += freq[s];
    }
    std::uint32_t largest_freq = 0;
    for (unsigned s = 0; s < A; ++s) largest_freq = std::max(largest_freq, freq[s]);
    unsigned largest = 0;
    while (freq[largest] != largest_freq) ++largest;
    freq[largest] = largest_freq + (1u << kPrecision) - sum;
    // The running sum in a register, not read back from start[].
    std::uint32_t run = 0;
    for (unsigned s = 0; s < A; ++s) start[s] = run, run += freq[s];
    start[A] = run;
  }

  bool note(unsigned s) {
    count[s] += kCountStep;
    if (++seen != refresh_at) return false;
    refresh_at = next_refresh(seen);
    make_table();
    return true;
  }

  // The decoder's search: the symbol whose range holds `slot`, from `from`
  // (a symbol at or below it) up.
  unsigned symbol_at(std::uint32_t slot, unsigned from) const {
    unsigned s = from;
    while (start[s + 1] <= slot) ++s;
    return s;
  }
  // The same for a small alphabet, from symbol 0: how many starts after the
  // first lie at or below the slot (start[A] = 2^16 never does), counted in
  // one loop the compiler vectorises, where the search's exit mispredicted.
  unsigned symbol_counted(std::uint32_t slot) const {
    unsigned s = 0;
    for (unsigned k = 1; k <= A; ++k) s += static_cast<unsigned>(start[k] <= slot);
    return s;
  }
};

using ByteModel = Model<256>;
using NibbleModel = Model<16>;

// The decoder's byte model: the same, and for every 256th slot the symbol
// whose range holds it, from which a short search finds a slot's symbol.
struct ByteDecoderModel : ByteModel {
  static constexpr unsigned kBucket = 1u << kLookupShift;
  static constexpr unsigned kBuckets = (1u << kPrecision) >> kLookupShift;
  std::array<std::uint8_t, kBuckets> lookup;
  ByteDecoderModel() { fill(); }
  // lookup[j] is the largest symbol s with start[s] ≤ j·256, that is with
  // ceil(start[s] / 256) ≤ j: each symbol is written where its start rounds
  // up to (the largest wins, written last), then a running maximum carries
  // it over the buckets no start falls in. No branch depends on the table,
  // where a search per bucket mispredicted at every symbol (it took a
  // quarter of the decoder's time: tables are made again every 128 symbols
  // of a context, more often at its start).
  void fill() {
    std::array<std::int16_t, kBuckets + 1> last;
    last.fill(-1);
    for (unsigned s = 0; s < 256; ++s) last[(start[s] + kBucket - 1) >> kLookupShift] = static_cast<std::int16_t>(s);
    std::int16_t symbol = 0;
    for (unsigned j = 0; j < kBuckets; ++j) {
      symbol = std::max(symbol, last[j]);
      lookup[j] = static_cast<std::uint8_t>(symbol);
    }
  }
};

// A brick's models, each made from a copy of the fresh one when its context
// is first met: a brick meets a fraction of the contexts, and making all of
// them (half a megabyte for the decoder's) cost more than coding a small
// brick. Kept per thread between bricks.
template <class M>
class Models {
 public:
  void reset(std::size_t count) {
    if (models_.size() < count) models_.resize(count);
    ready_.assign(count, 0);
  }
  M& operator[](std::size_t k) {
    if (!ready_[k]) {
      static const M fresh;
      models_[k] = fresh;
      ready_[k] = 1;
    }
    return models_[k];
  }

 private:
  std::vector<M> models_;
  std::vector<std::uint8_t> ready_;
};

// The context of a voxel from its neighbours' top bytes a (x − 1), b (y − 1)
// and c (z − 1), 0 outside the brick: 32·(their sign bits' sum) + the class
// of the sum of their low seven bits m, min(31, max(0, floor((m − 3·centre)
// / step) + 16)). `classes` holds that class for every m in 0 .. 381.
struct Contexts {
  std::array<std::uint8_t, 3 * 127 + 1> classes;
  Contexts(unsigned centre, unsigned step) {
    for (int m = 0; m < static_cast<int>(classes.size()); ++m) {
      const int v = m - 3 * static_cast<int>(centre) + 16 * static_cast<int>(step);
      classes[m] = static_cast<std::uint8_t>(v < 0 ? 0 : std::min(31, v / static_cast<int>(step)));
    }
  }
  // The parts of a row's contexts its earlier rows give: per x, the sign
  // count (bits 9–10) and low-bit sum (bits 0–8) of b and c.
  static void row_parts(const std::uint8_t* up, const std::uint8_t* back, std::uint32_t nx, std::uint16_t* parts) {
    for (std::uint32_t x = 0; x < nx; ++x) {
      const unsigned b = up ? up[x] : 0, c = back ? back[x] : 0;
      parts[x] = static_cast<std::uint16_t>(((b >> 7) + (c >> 7)) << 9 | ((b & 127) + (c & 127)));
    }
  }
  unsigned of(std::uint16_t part, unsigned a) const {
    const unsigned signs = (part >> 9) + (a >> 7), m = (part & 511) + (a & 127);
    return 32 * signs + classes[m];
  }
};

// The encoder's centre and step (any are valid): the centre is the median of
// the top bytes' low seven bits; the step two thirds of the spread between
// their 10th and 90th percentiles, at least 4. Measured on the noisy 256³
// phantoms (bench/RESULTS.md, "Codec 6"): binary16 did best with steps of
// 10-12 for a spread of 16, float32 (whose top bytes' low bits are the
// exponent's, a spread of 2) with 4; finer classes learn too slowly.
std::pair<unsigned, unsigned> choose_classes(const std::uint8_t* top, std::size_t n) {
  std::array<std::size_t, 128> histogram{};
  for (std::size_t i = 0; i < n; ++i) ++histogram[top[i] & 127];
  auto percentile = [&](std::size_t rank) {
    std::size_t seen = 0;
    for (unsigned v = 0; v < 128; ++v)
      if ((seen += histogram[v]) > rank) return v;
    return 127u;
  };
  const unsigned centre = percentile(n / 2), low = percentile(n / 10), high = percentile(n - 1 - n / 10);
  const unsigned step = std::clamp((2 * (high - low) + 1) / 3, 4u, 255u);
  return {centre, step};
}

void put_u32(std::uint8_t* p, std::uint32_t v) {
  for (int k = 0; k < 4; ++k) p[k] = static_cast<std::uint8_t>(v >> (8 * k));
}
std::uint32_t read_u32(const std::uint8_t* p) {
  return std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 | std::uint32_t{p[3]} << 24;
}

// A lower bound, in 1/256 bit, of what a symbol of frequency f (of 2^16)
// costs, -log2(f / 2^16): log2 f rounded up from its leading bit and the
// next eight. The encoder sums it to stop as soon as the brick cannot come
// out smaller than the caller's limit.
unsigned cost_q8(std::uint32_t f) {
  static const std::array<std::uint16_t, 256> fraction_up = [] {
    std::array<std::uint16_t, 256> t{};
    for (unsigned m = 0; m < 256; ++m)
      t[m] = static_cast<std::uint16_t>(std::ceil(256.0 * std::log2(1.0 + (m + 1) / 256.0)));
    return t;
  }();
  const unsigned e = 31 - static_cast<unsigned>(__builtin_clz(f));
  const unsigned m = e >= 8 ? (f >> (e - 8)) & 255 : (f << (8 - e)) & 255;
  const unsigned log2_up = (e << 8) + fraction_up[m];
  return log2_up >= (kPrecision << 8) ? 0 : (kPrecision << 8) - log2_up;
}

// floor(x / f) for x < 2^31 and 1 ≤ f < 2^16 without a division, which was
// a quarter of the encoder's time: (x · m) >> 47 with m = floor(2^47 / f) +
// 1 is exact, since m exceeds 2^47 / f by at most 1 and so the product by
// less than x / 2^47 < 2^-16 ≤ 1 / f. The reciprocals, 512 KiB, are made
// once.
std::uint32_t quotient(std::uint32_t x, std::uint32_t f) {
  static const std::vector<std::uint64_t> reciprocal = [] {
    std::vector<std::uint64_t> r(1u << kPrecision);
    for (std::uint64_t g = 1; g < r.size(); ++g) r[g] = ((std::uint64_t{1} << 47) / g) + 1;
    return r;
  }();
  __extension__ using Wide = unsigned __int128;  // GCC's and Clang's, without -Wpedantic's warning
  return static_cast<std::uint32_t>((static_cast<Wide>(x) * reciprocal[f]) >> 47);
}

// Visits the brick's rows in raster order: visit(i, parts) for the row
// starting at voxel i, with its row_parts from the top bytes in `top`.
template <class Visit>
void walk_rows(const BrickDims& d, const std::uint8_t* top, Visit&& visit) {
  const std::size_t sy = d[0], sz = std::size_t{d[0]} * d[1];
  std::vector<std::uint16_t> parts(d[0]);
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y, i += d[0]) {
      Contexts::row_parts(y ? top + i - sy : nullptr, z ? top + i - sz : nullptr, d[0], parts.data());
      visit(i, parts.data());
    }
}

}  // namespace

std::uint64_t top_byte_payload_bound(std::uint64_t count, unsigned width) {
  return kTopByteHeaderSize + 4 + width * count;
}

std::vector<std::uint8_t> encode_top_byte(const std::uint8_t* values, const BrickDims& dims, unsigned width,
                                          std::size_t limit, unsigned step_asked) {
  const std::size_t n = std::size_t{dims[0]} * dims[1] * dims[2];
  // Mode 1 (the second byte's high nibble coded too) for 4-byte values only:
  // float32's second byte holds the exponent's last bit and the fraction's
  // first, which the top byte predicts; binary16's low byte is fraction
  // bits that a model with 256 contexts learns too slowly in a brick
  // (bench/RESULTS.md, "Codec 6").
  const unsigned mode = width == 4 ? 1 : 0;
  // The spec's limit (§7): never larger than the values stored and a header.
  limit = std::min<std::size_t>(limit, top_byte_payload_bound(n, width) + 1);
  const std::size_t lower = mode ? (width - 2) * n + (n + 1) / 2 : (width - 1) * n;
  if (kTopByteHeaderSize + 4 + lower >= limit) return {};
  std::vector<std::uint8_t> top(n);
  for (std::size_t i = 0; i < n; ++i) top[i] = values[i * width + width - 1];
  const auto [centre, step_chosen] = choose_classes(top.data(), n);
  const unsigned step = step_asked ? std::min(step_asked, 255u) : step_chosen;
  const Contexts contexts(centre, step);
  thread_local Models<ByteModel> models;
  models.reset(kContexts);
  thread_local Models<NibbleModel> nibble_models;
  nibble_models.reset(mode ? kNibbleContexts : 0);
  // Every symbol's frequency and start, in the order the decoder reads them.
  const std::size_t symbols = mode ? 2 * n : n;
  thread_local std::vector<std::uint32_t> freqs, starts;  // each written before it is read
  freqs.resize(symbols);
  starts.resize(symbols);
  // What the symbols cost at the least, in 1/256 bit, against what the
  // limit leaves them: the trial stops when it cannot be smaller.
  const std::uint64_t budget_q8 = std::uint64_t{limit - kTopByteHeaderSize - 4 - lower} << 11;
  std::uint64_t spent_q8 = 0;
  // After a sixteenth of the rows, the cost so far times sixteen (an
  // overestimate: the models learn, so early symbols cost the most) is held
  // against the budget with 40 % to spare: a brick that projects over it is
  // left to the other codecs. On the six 256³ phantoms of bench/RESULTS.md
  // ("Codec 6") this gave up no brick that codec 6 would have won, and cut
  // the time of the trials that lose by a third.
  bool projected = false;
  walk_rows(dims, top.data(), [&](std::size_t row, const std::uint16_t* parts) {
    if (!projected && 16 * row >= n && n >= 4096) {
      projected = true;
      if (16 * spent_q8 * 10 > budget_q8 * 14) spent_q8 = budget_q8;
    }
    if (spent_q8 >= budget_q8) return;
    unsigned before = 0;
    for (std::uint32_t x = 0; x < dims[0]; ++x) {
      const std::size_t i = row + x;
      const unsigned s = top[i];
      ByteModel& m = models[contexts.of(parts[x], before)];
      const std::size_t at = mode ? 2 * i : i;
      freqs[at] = m.freq[s];
      starts[at] = m.start[s];
      spent_q8 += cost_q8(m.freq[s]);
      m.note(s);
      if (mode) {
        const unsigned u = values[i * width + width - 2] >> 4;
        NibbleModel& h = nibble_models[s];
        freqs[at + 1] = h.freq[u];
        starts[at + 1] = h.start[u];
        spent_q8 += cost_q8(h.freq[u]);
        h.note(u);
      }
      before = s;
    }
  });
  if (spent_q8 >= budget_q8) return {};
  // rANS from the last symbol to the first, the stream written backwards.
  const std::size_t room = 2 * symbols + 4;
  std::vector<std::uint8_t> stream(room);
  std::uint8_t* const begin = stream.data();
  std::uint8_t* p = begin + room;
  const std::size_t rans_limit = limit - kTopByteHeaderSize - lower;
  std::uint32_t x = kStateLow;
  for (std::size_t i = symbols; i-- > 0;) {
    const std::uint32_t f = freqs[i];
    const std::uint32_t x_max = ((kStateLow >> kPrecision) << 8) * f;
    while (x >= x_max) {
      *--p = static_cast<std::uint8_t>(x);
      x >>= 8;
    }
    const std::uint32_t q = quotient(x, f);
    x = (q << kPrecision) + (x - q * f) + starts[i];
    if (static_cast<std::size_t>(begin + room - p) + 4 >= rans_limit) return {};
  }
  p -= 4;
  put_u32(p, x);
  const auto rans_size = static_cast<std::uint32_t>(begin + room - p);
  std::vector<std::uint8_t> out(kTopByteHeaderSize + rans_size + lower);
  out[0] = static_cast<std::uint8_t>(centre);
  out[1] = static_cast<std::uint8_t>(step);
  out[2] = static_cast<std::uint8_t>(mode);
  put_u32(out.data() + 4, rans_size);
  std::memcpy(out.data() + kTopByteHeaderSize, p, rans_size);
  std::uint8_t* planes = out.data() + kTopByteHeaderSize + rans_size;
  const unsigned whole = mode ? width - 2 : width - 1;
  for (unsigned b = 0; b < whole; ++b)
    for (std::size_t i = 0; i < n; ++i) planes[b * n + i] = values[i * width + b];
  if (mode) {
    std::uint8_t* nibbles = planes + whole * n;
    for (std::size_t i = 0; i < n; ++i)
      nibbles[i / 2] =
          static_cast<std::uint8_t>(nibbles[i / 2] | (values[i * width + width - 2] & 15) << (4 * (i % 2)));
  }
  return out;
}

void decode_top_byte(const std::uint8_t* payload, std::size_t size, const BrickDims& dims, unsigned width,
                     std::uint8_t* out) {
  const std::size_t n = std::size_t{dims[0]} * dims[1] * dims[2];
  if (width != 2 && width != 4) bad("values of " + std::to_string(width) + " bytes, not 2 or 4");
  if (size < kTopByteHeaderSize)
    bad("the payload of " + std::to_string(size) + " bytes is shorter than the codec header");
  const unsigned centre = payload[0], step = payload[1], mode = payload[2];
  if (centre > 127) bad("the centre " + std::to_string(centre) + " exceeds 127");
  if (step == 0) bad("the step is 0");
  if (mode > 1) bad("the mode " + std::to_string(mode) + " is not 0 or 1");
  if (payload[3] != 0) bad("the reserved byte 3 is not 0");
  const std::uint64_t symbols = mode ? 2 * std::uint64_t{n} : n;
  const std::uint64_t rans_size = read_u32(payload + 4);
  const unsigned whole = mode ? width - 2 : width - 1;
  const std::uint64_t lower = std::uint64_t{whole} * n + (mode ? (std::uint64_t{n} + 1) / 2 : 0);
  if (rans_size < 4 || rans_size > 2 * symbols + 4)
    bad("the rANS stream's length " + std::to_string(rans_size) + " is not within 4 .. " +
        std::to_string(2 * symbols + 4));
  if (kTopByteHeaderSize + rans_size + lower != size)
    bad("the payload holds " + std::to_string(size) + " bytes, not the header's 8, the rANS stream's " +
        std::to_string(rans_size) + " and the stored bits' " + std::to_string(lower));
  const std::uint8_t* in = payload + kTopByteHeaderSize;
  const std::uint8_t* const end = in + rans_size;
  const std::uint8_t* const nibbles = end + std::size_t{whole} * n;
  if (mode && n % 2 && (nibbles[n / 2] >> 4) != 0) bad("the padding nibble after the last voxel's is not 0");
  std::uint32_t x = read_u32(in);
  in += 4;
  if (x < kStateLow || x >= (1u << 31))
    bad("the initial rANS state " + std::to_string(x) + " is not in 2^23 .. 2^31 - 1");

  const Contexts contexts(centre, step);
  thread_local Models<ByteDecoderModel> models;
  models.reset(kContexts);
  thread_local Models<NibbleModel> nibble_models;
  nibble_models.reset(mode ? kNibbleContexts : 0);
  thread_local std::vector<std::uint8_t> top;
  top.resize(n);
  walk_rows(dims, top.data(), [&](std::size_t row, const std::uint16_t* parts) {
    // The state and the stream's position as locals, which the loop keeps in
    // registers (as captured variables they went through memory, each
    // symbol's load waiting on the last one's store).
    std::uint32_t state = x;
    const std::uint8_t* at = in;
    // Symbol s of `m` taken from the state, the state renormalised: at most two
    // bytes (a step leaves the state at 2^7 or more), their number from two
    // compares rather than a loop whose exit the data decides.
    auto decode = [&](auto& m, const unsigned s) {
      const std::uint32_t slot = state & ((1u << kPrecision) - 1);
      state = m.freq[s] * (state >> kPrecision) + slot - m.start[s];
      if (__builtin_expect(end - at >= 2, 1)) {
        const unsigned k = static_cast<unsigned>(state < kStateLow) + static_cast<unsigned>(state < (kStateLow >> 8));
        const std::uint32_t next = std::uint32_t{at[0]} << 8 | at[1];
        state = state << (8 * k) | next >> (16 - 8 * k);
        at += k;
      } else {
        while (state < kStateLow) {
          if (at == end) bad("the rANS stream ends before the brick's last voxel");
          state = state << 8 | *at++;
        }
      }
      return s;
    };
    unsigned before = 0;
    for (std::uint32_t i = 0; i < dims[0]; ++i) {
      ByteDecoderModel& m = models[contexts.of(parts[i], before)];
      const std::uint32_t slot = state & ((1u << kPrecision) - 1);
      const unsigned s = decode(m, m.symbol_at(slot, m.lookup[slot >> kLookupShift]));
      if (m.note(s)) m.fill();
      top[row + i] = static_cast<std::uint8_t>(s);
      std::uint8_t* value = out + (row + i) * width;
      if (mode) {
        NibbleModel& h = nibble_models[s];
        const unsigned u = decode(h, h.symbol_counted(state & ((1u << kPrecision) - 1)));
        h.note(u);
        value[width - 2] = static_cast<std::uint8_t>(u << 4 | ((nibbles[(row + i) / 2] >> (4 * ((row + i) % 2))) & 15));
      }
      value[width - 1] = static_cast<std::uint8_t>(s);
      before = s;
    }
    x = state;
    in = at;
  });
  if (in != end) bad(std::to_string(end - in) + " bytes of the rANS stream are left after the brick's last voxel");
  if (x != kStateLow) bad("the rANS state does not end at 2^23");
  for (unsigned b = 0; b < whole; ++b)
    for (std::size_t i = 0; i < n; ++i) out[i * width + b] = end[b * n + i];
}

}  // namespace ivol
