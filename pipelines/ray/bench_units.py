#!/usr/bin/env python3
"""Time N ingest units through Ray's task API on a local Ray with C CPUs (called by
`cargo bench -p nrw-etl --bench store_and_ray`): prints the seconds from submitting the
first task to the last result, Ray's startup excluded.

    python3 pipelines/ray/bench_units.py SCENE OUT BINARY N CPUS [INGEST_ARG ...]
"""

import os
import sys
import time

os.environ["RAY_USAGE_STATS_ENABLED"] = "0"

import ray  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import driver  # noqa: E402


def main():
    scene, out, binary, n, cpus, *extra = sys.argv[1:]
    ray.init(num_cpus=int(cpus), logging_level="ERROR", log_to_driver=False)
    ray.get(driver.nrw_task.remote(binary, ["--version"], {}))  # warm a worker
    t = time.perf_counter()
    driver.units(binary, ["ingest", scene, "--out", out, *extra], int(n), {})
    print(f"{time.perf_counter() - t:.3f}")
    ray.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
