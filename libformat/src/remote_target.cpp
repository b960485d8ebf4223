#include "remote_target.hpp"

#include <cstdlib>

#include "ivol/error.hpp"

namespace ivol::detail {
namespace {

std::string environment(const char* name) {
  const char* value = std::getenv(name);
  return value ? std::string(value) : std::string();
}

std::string first_of(const char* a, const char* b) {
  std::string value = environment(a);
  return value.empty() ? environment(b) : value;
}

// RFC 3986 percent-encoding of a key, '/' kept: SigV4's canonical URI is
// the path encoded once, and libcurl signs the path as it is sent.
std::string encode_key(const std::string& key) {
  static const char* hex = "0123456789ABCDEF";
  std::string out;
  for (const unsigned char c : key) {
    const bool unreserved = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' ||
                            c == '.' || c == '_' || c == '~' || c == '/';
    if (unreserved) {
      out += static_cast<char>(c);
    } else {
      out += '%';
      out += hex[c >> 4];
      out += hex[c & 15];
    }
  }
  return out;
}

}  // namespace

RemoteTarget resolve_remote_target(const std::string& path) {
  RemoteTarget target;
  if (path.rfind("s3://", 0) != 0) {
    target.url = path;
    return target;
  }
  const std::string rest = path.substr(5);
  const auto slash = rest.find('/');
  if (slash == std::string::npos || slash == 0 || slash + 1 == rest.size())
    throw Error(ErrorClass::InvalidArgument, path + ": an S3 path is s3://BUCKET/KEY");
  const std::string bucket = rest.substr(0, slash), key = encode_key(rest.substr(slash + 1));
  std::string region = first_of("AWS_REGION", "AWS_DEFAULT_REGION");
  if (region.empty()) region = "us-east-1";
  std::string endpoint = first_of("AWS_ENDPOINT_URL_S3", "AWS_ENDPOINT_URL");
  while (!endpoint.empty() && endpoint.back() == '/') endpoint.pop_back();
  target.url = endpoint.empty() ? "https://" + bucket + ".s3." + region + ".amazonaws.com/" + key
                                : endpoint + "/" + bucket + "/" + key;
  const std::string id = environment("AWS_ACCESS_KEY_ID"), secret = environment("AWS_SECRET_ACCESS_KEY");
  if (id.empty() != secret.empty())
    throw Error(ErrorClass::InvalidArgument,
                path + ": AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY must be set together (only " +
                    (id.empty() ? "AWS_SECRET_ACCESS_KEY" : "AWS_ACCESS_KEY_ID") + " is)");
  if (id.empty()) return target;  // a public bucket: unsigned requests
  target.aws_sigv4 = "aws:amz:" + region + ":s3";
  target.credentials = id + ":" + secret;
  // S3 wants the payload's hash with every signed request; a GET has none.
  // Sent explicitly because libcurl before 8.1 does not add it.
  target.headers.push_back("x-amz-content-sha256: e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  if (const std::string token = environment("AWS_SESSION_TOKEN"); !token.empty())
    target.headers.push_back("x-amz-security-token: " + token);
  return target;
}

}  // namespace ivol::detail
