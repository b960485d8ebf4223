// A .ivol file on an HTTP(S) server, read with range requests (libcurl), as
// Cloud-Optimized GeoTIFF and Zarr readers read theirs: a slice or a level
// of detail of a large file costs a few requests and a few per cent of its
// bytes, never the whole file.
//
// Reads go through a cache of aligned pages (64 KiB; at most 64 MiB or
// IVOL_HTTP_CACHE_MIB); the pages a read misses are fetched in one request
// per contiguous run. prefetch() fetches the exact ranges a read is about to
// need (the Reader plans them: the blocks a slice, box or level touches),
// ranges less than 16 KiB apart merged into one request, up to 8 requests
// at a time over parallel connections.
// Every response must be a 206 with the asked Content-Range, and the file's
// ETag (or Last-Modified) must not change while it is open (If-Match): a
// server that ignores ranges, or a file replaced under the reader, is an
// error naming the URL, not a silently mixed read. Only http and https are
// followed, redirects included; connections time out after 30 s, stalled
// transfers after 60 s below 1 KiB/s. A dropped connection, a timeout or a
// 429/500/502/503/504 is tried again (IVOL_HTTP_RETRIES times, default 4,
// waiting 0.25 s, doubling, at most 4 s) before it is an error naming the
// attempts. s3:// paths: remote_target.hpp.
#pragma once

#include <memory>
#include <string>

#include "random_access_file.hpp"

namespace ivol::detail {

std::unique_ptr<ByteSource> open_http_source(const std::string& url);

}  // namespace ivol::detail
