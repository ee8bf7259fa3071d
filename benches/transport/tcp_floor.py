#!/usr/bin/env python3
"""The floor under any ROS 1 egress figure: one-way latency of a payload over loopback TCP between
two processes, with nothing but the kernel's copies (send buffer, receive buffer, no
serialization, the receiver's buffer allocated once).

    python3 benches/transport/tcp_floor.py [--bytes 6957360] [--count 100] [--rate 20]

The sender stamps CLOCK_MONOTONIC into the first 8 bytes just before `sendall`; the receiver reads
the whole payload into one preallocated buffer and takes the difference. Both sockets use
TCP_NODELAY, as the bridge and roscpp's `tcp_nodelay` do. The default payload is a 1920x1208 rgb8
image. Prints p50 / p99 / min in milliseconds.
"""
import argparse
import os
import socket
import struct
import time


def receive(conn, n, count, out):
    buf = bytearray(n)
    mv = memoryview(buf)
    lat = []
    for _ in range(count):
        got = 0
        while got < n:
            r = conn.recv_into(mv[got:], n - got)
            if r == 0:
                raise SystemExit("sender closed early")
            got += r
        lat.append((time.clock_gettime_ns(time.CLOCK_MONOTONIC) - struct.unpack_from("<q", buf)[0]) / 1e6)
    os.write(out, (" ".join(f"{x:.4f}" for x in lat)).encode())


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bytes", type=int, default=1920 * 1208 * 3)
    ap.add_argument("--count", type=int, default=100)
    ap.add_argument("--rate", type=float, default=20.0)
    a = ap.parse_args()
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    port = srv.getsockname()[1]
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        conn, _ = srv.accept()
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        receive(conn, a.bytes, a.count, w)
        os._exit(0)
    os.close(w)
    s = socket.create_connection(("127.0.0.1", port))
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    payload = bytearray(a.bytes)
    for _ in range(a.count):
        struct.pack_into("<q", payload, 0, time.clock_gettime_ns(time.CLOCK_MONOTONIC))
        s.sendall(payload)
        time.sleep(1.0 / a.rate)
    chunks = []
    while True:
        c = os.read(r, 1 << 16)
        if not c:
            break
        chunks.append(c)
    os.waitpid(pid, 0)
    lat = sorted(float(x) for x in b"".join(chunks).split())
    p = lambda q: lat[min(len(lat) - 1, int(q * len(lat)))]
    print(f"loopback TCP, {a.bytes} bytes, {len(lat)} messages | p50 {p(0.5):.2f} ms | p99 {p(0.99):.2f} ms | min {lat[0]:.2f} ms")


if __name__ == "__main__":
    main()
