#!/usr/bin/env python3
"""A small HTTP server for ivol's remote-read tests: serves one folder, with
byte ranges (206 + Content-Range), an ETag per file version and If-Match
(412 when the file changed), as object stores and nginx do; counts requests
and bytes sent per file in COUNTS (JSON, rewritten after every request).

    range_http_server.py FOLDER PORT_FILE COUNTS [--no-ranges] [--change-after N]

Writes the port it listens on (127.0.0.1) into PORT_FILE. --no-ranges: a
server that ignores Range and sends whole files (200). --change-after N:
from request N+1 on, every file has a new ETag, as if replaced."""
import http.server
import json
import os
import re
import sys
import threading

folder, port_file, counts_file = sys.argv[1:4]
ranges = "--no-ranges" not in sys.argv
change_after = int(sys.argv[sys.argv.index("--change-after") + 1]) if "--change-after" in sys.argv else None
served = [0]
counts = {}
lock = threading.Lock()


class Handler(http.server.BaseHTTPRequestHandler):
    def log_message(self, *args):
        pass

    def do_GET(self):
        path = os.path.join(folder, os.path.basename(self.path.lstrip("/")))
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
        wanted = re.fullmatch(r"bytes=(\d+)-(\d*)", self.headers.get("Range", ""))
        if ranges and wanted:
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
