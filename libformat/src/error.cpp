#include "ivol/error.hpp"

namespace ivol {

const char* error_class_name(ErrorClass error_class) {
  switch (error_class) {
    case ErrorClass::NotIvol:
      return "not-ivol";
    case ErrorClass::UnsupportedVersion:
      return "unsupported-version";
    case ErrorClass::UnsupportedFeature:
      return "unsupported-feature";
    case ErrorClass::Truncated:
      return "truncated";
    case ErrorClass::Checksum:
      return "checksum";
    case ErrorClass::Malformed:
      return "malformed";
    case ErrorClass::LimitExceeded:
      return "limit-exceeded";
    case ErrorClass::Io:
      return "io";
    case ErrorClass::InvalidArgument:
      return "invalid-argument";
  }
  return "unknown";
}

}  // namespace ivol
