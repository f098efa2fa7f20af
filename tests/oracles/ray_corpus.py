#!/usr/bin/env python3
"""A driver of its own that calls the Ray driver's `run_corpus` (called by tests/ray.rs).

    python3 tests/oracles/ray_corpus.py DRIVER_PY OUT BINARY SCENE... [-- INGEST_ARG ...]

Loads pipelines/ray/driver.py from its path under another module name (so Ray's workers
could not import it: the tasks must carry its code), starts a cluster of a 0-CPU head and
two 1-CPU worker nodes, runs the scenes into OUT, and kills one worker node (SIGKILL) once an
ingest unit running on it has recorded a group: the task log must show that unit cut off
there and run again elsewhere, and only the broken scene's commands failing.
"""

import importlib.util
import os
import sys
import threading

os.environ["RAY_USAGE_STATS_ENABLED"] = "0"

import ray  # noqa: E402
from ray.cluster_utils import Cluster  # noqa: E402


def load_driver(path):
    spec = importlib.util.spec_from_file_location("nrw_corpus_test_driver", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def load_harness(driver_py):
    """pipelines/ray/test_driver.py (beside the driver): its kill and task-log checks."""
    spec = importlib.util.spec_from_file_location(
        "nrw_ray_test_driver", os.path.join(os.path.dirname(driver_py), "test_driver.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main():
    args = sys.argv[1:]
    ingest_args = []
    if "--" in args:
        ingest_args = args[args.index("--") + 1:]
        args = args[:args.index("--")]
    driver_py, out, binary, *scenes = args
    driver = load_driver(driver_py)
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0})
    doomed = cluster.add_node(num_cpus=1)
    cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    ray.init(address=cluster.address, logging_level="ERROR", log_to_driver=False)
    killed = threading.Event()
    harness = load_harness(driver_py)
    task_log = os.path.join(os.path.dirname(os.path.abspath(out)), "ray-corpus-tasks.jsonl")
    threading.Thread(target=harness.kill_mid_task, args=(cluster, doomed, task_log, killed), daemon=True).start()
    try:
        driver.run_corpus(scenes, out, 4, binary=binary, val=2, k=3, tier="color-stats",
                          ingest_args=ingest_args, log=lambda m: print(m, flush=True), task_log=task_log)
    finally:
        ray.shutdown()
        cluster.shutdown()
    if not killed.is_set():
        print("the worker node was never killed", file=sys.stderr)
        return 1
    # Only the broken scene's commands may fail (each retried, none succeeding after).
    broken = [s for s in scenes if "broken" in os.path.basename(os.path.normpath(s))]
    print(harness.check_task_log(task_log, doomed.node_id, failing=broken), flush=True)
    print("node killed mid-run; every scene ran", flush=True)
    try:
        import pyarrow.parquet as pq
        t = pq.read_table(os.path.join(out, "corpus.parquet"))
        print("pyarrow read", t.num_rows, "rows:", t.column("status").to_pylist(), flush=True)
    except ImportError:
        print("pyarrow not installed: index read by the Rust test only", flush=True)
    try:
        import duckdb
        q = f"select name, status from read_parquet('{os.path.join(out, 'corpus.parquet')}') order by name"
        print("duckdb read:", duckdb.sql(q).fetchall(), flush=True)
    except ImportError:
        print("duckdb not installed", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
