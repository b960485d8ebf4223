// Packing plain values and byte strings into one message and reading them
// back in the same order, for messages between ivol's own processes: the
// HDF5 worker's requests and replies (isolated_worker.hpp) and the blocks a
// distributed reconstruction's ranks compress (tools/cli/mpi_block_farm).
// Both ends are the same build, so values travel in the host's byte order.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "ivol/error.hpp"

namespace ivol::convert {

// `Bytes` is the message's buffer: std::string or std::vector<std::uint8_t>.
template <typename Bytes>
class BasicWireWriter {
 public:
  template <typename T>
  BasicWireWriter& put(const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    append(&value, sizeof value);
    return *this;
  }
  // A length, then the bytes.
  template <typename Sequence>
  BasicWireWriter& put_bytes(const Sequence& sequence) {
    static_assert(sizeof(typename Sequence::value_type) == 1);
    put<std::uint64_t>(sequence.size());
    append(sequence.data(), sequence.size());
    return *this;
  }
  BasicWireWriter& put_string(const std::string& text) { return put_bytes(text); }
  Bytes& bytes() { return bytes_; }

 private:
  void append(const void* data, std::size_t size) {
    const auto* first = static_cast<const typename Bytes::value_type*>(data);
    bytes_.insert(bytes_.end(), first, first + size);
  }
  Bytes bytes_;
};

// A message shorter than its fields throws: the other end is ivol itself, so
// that is a bug, not a damaged file. The reader owns the message (replies
// arrive as temporaries).
template <typename Bytes>
class BasicWireReader {
 public:
  explicit BasicWireReader(Bytes bytes) : bytes_(std::move(bytes)) {}
  template <typename T>
  T get() {
    static_assert(std::is_trivially_copyable_v<T>);
    T value;
    std::memcpy(&value, take(sizeof value), sizeof value);
    return value;
  }
  template <typename Sequence = Bytes>
  Sequence get_bytes() {
    const auto size = get<std::uint64_t>();
    const auto* first = reinterpret_cast<const typename Sequence::value_type*>(take(size));
    return Sequence(first, first + size);
  }
  std::string get_string() { return get_bytes<std::string>(); }

 private:
  const void* take(std::uint64_t size) {
    if (size > bytes_.size() - position_)
      throw Error(ErrorClass::Malformed, "a message between ivol's processes is shorter than its fields");
    const void* at = bytes_.data() + position_;
    position_ += size;
    return at;
  }
  Bytes bytes_;
  std::size_t position_ = 0;
};

using WireWriter = BasicWireWriter<std::string>;
using WireReader = BasicWireReader<std::string>;

}  // namespace ivol::convert
