"""Views per second through nrw.Dataset against the pure-Python decode of the same shards
(pyarrow + Pillow + OpenEXR, tests/reference.py), one core each, and through a PyTorch
DataLoader with 2 workers over each; peak memory beside every figure.

    python3 python/bench.py DATASET [DATASET ...] [--passes 3] [--repeat 5] [--out docs/bench/python.md]

Each case runs in its own process (pinned to one core for the one-core cases, with
RAYON_NUM_THREADS=1); a case reads every view of the dataset `passes` times and the best pass
counts. The DataLoader cases need torch; without it they are left out and the report says so.
Build the package optimised first (`pip install ./python`): a `--profile dev` build measures
the unoptimised decoder.
"""

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
# The installed package, not its sources beside this script (they lack the compiled half).
sys.path = [p for p in sys.path if os.path.abspath(p or ".") != HERE]


def cpu():
    """Model name and the SIMD flags that matter for the figures."""
    model, flags = platform.processor() or "unknown", set()
    with open("/proc/cpuinfo") as f:
        for line in f:
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
            elif line.startswith("flags"):
                flags = set(line.split(":", 1)[1].split())
    wanted = ["sse4_2", "avx", "avx2", "fma", "avx512f", "avx512bw", "avx512_vnni"]
    return model, [f for f in wanted if f in flags], os.cpu_count()


# --- the readers measured (run inside the case's process) -----------------------------------

def nrw_views(root, repeat, ids=None):
    import nrw

    ds = nrw.Dataset(root)
    for _ in range(repeat):
        for v in ds.views(ids=ids) if ids is not None else ds.views():
            yield v["image_id"], v


def python_views(root, repeat, ids=None):
    sys.path.insert(0, os.path.join(HERE, "tests"))
    import pyarrow.parquet as pq

    import reference

    wanted = None if ids is None else set(ids)
    for _ in range(repeat):
        for path in reference.shard_paths(root):
            for row in pq.read_table(path).to_pylist():
                if wanted is None or row["image_id"] in wanted:
                    yield row["image_id"], reference.decode(row)


READERS = {"nrw": nrw_views, "python": python_views}


def loader_views(reader, root, repeat, workers):
    import torch
    from torch.utils.data import DataLoader, IterableDataset, get_worker_info

    import nrw

    ids = nrw.Dataset(root).ids()

    class Views(IterableDataset):
        def __iter__(self):
            info = get_worker_info()
            k, n = (info.id, info.num_workers) if info else (0, 1)
            for image_id, view in READERS[reader](root, repeat, ids[k::n]):
                yield {key: torch.from_numpy(v) for key, v in view.items() if hasattr(v, "dtype")}

    for item in DataLoader(Views(), batch_size=None, num_workers=workers):
        yield item


def run_case(case, root, passes, repeat):
    """Inside the case's process: best views/s over `passes` passes."""
    reader, _, workers = case.partition(":")
    best, count = 0.0, 0
    for _ in range(passes):
        t = time.perf_counter()
        views = loader_views(reader, root, repeat, int(workers)) if workers else READERS[reader](root, repeat)
        count = sum(1 for _ in views)
        best = max(best, count / (time.perf_counter() - t))
    self_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    child_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    print(json.dumps({"views": count, "per_s": best, "rss_mb": self_kb / 1024,
                      "worker_rss_mb": child_kb / 1024}))


def measure(case, root, passes, repeat, one_core):
    env = dict(os.environ)
    cmd = [sys.executable, __file__, "--case", case, "--passes", str(passes), "--repeat", str(repeat), root]
    if one_core:
        env["RAYON_NUM_THREADS"] = "1"
        cmd = ["taskset", "-c", "0", *cmd]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"{case} on {root} failed:\n{out.stderr}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("datasets", nargs="+")
    p.add_argument("--passes", type=int, default=3)
    p.add_argument("--repeat", type=int, default=5, help="reads of every view in one pass (a DataLoader starts its workers once a pass)")
    p.add_argument("--out", default=os.path.join(HERE, "..", "docs", "bench", "python.md"))
    p.add_argument("--case", help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.case:
        return run_case(a.case, a.datasets[0], a.passes, a.repeat)
    # Asked of a child: this process stays small, as a child's peak memory counts from its
    # parent's (Linux keeps the high-water mark across exec).
    have_torch = subprocess.run([sys.executable, "-c", "import torch"], capture_output=True).returncode == 0
    where = subprocess.run([sys.executable, "-c", "import nrw, os; print(os.path.dirname(nrw.__file__))"],
                           capture_output=True, text=True, cwd="/").stdout.strip()
    model, flags, cores = cpu()
    cases = [("nrw, 1 core", "nrw", True), ("pure Python, 1 core", "python", True),
             (f"nrw, {cores} cores", "nrw", False)]
    if have_torch:
        cases += [("nrw, DataLoader 2 workers", "nrw:2", False),
                  ("pure Python, DataLoader 2 workers", "python:2", False)]
    lines = [
        "# Python reader: views per second",
        "",
        "Made by `python3 python/bench.py " + " ".join(os.path.basename(d.rstrip("/")) for d in a.datasets)
        + f" --passes {a.passes} --repeat {a.repeat}` (full paths elided).",
        f"Machine: {model}, {cores} cores, flags {' '.join(flags)}; Python {platform.python_version()},"
        f" nrw extension at {where}.",
        "A view is every payload decoded (photo, render, depth, and normals, semantics, labels,"
        f" transient when present); a pass reads every view {a.repeat} times (a DataLoader's"
        " workers start once a pass). Best of the passes; peak RSS of the process (and of its"
        " busiest DataLoader worker). Views column: views a pass reads.",
        "",
        "| dataset | views | reader | views/s | × pure Python (1 core) | peak MB | worker peak MB |",
        "|---|---|---|---|---|---|---|",
    ]
    for root in a.datasets:
        results = {label: measure(case, root, a.passes, a.repeat, one) for label, case, one in cases}
        base = results["pure Python, 1 core"]["per_s"]
        for label, r in results.items():
            worker = f"{r['worker_rss_mb']:.0f}" if ":" in dict((l, c) for l, c, _ in cases)[label] else "–"
            lines.append(f"| {os.path.basename(root.rstrip('/'))} | {r['views']} | {label} | {r['per_s']:.1f} |"
                         f" {r['per_s'] / base:.2f} | {r['rss_mb']:.0f} | {worker} |")
            print(lines[-1], flush=True)
    if not have_torch:
        lines += ["", "The DataLoader rows need torch, which is not installed here."]
    os.makedirs(os.path.dirname(a.out), exist_ok=True)
    with open(a.out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
