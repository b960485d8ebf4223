#!/usr/bin/env python3
"""A small HTTP server for ivol's remote-read tests: serves one folder, with
byte ranges (206 + Content-Range), an ETag per file version and If-Match
(412 when the file changed), as object stores and nginx do; counts requests
and bytes sent per file in COUNTS (JSON, rewritten after every request).

    range_http_server.py FOLDER PORT_FILE COUNTS [--no-ranges] [--change-after N]
        [--drop N] [--busy N] [--forbid NAME] [--sigv4 KEY_ID:SECRET:REGION[:TOKEN]] [--delay-ms MS]
        [--single-range]

Writes the port it listens on (127.0.0.1) into PORT_FILE. --no-ranges: a
server that ignores Range and sends whole files (200). --change-after N:
from request N+1 on, every file has a new ETag, as if replaced. --drop N:
the first N range responses stop after half their body and close the
connection. --busy N: the first N requests get 503. --forbid NAME: 403 for
that file. --sigv4: every request must carry an AWS Signature Version 4
for these credentials, checked with botocore's signer (an implementation
independent of libcurl's); otherwise 403, as S3 answers. Paths may be
path-style S3 (/BUCKET/KEY): the file served is KEY's last part. --delay-ms:
every response waits MS milliseconds first, a round trip to a distant
store (bench/remote_reads.sh). HEAD is answered too (HDF5's ROS3 driver
asks for the size with it). A request for several ranges gets them as
multipart/byteranges, as from nginx (and the Server header starts with
"nginx", which is how ivol knows to ask); --single-range: the whole file
(200) instead, as S3 answers (Server: AmazonS3)."""
import hmac
import http.server
import json
import os
import re
import socket
import sys
import threading
import time


def option(name, default=None):
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


folder, port_file, counts_file = sys.argv[1:4]
ranges = "--no-ranges" not in sys.argv
change_after = int(option("--change-after")) if "--change-after" in sys.argv else None
drops_left = [int(option("--drop", 0))]
busy_left = [int(option("--busy", 0))]
forbidden = option("--forbid")
sigv4 = option("--sigv4", "").split(":") if "--sigv4" in sys.argv else None
delay = float(option("--delay-ms", 0)) / 1000
several = "--single-range" not in sys.argv
served = [0]
counts = {}
lock = threading.Lock()


def signature_valid(headers, path):
    """Recomputes the request's SigV4 signature with botocore, over the
    headers the request says it signed, and compares."""
    from botocore.auth import S3SigV4Auth
    from botocore.awsrequest import AWSRequest
    from botocore.credentials import Credentials

    key_id, secret, region = sigv4[:3]
    token = sigv4[3] if len(sigv4) > 3 else None
    found = re.fullmatch(r"AWS4-HMAC-SHA256 Credential=([^/]+)/(\d{8})/([^/]+)/s3/aws4_request,\s*"
                         r"SignedHeaders=([^,]+),\s*Signature=([0-9a-f]{64})", headers.get("Authorization", ""))
    if not found or found.group(1) != key_id or found.group(3) != region:
        return False
    names = found.group(4).split(";")
    if "host" not in names or "x-amz-date" not in names or "x-amz-content-sha256" not in names:
        return False
    if token is not None and ("x-amz-security-token" not in names or headers.get("x-amz-security-token") != token):
        return False
    signed = {name: headers.get(name) for name in names}
    if None in signed.values() or not headers["x-amz-date"].startswith(found.group(2)):
        return False
    request = AWSRequest(method="GET", url="http://" + headers["Host"] + path, headers=signed)
    request.context["timestamp"] = headers["x-amz-date"]
    signer = S3SigV4Auth(Credentials(key_id, secret, token), "s3", region)
    expected = signer.signature(signer.string_to_sign(request, signer.canonical_request(request)), request)
    return hmac.compare_digest(expected, found.group(5))


class Handler(http.server.BaseHTTPRequestHandler):
    server_version = ("nginx" if several else "AmazonS3") + " (ivol test server)"
    sys_version = ""

    def log_message(self, *args):
        pass

    def do_HEAD(self):
        self.do_GET(head=True)

    def do_GET(self, head=False):
        if delay:
            time.sleep(delay)
        path = os.path.join(folder, os.path.basename(self.path.split("?")[0].rstrip("/")))
        with lock:
            busy = busy_left[0] > 0
            busy_left[0] -= busy
        if busy:
            self.send_error(503)
            return
        if sigv4 is not None and not signature_valid(self.headers, self.path):
            self.send_error(403, "SignatureDoesNotMatch")
            return
        if forbidden is not None and os.path.basename(path) == forbidden:
            self.send_error(403)
            return
        if not os.path.isfile(path):
            self.send_error(404)
            return
        stat = os.stat(path)
        with lock:
            served[0] += 1
            replaced = change_after is not None and served[0] > change_after
        etag = '"%x-%x%s"' % (stat.st_mtime_ns, stat.st_size, "-new" if replaced else "")
        match = self.headers.get("If-Match")
        if match is not None and match != etag:
            self.send_error(412)
            return
        size = stat.st_size
        asked = self.headers.get("Range", "")
        wanted = re.fullmatch(r"bytes=(\d+)-(\d*)", asked)
        many = re.fullmatch(r"bytes=\d+-\d+(,\d+-\d+)+", asked) if several else None
        if head:
            self.send_response(200)
            self.send_header("Content-Length", str(size))
            self.send_header("ETag", etag)
            self.send_header("Accept-Ranges", "bytes")
            self.end_headers()
            return
        if ranges and many:
            boundary = "ivol-test-boundary-%d" % served[0]
            body = b""
            with open(path, "rb") as f:
                for first, last in (map(int, r.split("-")) for r in asked[6:].split(",")):
                    last = min(last, size - 1)
                    f.seek(first)
                    body += ("\r\n--%s\r\nContent-Type: application/octet-stream\r\n"
                             "Content-Range: bytes %d-%d/%d\r\n\r\n" % (boundary, first, last, size)).encode()
                    body += f.read(last + 1 - first)
            body += ("\r\n--%s--\r\n" % boundary).encode()
            self.send_response(206)
            self.send_header("Content-Type", "multipart/byteranges; boundary=" + boundary)
        elif ranges and wanted:
            begin = int(wanted.group(1))
            end = min(int(wanted.group(2)) if wanted.group(2) else size - 1, size - 1)
            if begin >= size:
                self.send_response(416)
                self.send_header("Content-Range", "bytes */%d" % size)
                self.end_headers()
                return
            # Only the range is read: files of hundreds of MiB are served too.
            with open(path, "rb") as f:
                f.seek(begin)
                body = f.read(end + 1 - begin)
            self.send_response(206)
            self.send_header("Content-Range", "bytes %d-%d/%d" % (begin, end, size))
        else:
            with open(path, "rb") as f:
                body = f.read()
            self.send_response(200)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("ETag", etag)
        self.end_headers()
        with lock:
            drop = ranges and wanted is not None and drops_left[0] > 0
            drops_left[0] -= drop
        if drop:
            # A connection lost mid-block: half the body, then the end.
            self.wfile.write(body[: len(body) // 2])
            self.wfile.flush()
            self.connection.shutdown(socket.SHUT_RDWR)
            self.close_connection = True
            return
        self.wfile.write(body)
        with lock:
            c = counts.setdefault(os.path.basename(path), {"requests": 0, "bytes": 0})
            c["requests"] += 1
            c["bytes"] += len(body)
            with open(counts_file + ".tmp", "w") as out:
                json.dump(counts, out)
            os.replace(counts_file + ".tmp", counts_file)


class Server(http.server.ThreadingHTTPServer):
    # Readers fetch up to 8 ranges at a time: the default backlog of 5
    # dropped connections (a second's wait for each).
    request_queue_size = 64


server = Server(("127.0.0.1", 0), Handler)
with open(port_file + ".tmp", "w") as out:
    out.write(str(server.server_address[1]))
os.replace(port_file + ".tmp", port_file)
server.serve_forever()
