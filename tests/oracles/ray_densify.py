"""Densify as work units on Ray's multi-node harness (two 1-CPU worker nodes): the driver's
`densify` step, run by tests/ray.rs, which compares the workspace with one process's.

    python3 tests/oracles/ray_densify.py SCENE BINARY UNITS [DENSIFY_ARG ...]
"""

import os
import sys

import ray
from ray.cluster_utils import Cluster

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "pipelines", "ray"))
import driver  # noqa: E402


def main():
    scene, binary, n, *args = sys.argv[1:]
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0})
    for _ in range(2):
        cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    ray.init(address=cluster.address, logging_level="ERROR", log_to_driver=False)
    try:
        print(driver.densify(scene, int(n), binary, args, log=lambda m: print(m, flush=True)), flush=True)
    finally:
        ray.shutdown()
        cluster.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
