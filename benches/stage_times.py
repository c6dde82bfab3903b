#!/usr/bin/env python3
"""Pipeline stage times of uncached tiles, as a running `sylva serve` reports
them in `Server-Timing`: requests the N `cem` tiles of a level nearest the
region's centre, once each, and prints the median latency and the median of
every stage. Start the server on an empty cache first.

    python3 benches/stage_times.py http://127.0.0.1:8080 10 50
"""
import json
import statistics
import sys
import time
import urllib.request


def nearest_tiles(tileset, level, n):
    west, south, east, north = tileset["bounds"]
    d = tileset["level0_delta_deg"] / 2**level
    row = lambda lat: int((lat + 90) // d)
    col = lambda lon: int((lon + 180) // d)
    r0, c0 = row((south + north) / 2), col((west + east) / 2)
    tiles = [(r, c) for r in range(row(south), row(north) + 1) for c in range(col(west), col(east) + 1)]
    return sorted(tiles, key=lambda t: (t[0] - r0) ** 2 + (t[1] - c0) ** 2)[:n]


def main(base, level, n):
    tileset = json.load(urllib.request.urlopen(f"{base}/tiles.json"))
    latency, stages = [], {}
    for r, c in nearest_tiles(tileset, level, n):
        start = time.perf_counter()
        with urllib.request.urlopen(f"{base}/tiles/cem/{level}/{r}/{r}_{c}.bil") as reply:
            reply.read()
            timing = reply.headers.get("Server-Timing", "")
        latency.append((time.perf_counter() - start) * 1e3)
        for part in filter(None, (p.strip() for p in timing.split(","))):
            name, _, dur = part.partition(";dur=")
            stages.setdefault(name, []).append(float(dur))
    medians = " ".join(f"{k}={statistics.median(v):.2f}" for k, v in stages.items())
    print(f"level {level}: {len(latency)} tiles, p50 {statistics.median(latency):.2f} ms; stage medians (ms): {medians}")


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]) if len(sys.argv) > 3 else 50)
