#!/usr/bin/env python3
"""The memory wrong token secrets cost a running `nanopush serve`: a token file with one person,
then wrong secrets for that person's real id (`npt_<id>_<wrong>`, so argon2 runs for each) from
distinct addresses behind a trusted proxy (so the per-address limit does not stop them): 24 one at
a time, then bursts of 400 at once, then 5 s idle. Prints the server's RSS after each.

    python3 tests/tools/failed_checks_rss.py target/release/nanopush
"""

import http.client
import os
import re
import subprocess
import sys
import tempfile
import threading
import time


def rss_mib(pid):
    with open(f"/proc/{pid}/status") as f:
        return int(re.search(r"VmRSS:\s+(\d+)", f.read()).group(1)) // 1024


def attempt(port, token, i):
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    c.request("GET", "/api/status", headers={"Authorization": f"Bearer {token}",
                                              "X-Forwarded-For": f"10.{i // 65536 % 256}.{i // 256 % 256}.{i % 256}"})
    return c.getresponse().status


def main():
    nanopush = os.path.abspath(sys.argv[1])
    d = tempfile.mkdtemp(prefix="nanopush-rss-")
    tokens = os.path.join(d, "tokens")
    out = subprocess.run([nanopush, "token", "add", "alice", "--role", "operator", "--token-file", tokens],
                         capture_output=True, text=True, check=True).stdout
    real = out.strip().splitlines()[-1]
    wrong = f"npt_{real.split('_')[1]}_{'0' * 32}"
    srv = subprocess.Popen([nanopush, "serve", "--port", "0", "--haptic", "none", "--token-file", tokens,
                            "--trusted-proxy", "127.0.0.1", "--data-dir", os.path.join(d, "records")],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    port = int(re.search(r":(\d+)", srv.stdout.readline()).group(1))
    try:
        print(f"start: {rss_mib(srv.pid)} MiB")
        for i in range(24):
            attempt(port, wrong, i)
        print(f"24 failed checks one at a time: {rss_mib(srv.pid)} MiB")
        for burst in range(2):
            codes = []
            ts = [threading.Thread(target=lambda i=i: codes.append(attempt(port, wrong, 1000 + burst * 1000 + i)))
                  for i in range(400)]
            for t in ts:
                t.start()
            for t in ts:
                t.join()
            print(f"burst {burst + 1} of 400 at once ({codes.count(401)} checked, {codes.count(503)} told busy): "
                  f"{rss_mib(srv.pid)} MiB")
        time.sleep(5)
        print(f"5 s idle: {rss_mib(srv.pid)} MiB")
    finally:
        srv.terminate()
        srv.wait()


main()
