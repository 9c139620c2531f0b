"""Per-frame cost of calling voxpan from Python vs the Rust pipeline, on the same frames.

    python bindings/python/examples/bench_overhead.py [DATASET] [--cli target/release/voxpan]

Python: each frame's refine, fill_holes and integrate calls (frames decoded beforehand), timed
around the call, so array conversion, copies and GIL hand-over are included. Rust: the same
frames through `voxpan run` (median ms per stage from its metrics.json). Also, exactly: the
integrate call's wall time vs the time voxpan measured inside the same call (track_ms +
integrate_ms of its report), i.e. the binding's own overhead. Build both optimised
(`pip install ./bindings/python`, `cargo build --release -p voxpan`).
"""

import argparse
import json
import pathlib
import statistics
import subprocess
import tempfile
import time

import voxpan

REPO = pathlib.Path(__file__).resolve().parents[3]


def median(xs):
    # The pipeline's median: the upper middle for an even count.
    return sorted(xs)[len(xs) // 2]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", nargs="?", default=REPO.parent / "shared" / "data" / "flat")
    ap.add_argument("--cli", default=REPO / "target" / "release" / "voxpan")
    args = ap.parse_args()

    ds = voxpan.open_dataset(args.dataset)
    frames = list(ds)
    times = {"refine": [], "trim": [], "fill": [], "integrate": [], "inside": []}
    m = voxpan.PanopticMap(class_names=ds.class_names)
    start = time.perf_counter()
    for f in frames:
        t0 = time.perf_counter()
        labels, _ = voxpan.trim_stuff_planes(f["depth"], f["labels"], f["segments"])
        t_trimmed = time.perf_counter()
        labels, _ = voxpan.refine(f["depth"], labels, segments=f["segments"])
        t1 = time.perf_counter()
        depth = voxpan.fill_holes(f["depth"], k=5)
        t2 = time.perf_counter()
        report = m.integrate(depth, f["color"], f["intrinsics"], f["pose"],
                             labels=labels, segments=f["segments"])
        t3 = time.perf_counter()
        times["trim"].append((t_trimmed - t0) * 1e3)
        times["refine"].append((t1 - t_trimmed) * 1e3)
        times["fill"].append((t2 - t1) * 1e3)
        times["integrate"].append((t3 - t2) * 1e3)
        times["inside"].append(report["track_ms"] + report["integrate_ms"])
    python_s = time.perf_counter() - start

    ids = [int(i) for i in ds.frame_ids]
    with tempfile.TemporaryDirectory() as out:
        subprocess.run([str(args.cli), "run", str(args.dataset), "--out", out,
                        "--frames", f"{min(ids)}:{max(ids)}"], check=True, capture_output=True)
        rust = json.loads((pathlib.Path(out) / "metrics.json").read_text())["report"]
    stage = rust["stage_ms"]

    n = len(frames)
    print(f"{n} frames, {m.block_count} blocks (voxpan run: {rust['blocks']})")
    print(f"{'stage':<10} {'Python call':>12} {'Rust pipeline':>14} {'difference':>11}")
    rows = [("refine", median(times["refine"]), stage["refine"]),
            ("trim", median(times["trim"]), stage["trim"]),
            ("fill", median(times["fill"]), stage["fill"]),
            ("integrate", median(times["integrate"]), stage["track"] + stage["integrate"])]
    for name, py, rs in rows:
        print(f"{name:<10} {py:>9.2f} ms {rs:>11.2f} ms {100 * (py - rs) / rs:>+10.1f}%")
    py_total = sum(r[1] for r in rows)
    rs_total = sum(r[2] for r in rows)
    print(f"{'total':<10} {py_total:>9.2f} ms {rs_total:>11.2f} ms "
          f"{100 * (py_total - rs_total) / rs_total:>+10.1f}%")
    over = [w - i for w, i in zip(times["integrate"], times["inside"])]
    print(f"integrate: binding overhead {median(over):.3f} ms/frame (median of wall - voxpan's own "
          f"time; {100 * median(over) / median(times['inside']):.1f}% of "
          f"{median(times['inside']):.2f} ms)")
    print(f"frames/s: Python loop {n / python_s:.1f} (sequential), voxpan run {rust['fps']:.1f} "
          "(perception on a worker thread, overlapped with integration)")
    print(f"stdev of the Python integrate call: {statistics.stdev(times['integrate']):.2f} ms")


if __name__ == "__main__":
    main()
