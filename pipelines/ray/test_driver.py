#!/usr/bin/env python3
"""Test of the Ray driver on Ray's own multi-node harness (called by tests/ray.rs).

    python3 pipelines/ray/test_driver.py SCENE OUT BINARY [INGEST_ARG ...]

Starts a cluster of a 0-CPU head and two 1-CPU worker nodes on this machine, runs the
driver into OUT, and, when OUT is a local folder, kills one worker node (raylet and
workers, SIGKILL) once the first ingest group is recorded: its tasks must be retried on
the other node. (OUT may be an object-store URL; the nodes inherit this process's
variables.) The caller compares OUT with a single-process run byte for byte.
"""

import os
import sys
import threading
import time

os.environ["RAY_USAGE_STATS_ENABLED"] = "0"

import ray  # noqa: E402
from ray.cluster_utils import Cluster  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import driver  # noqa: E402


def main():
    scene, out, binary, *ingest_args = sys.argv[1:]
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0})
    doomed = cluster.add_node(num_cpus=1)
    cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    ray.init(address=cluster.address, logging_level="ERROR", log_to_driver=False)
    killed = threading.Event()

    def kill_when_started():
        records = os.path.join(out, ".units", "ingest")
        deadline = time.time() + 300
        while time.time() < deadline:
            if os.path.isdir(records) and any(n.startswith("group-") for n in os.listdir(records)):
                cluster.remove_node(doomed, allow_graceful=False)
                killed.set()
                return
            time.sleep(0.05)

    remote = "://" in out
    if not remote:
        threading.Thread(target=kill_when_started, daemon=True).start()
    try:
        driver.run(scene, out, 4, binary=binary, val=2, k=3, tier="color-stats",
                   ingest_args=ingest_args, log=lambda m: print(m, flush=True))
    finally:
        ray.shutdown()
        cluster.shutdown()
    if remote:
        print("every task completed", flush=True)
        return 0
    if not killed.is_set():
        print("the worker node was never killed", file=sys.stderr)
        return 1
    print("node killed mid-run; every task completed", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
