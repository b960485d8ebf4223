// Errors raised by libformat. Every error carries the class the spec (§13)
// assigns to it, so that tools, tests and fuzzers can tell a damaged file from
// an unsupported one without parsing messages.
#pragma once

#include <stdexcept>
#include <string>

namespace ivol {

enum class ErrorClass {
  NotIvol,             // the file does not start with the signature
  UnsupportedVersion,  // version_major is not one we know
  UnsupportedFeature,  // unknown required feature, enum value or stream
  Truncated,           // too short, or no valid footer at the end
  Checksum,            // a CRC-32C or zstd checksum does not match
  Malformed,           // any other broken rule of the spec
  LimitExceeded,       // the file is valid but exceeds a limit set by the caller
  Io,                  // the operating system refused a read or write
  InvalidArgument,     // the caller asked for something impossible
};

// The spec's name for an error class ("not-ivol", "checksum", ...).
const char* error_class_name(ErrorClass error_class);

class Error : public std::runtime_error {
 public:
  Error(ErrorClass error_class, const std::string& message) : std::runtime_error(message), class_(error_class) {}
  ErrorClass error_class() const noexcept { return class_; }

 private:
  ErrorClass class_;
};

}  // namespace ivol
