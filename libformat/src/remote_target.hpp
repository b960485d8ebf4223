// What a remote path becomes for libcurl. http:// and https:// URLs are
// fetched as given (a pre-signed S3 URL carries its signature in its
// query). s3://BUCKET/KEY is an object in an S3-compatible store, located
// and signed from the environment the AWS tools read:
//   AWS_ENDPOINT_URL_S3 or AWS_ENDPOINT_URL  another store (MinIO, Ceph,
//       R2, ...): path-style ENDPOINT/BUCKET/KEY; otherwise AWS's
//       virtual-hosted https://BUCKET.s3.REGION.amazonaws.com/KEY
//   AWS_REGION or AWS_DEFAULT_REGION         the region (us-east-1)
//   AWS_ACCESS_KEY_ID, AWS_SECRET_ACCESS_KEY requests signed with AWS
//       Signature Version 4 (libcurl's); neither set: unsigned requests,
//       for a public bucket
//   AWS_SESSION_TOKEN                        temporary credentials' token
#pragma once

#include <string>
#include <vector>

namespace ivol::detail {

struct RemoteTarget {
  std::string url;                   // what libcurl fetches
  std::string aws_sigv4;             // CURLOPT_AWS_SIGV4; empty: not signed
  std::string credentials;           // CURLOPT_USERPWD, "KEY_ID:SECRET"
  std::vector<std::string> headers;  // sent (and signed) with every request
};

// Throws ivol::Error (invalid-argument) for an s3:// path without a bucket
// or key, or with only one of the two credential variables set.
RemoteTarget resolve_remote_target(const std::string& path);

}  // namespace ivol::detail
