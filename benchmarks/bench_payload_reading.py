"""Reading a measurement file with a payload on every sample, against the same file without.

``python benchmarks/bench_payload_reading.py [--samples N] [--repeats R]``

Writes two files of N samples (default 10,000; six joints, one pose each, in metres and
radians), one with ``"payload": {"frame", "mass_kg", "com", "inertia"}`` on every sample,
and times, best of R interleaved runs (default 20; the machine is shared): the JSON parse
(``json.loads``), kinfw's reader on the parsed document (``measurements_from_dict``:
checks, the bulk path, payloads, the unknown-key check) and ``read_measurements`` whole.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from kinfw.measurements import measurements_from_dict, read_measurements


def document(n: int, payload: bool) -> dict:
    """``n`` samples of a pose of ``tool0``; with ``payload``, a load of 0 to 10 kg."""
    rng = np.random.default_rng(0)
    samples = []
    for i in range(n):
        xyz = rng.normal(size=3).tolist()
        pose = {"frame": "tool0", "kind": "pose", "xyz": xyz, "quat_xyzw": [0.0, 0.0, 0.0, 1.0]}
        sample = {"q": rng.normal(size=6).tolist(), "observations": [pose]}
        if payload:
            sample["payload"] = {
                "frame": "tool0",
                "mass_kg": float(i % 11),
                "com": [0.0, 0.0, 0.08],
                "inertia": [0.02, 0.0, 0.0, 0.02, 0.0, 0.01],
            }
        samples.append(sample)
    return {
        "format": "kinfw-measurements",
        "version": 1,
        "units": {"length": "m", "angle": "rad"},
        "joint_names": [f"joint{k}" for k in range(1, 7)],
        "samples": samples,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp())
    paths = {}
    for payload in (False, True):
        paths[payload] = folder / f"payload_{int(payload)}.json"
        paths[payload].write_text(json.dumps(document(args.samples, payload)))
    best = {p: [np.inf, np.inf, np.inf] for p in paths}
    for _ in range(args.repeats):
        for payload, path in paths.items():
            text = path.read_text()
            t0 = time.perf_counter()
            doc = json.loads(text)
            t1 = time.perf_counter()
            measurements_from_dict(doc, source=str(path))
            t2 = time.perf_counter()
            read_measurements(path)
            t3 = time.perf_counter()
            best[payload] = [
                min(b, t) for b, t in zip(best[payload], (t1 - t0, t2 - t1, t3 - t2), strict=True)
            ]
    print(f"{args.samples} samples, best of {args.repeats}")
    header = ("file", "MB", "json.loads ms", "reader ms", "read_measurements ms")
    print(f"{header[0]:<18} {header[1]:>6} {header[2]:>14} {header[3]:>10} {header[4]:>21}")
    for payload, path in paths.items():
        parse, reader, whole = (1e3 * t for t in best[payload])
        name = "payload on each" if payload else "no payload"
        size = path.stat().st_size / 1e6
        print(f"{name:<18} {size:>6.2f} {parse:>14.0f} {reader:>10.0f} {whole:>21.0f}")


if __name__ == "__main__":
    main()
