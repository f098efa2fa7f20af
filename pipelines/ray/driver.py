#!/usr/bin/env python3
"""Build an nrw-etl dataset on a Ray cluster: ingest and style as work units, fanned out.

    python3 pipelines/ray/driver.py SCENE --out DATASET --units 32 [--address auto]

Steps: `nrw-etl ingest --shard i/N` on N tasks (retried when a task or its node dies; a
retried unit resumes where it stopped), `nrw-etl finalize`, `split`, `style --shard i/N`
on N tasks, `finalize`, `triplets`, `qa`. Every task calls the `nrw-etl` binary, which
must be on each node (same version); the dataset must be where every node can reach it:
an object-store URL (s3://, gs://, az://, credentials from the usual variables) or a
shared file system. The result is byte-identical to `nrw-etl ingest` etc. in one process.
"""

import argparse
import os
import subprocess
import sys

import ray

RAY_VERSION = "2.60.0"


def _die_with_parent():
    """Linux: the nrw-etl process dies with the Ray worker that started it, so a killed task
    leaves no process behind (its retry resumes the unit instead)."""
    try:
        import ctypes
        import signal
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except OSError:
        pass


@ray.remote(num_cpus=1, max_retries=3, retry_exceptions=True)
def nrw_task(binary, args, env):
    """One nrw-etl command on whichever node Ray picks; raises (and Ray retries) on failure."""
    full_env = dict(os.environ)
    full_env.update(env)
    done = subprocess.run([binary, *args], env=full_env, capture_output=True, text=True,
                          preexec_fn=_die_with_parent if sys.platform == "linux" else None)
    if done.returncode != 0:
        raise RuntimeError(f"nrw-etl {' '.join(args)} exited {done.returncode}: {done.stderr.strip()}")
    return done.stdout.strip()


def units(binary, stage_args, n, env):
    """Run work units 0..n-1 of a stage and wait for all of them."""
    quiet = [] if "--quiet" in stage_args else ["--quiet"]
    refs = [nrw_task.remote(binary, [*stage_args, "--shard", f"{i}/{n}", *quiet], env) for i in range(n)]
    return ray.get(refs)


def one(binary, args, env):
    """One whole-dataset step (finalize, split, triplets, qa) as a Ray task."""
    return ray.get(nrw_task.remote(binary, args, env))


def run(scene, out, n, binary="nrw-etl", val=100, k=20, tier="vgg16-512", weights=None,
        ingest_args=(), env=None, style=True, log=print):
    """The whole pipeline on the connected Ray cluster; returns the report's location."""
    env = dict(env or {})
    log(f"ingest: {n} units")
    units(binary, ["ingest", scene, "--out", out, *ingest_args], n, env)
    log(one(binary, ["finalize", out], env) or "finalized ingest")
    log(one(binary, ["split", out, "--val", str(val)], env))
    if style:
        style_args = ["style", out, "--tier", tier]
        if weights:
            style_args += ["--weights", weights]
        log(f"style: {n} units")
        units(binary, style_args, n, env)
        log(one(binary, ["finalize", out], env) or "finalized style")
        log(one(binary, ["triplets", out, "--k", str(k)], env))
    report = one(binary, ["qa", out], env)
    log(f"dataset: {out}")
    log(f"report:  {report}")
    return report


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", help="COLMAP scene folder, readable on every node")
    p.add_argument("--out", required=True, help="dataset: s3://bucket/prefix, gs://, az://, or a shared folder")
    p.add_argument("--units", type=int, default=None, help="work units per stage [default: the cluster's CPUs]")
    p.add_argument("--address", default=None, help="Ray cluster address [default: a local Ray]")
    p.add_argument("--binary", default="nrw-etl", help="nrw-etl on every node [default: from PATH]")
    p.add_argument("--val", type=int, default=100, help="validation photos (the paper: 100)")
    p.add_argument("--k", type=int, default=20, help="triplet neighbours (the paper: 20)")
    p.add_argument("--tier", default="vgg16-512", help="style tier (color-stats needs no weights)")
    p.add_argument("--weights", default=None, help="VGG16 safetensors, readable on every node")
    p.add_argument("--ingest-arg", action="append", default=[], help="extra ingest argument (repeat)")
    a = p.parse_args(argv)
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    ray.init(address=a.address)
    n = a.units or max(1, int(ray.cluster_resources().get("CPU", 1)))
    run(a.scene, a.out, n, a.binary, a.val, a.k, a.tier, a.weights, a.ingest_arg)
    return 0


if __name__ == "__main__":
    sys.exit(main())
