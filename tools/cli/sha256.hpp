// SHA-256 (FIPS 180-4) through OpenSSL's libcrypto, for fixity: the digests
// ivol records and checks are the ones `sha256sum` prints.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

namespace ivol::cli {

class Sha256 {
 public:
  Sha256();
  ~Sha256();
  Sha256(const Sha256&) = delete;
  Sha256& operator=(const Sha256&) = delete;
  void update(const void* data, std::size_t size);
  std::string hex();  // finishes: lower-case hex, 64 characters

 private:
  struct Context;
  std::unique_ptr<Context> context_;
};

struct FileDigest {
  std::string path;
  std::uint64_t bytes = 0;
  std::string sha256;
};

// Reads the whole file once. Throws ivol::Error (Io) naming the file. With
// `cancel`, stops early (the digest is then meaningless) once it is set.
FileDigest digest_file(const std::string& path, const std::atomic<bool>* cancel = nullptr);

}  // namespace ivol::cli
