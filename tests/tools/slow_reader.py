#!/usr/bin/env python3
"""How stale the telemetry a slow reader sees is, with Python's `websockets` (pip install
websockets): a reader with a small queue (`max_queue=4`: the library stops reading the socket when
its queue is full, and keeps what it already read in memory) takes 15 messages a second of the
60 Hz telemetry, acknowledging each frame it reads (`--no-ack`: never, as a client written before
`ack`); a fast reader on another connection has the newest frame. Prints how many
frames behind the newest each frame the slow reader read was, after a warm-up.

    python3 tests/tools/slow_reader.py ws://127.0.0.1:8080/ws --seconds 30
"""

import argparse
import asyncio
import json
import statistics
import time

import websockets


async def fast(url, newest, stop):
    async with websockets.connect(url) as ws:
        await ws.send(json.dumps({"type": "subscribe", "id": 1, "streams": ["tip"]}))
        while not stop.is_set():
            try:
                m = json.loads(await asyncio.wait_for(ws.recv(), 1.0))
            except asyncio.TimeoutError:
                continue
            if m.get("type") == "telemetry":
                newest[0] = max(newest[0], m["seq"])
                await ws.send(json.dumps({"type": "ack", "seq": m["seq"]}))


async def slow(url, newest, args):
    behind, frames, errors = [], 0, 0
    async with websockets.connect(url, max_queue=4) as ws:
        await ws.send(json.dumps({"type": "subscribe", "id": 1, "streams": ["tip"]}))
        t0 = time.monotonic()
        k = 0
        while time.monotonic() - t0 < args.seconds:
            k += 1
            await asyncio.sleep(max(0.0, t0 + k / args.rate - time.monotonic()))
            m = json.loads(await ws.recv())
            if m.get("type") == "telemetry":
                frames += 1
                if time.monotonic() - t0 > args.warm:
                    behind.append(newest[0] - m["seq"])
                if not args.no_ack:
                    await ws.send(json.dumps({"type": "ack", "seq": m["seq"]}))
            elif m.get("type") == "error":
                errors += 1
    return behind, frames, errors


async def main():
    p = argparse.ArgumentParser()
    p.add_argument("url")
    p.add_argument("--seconds", type=float, default=30.0)
    p.add_argument("--warm", type=float, default=2.0)
    p.add_argument("--rate", type=float, default=15.0)
    p.add_argument("--no-ack", action="store_true")
    args = p.parse_args()
    newest, stop = [0], asyncio.Event()
    f = asyncio.create_task(fast(args.url, newest, stop))
    await asyncio.sleep(0.5)
    behind, frames, errors = await slow(args.url, newest, args)
    stop.set()
    await f
    print(
        f"websockets {websockets.__version__}, max_queue=4, {args.rate:g} messages/s, "
        f"{'no acks' if args.no_ack else 'each frame acknowledged'}: {frames} frames read in {args.seconds:g} s "
        f"({errors} errors); behind the newest by at most {max(behind)} frames "
        f"({max(behind) / 60:.2f} s at 60 Hz), median {statistics.median(behind):g}, "
        f"last {behind[-1]}"
    )


asyncio.run(main())
