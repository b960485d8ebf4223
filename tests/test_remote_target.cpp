// Where an s3:// path goes and how it is signed, from the environment the
// AWS tools read (libformat/src/remote_target.hpp): AWS's virtual-hosted
// URL or an endpoint's path-style one, the key percent-encoded once, the
// SigV4 scope, the session token, and the refusals.
#include <gtest/gtest.h>

#include <cstdlib>

#include "expect_error.hpp"
#include "remote_target.hpp"

namespace ivol::detail {
namespace {

class RemoteTarget : public ::testing::Test {
 protected:
  void SetUp() override {
    for (const char* name : {"AWS_ENDPOINT_URL_S3", "AWS_ENDPOINT_URL", "AWS_REGION", "AWS_DEFAULT_REGION",
                             "AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY", "AWS_SESSION_TOKEN"})
      unsetenv(name);
  }
  void TearDown() override { SetUp(); }
};

TEST_F(RemoteTarget, HttpUrlsAreFetchedAsGivenAndUnsigned) {
  setenv("AWS_ACCESS_KEY_ID", "AKID", 1);
  setenv("AWS_SECRET_ACCESS_KEY", "secret", 1);
  const auto t = resolve_remote_target("https://host/b/x.ivol?X-Amz-Signature=abc");
  EXPECT_EQ(t.url, "https://host/b/x.ivol?X-Amz-Signature=abc");
  EXPECT_TRUE(t.aws_sigv4.empty());
  EXPECT_TRUE(t.headers.empty());
}

TEST_F(RemoteTarget, S3WithoutCredentialsIsAnUnsignedVirtualHostedUrl) {
  const auto t = resolve_remote_target("s3://scans/2026/part 7.ivol");
  EXPECT_EQ(t.url, "https://scans.s3.us-east-1.amazonaws.com/2026/part%207.ivol");
  EXPECT_TRUE(t.aws_sigv4.empty());
}

TEST_F(RemoteTarget, RegionEndpointAndCredentialsComeFromTheEnvironment) {
  setenv("AWS_DEFAULT_REGION", "eu-central-1", 1);
  setenv("AWS_ACCESS_KEY_ID", "AKID", 1);
  setenv("AWS_SECRET_ACCESS_KEY", "s/ecret", 1);
  auto t = resolve_remote_target("s3://scans/a+b.ivol");
  EXPECT_EQ(t.url, "https://scans.s3.eu-central-1.amazonaws.com/a%2Bb.ivol");
  EXPECT_EQ(t.aws_sigv4, "aws:amz:eu-central-1:s3");
  EXPECT_EQ(t.credentials, "AKID:s/ecret");
  ASSERT_EQ(t.headers.size(), 1u);
  EXPECT_EQ(t.headers[0],
            "x-amz-content-sha256: e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");  // SHA-256("")

  setenv("AWS_REGION", "us-west-2", 1);  // AWS_REGION wins over AWS_DEFAULT_REGION
  setenv("AWS_ENDPOINT_URL", "http://127.0.0.1:9000/", 1);
  setenv("AWS_SESSION_TOKEN", "tok", 1);
  t = resolve_remote_target("s3://scans/dir/x.ivol");
  EXPECT_EQ(t.url, "http://127.0.0.1:9000/scans/dir/x.ivol");
  EXPECT_EQ(t.aws_sigv4, "aws:amz:us-west-2:s3");
  ASSERT_EQ(t.headers.size(), 2u);
  EXPECT_EQ(t.headers[1], "x-amz-security-token: tok");

  setenv("AWS_ENDPOINT_URL_S3", "https://minio.example", 1);  // the S3-specific one wins
  EXPECT_EQ(resolve_remote_target("s3://scans/x.ivol").url, "https://minio.example/scans/x.ivol");
}

TEST_F(RemoteTarget, MalformedPathsAndHalfCredentialsAreRefused) {
  for (const char* path : {"s3://", "s3://bucket", "s3://bucket/", "s3:///key"}) {
    const Error e = test::error_of([&] { resolve_remote_target(path); });
    EXPECT_EQ(e.error_class(), ErrorClass::InvalidArgument) << path;
    EXPECT_TRUE(test::contains(e.what(), "s3://BUCKET/KEY")) << e.what();
  }
  setenv("AWS_ACCESS_KEY_ID", "AKID", 1);
  const Error e = test::error_of([] { resolve_remote_target("s3://b/k.ivol"); });
  EXPECT_EQ(e.error_class(), ErrorClass::InvalidArgument);
  EXPECT_TRUE(test::contains(e.what(), "(only AWS_ACCESS_KEY_ID is)")) << e.what();
}

}  // namespace
}  // namespace ivol::detail
