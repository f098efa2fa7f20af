#!/usr/bin/env python3
"""Test of the Ray driver on Ray's own multi-node harness (called by tests/ray.rs).

    python3 pipelines/ray/test_driver.py SCENE OUT BINARY [INGEST_ARG ...]

Starts a cluster of a 0-CPU head and two 1-CPU worker nodes on this machine, runs the
driver into OUT, and, when OUT is a local folder, kills one worker node (raylet and
workers, SIGKILL) once an ingest unit running on it has recorded a group of its own: the
task log then shows that unit cut off there and run again to exit 0 on the other node, and
no failure of the binary behind a retry. (OUT may be an object-store URL; the nodes inherit this process's
variables.) The caller compares OUT with a single-process run byte for byte.
"""

import collections
import json
import os
import sys
import threading
import time

os.environ["RAY_USAGE_STATS_ENABLED"] = "0"

import ray  # noqa: E402
from ray.cluster_utils import Cluster  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import driver  # noqa: E402


def _doomed_unit_mid_way(task_log, node_id):
    """Whether an ingest unit started on node `node_id` (per the task log) has recorded one of
    its own groups: the node then holds a task that is part-way through."""
    if not os.path.exists(task_log):
        return False
    with open(task_log, encoding="utf-8") as f:
        events = [json.loads(line) for line in f if line.endswith("\n")]
    for e in events:
        args = e["args"]
        if e["event"] != "start" or e["node"] != node_id or args[0] != "ingest":
            continue
        i, n = map(int, args[args.index("--unit") + 1].split("/"))
        records = os.path.join(args[args.index("--out") + 1], ".units", "ingest")
        names = os.listdir(records) if os.path.isdir(records) else []
        groups = [int(m[len("group-"):-len(".json")]) for m in names if m.startswith("group-") and m.endswith(".json")]
        if any(g % n == i for g in groups):
            return True
    return False


def kill_mid_task(cluster, doomed, task_log, killed, seconds=300):
    """SIGKILL the node `doomed` (raylet and workers) once an ingest unit running on it has
    recorded a group of its own, so it dies holding a task part-way through (a node killed
    before any task reached it would test nothing)."""
    deadline = time.time() + seconds
    while time.time() < deadline:
        if _doomed_unit_mid_way(task_log, doomed.node_id):
            cluster.remove_node(doomed, allow_graceful=False)
            killed.set()
            return
        time.sleep(0.05)


def check_task_log(path, doomed, failing=()):
    """What the task log must show after a node was killed: an attempt that started on the
    doomed node and never ended, or ended by a signal as the node went down (its wrapper can
    outlive the child it was killing by a moment and log the signal; either way it held a
    task when the node died), its command run again to
    exit 0 on a surviving node, and no command that exited non-zero except those naming one
    of `failing` (a retry must follow a lost node, never hide a failure of the binary);
    a failing command never later succeeds. Returns a one-line summary."""
    with open(path, encoding="utf-8") as f:
        events = [json.loads(line) for line in f]
    key = lambda e: (e["node"], e["pid"], tuple(e["args"]))  # noqa: E731
    # An end by a signal on the doomed node is the node's death, not the binary's exit.
    killed = lambda e: e["node"] == doomed and e.get("code", 0) < 0  # noqa: E731
    ends = collections.Counter(key(e) for e in events if e["event"] == "end" and not killed(e))
    lost = []
    for e in (e for e in events if e["event"] == "start"):
        if ends[key(e)]:
            ends[key(e)] -= 1
        else:
            lost.append(e)
    cut = [e for e in lost if e["node"] == doomed]
    assert cut, f"no task was running on the killed node {doomed}: {events}"
    assert all(e["node"] == doomed for e in lost), f"attempts lost on a surviving node: {lost}"
    finished = [e for e in events if e["event"] == "end" and not killed(e)]
    expected_failure = lambda e: any(name in " ".join(e["args"]) for name in failing)  # noqa: E731
    for e in cut:
        again = [f for f in finished if f["args"] == e["args"] and f["node"] != doomed
                 and (f["code"] == 0 or expected_failure(e))]
        assert again, f"{e['args']} was lost with the node and never ran again to exit 0"
    failed = [e for e in finished if e["code"] != 0]
    for e in failed:
        assert expected_failure(e), f"the binary failed, hidden by a retry: {e}"
        later = [f for f in finished if f["args"] == e["args"] and f["code"] == 0]
        assert not later, f"{e['args']} failed, then a retry succeeded: {later}"
    return (f"task log: {len(finished)} attempts ended, {len(cut)} cut off on the killed node and "
            f"run again elsewhere, {len(failed)} failed (expected)")


def main():
    scene, out, binary, *ingest_args = sys.argv[1:]
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0})
    doomed = cluster.add_node(num_cpus=1)
    cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    ray.init(address=cluster.address, logging_level="ERROR", log_to_driver=False)
    killed = threading.Event()
    remote = "://" in out
    task_log = os.path.join(os.path.dirname(os.path.abspath(out)), "ray-tasks.jsonl") if not remote else None
    if not remote:
        threading.Thread(target=kill_mid_task, args=(cluster, doomed, task_log, killed), daemon=True).start()
    try:
        driver.run(scene, out, 4, binary=binary, val=2, k=3, tier="color-stats",
                   ingest_args=ingest_args, log=lambda m: print(m, flush=True), task_log=task_log)
    finally:
        ray.shutdown()
        cluster.shutdown()
    if remote:
        print("every task completed", flush=True)
        return 0
    if not killed.is_set():
        print("the worker node was never killed", file=sys.stderr)
        return 1
    print(check_task_log(task_log, doomed.node_id), flush=True)
    print("node killed mid-run; every task completed", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
