#!/usr/bin/env python3
"""Build nrw-etl datasets on a Ray cluster: ingest and style as work units, fanned out.

    python3 pipelines/ray/driver.py SCENE --out DATASET --units 32 [--address auto]
    python3 pipelines/ray/driver.py --scenes LIST --out s3://bucket/corpus/ [--address auto]

With --scenes (a file of scene folders, one a line, or a glob such as '/data/*/'), one
dataset per scene under OUT/NAME (NAME: the scene folder's name), the scenes' pipelines
running at once so their units share the cluster; a scene that fails (after the retries) is
recorded and the others go on. Then OUT/corpus.parquet indexes them, one row per scene:
where its dataset and report are, counts and verdicts, or its error (schemas/corpus.toml;
pyarrow.parquet.read_table or DuckDB's read_parquet read it).

With --densify, the scene is densified first (multi-view stereo into SCENE/dense, which ingest
then renders): `nrw-etl densify --unit i/N --pass photometric` on N tasks, then the same with
`--pass geometric`, then `densify --finalize` (fusion, on one node); the scene folder must be
on a shared file system. A scene that has SCENE/dense/fused.ply already is not densified again.

Steps: `nrw-etl ingest --unit i/N` on N tasks (retried when a task or its node dies; a
retried unit resumes where it stopped), `nrw-etl finalize`, `split`, `style --unit i/N`
on N tasks, `finalize`, `triplets`, `qa`. Every task calls the `nrw-etl` binary, which
must be on each node (same version); the dataset must be where every node can reach it:
an object-store URL (s3://, gs://, az://, credentials from the usual variables) or a
shared file system. The result is byte-identical to `nrw-etl ingest` etc. in one process.
"""

import argparse
import concurrent.futures
import glob
import json
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


# Tasks carry this module's code with them (pickled by value), so `run` and `run_corpus`
# work from any other driver, whose workers cannot import a module named `driver`.
if __name__ != "__main__":
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])


def _record(task_log, **event):
    """Append one attempt's event to the task log (one JSON line; O_APPEND, so lines of
    several nodes on a shared file system do not interleave)."""
    if task_log:
        with open(task_log, "a", encoding="utf-8") as f:
            f.write(json.dumps(event) + "\n")


@ray.remote(num_cpus=1, max_retries=3, retry_exceptions=True)
def nrw_task(binary, args, env, task_log=None):
    """One nrw-etl command on whichever node Ray picks; raises (and Ray retries) on failure.
    With `task_log`, each attempt records where it started and how it ended, so a run can
    show which node ran what and that a retry followed a lost node, not a failed command."""
    full_env = dict(os.environ)
    full_env.update(env)
    node = ray.get_runtime_context().get_node_id()
    _record(task_log, event="start", node=node, args=args, pid=os.getpid())
    done = subprocess.run([binary, *args], env=full_env, capture_output=True, text=True,
                          preexec_fn=_die_with_parent if sys.platform == "linux" else None)
    _record(task_log, event="end", node=node, args=args, pid=os.getpid(), code=done.returncode)
    if done.returncode != 0:
        raise RuntimeError(f"nrw-etl {' '.join(args)} exited {done.returncode}: {done.stderr.strip()}")
    return done.stdout.strip()


def units(binary, stage_args, n, env, task_log=None):
    """Run work units 0..n-1 of a stage and wait for all of them."""
    quiet = [] if "--quiet" in stage_args else ["--quiet"]
    refs = [nrw_task.remote(binary, [*stage_args, "--unit", f"{i}/{n}", *quiet], env, task_log)
            for i in range(n)]
    return ray.get(refs)


def one(binary, args, env, task_log=None):
    """One whole-dataset step (finalize, split, triplets, qa) as a Ray task."""
    return ray.get(nrw_task.remote(binary, args, env, task_log))


def densify(scene, n, binary="nrw-etl", densify_args=(), env=None, log=print, task_log=None):
    """Multi-view stereo into the scene's dense workspace: both passes as N work units each,
    then fusion as one task; the bytes of `nrw-etl densify SCENE` in one process. Returns
    finalize's summary."""
    env = dict(env or {})
    base = ["densify", scene, *densify_args]
    for p in ("photometric", "geometric"):
        log(f"densify, {p} pass: {n} units")
        units(binary, [*base, "--pass", p], n, env, task_log)
    return one(binary, [*base, "--finalize", "--quiet"], env, task_log)


def run(scene, out, n, binary="nrw-etl", val=100, k=20, tier="vgg16-512", weights=None,
        ingest_args=(), env=None, style=True, log=print, task_log=None, densify_args=None):
    """The whole pipeline on the connected Ray cluster; returns the report's location.
    `task_log`: a file every node can append to (a shared file system) where each task
    attempt records its node, command and exit code, as JSON lines. `densify_args` (a list,
    possibly empty): densify the scene first, with these arguments."""
    env = dict(env or {})
    if densify_args is not None:
        if os.path.exists(os.path.join(scene, "dense", "fused.ply")) and "--overwrite" not in densify_args:
            log("densify skipped: the scene has dense/fused.ply already (--densify-arg=--overwrite replaces it)")
        else:
            log(densify(scene, n, binary, densify_args, env, log, task_log) or "densified")
    log(f"ingest: {n} units")
    units(binary, ["ingest", scene, "--out", out, *ingest_args], n, env, task_log)
    log(one(binary, ["finalize", out], env, task_log) or "finalized ingest")
    log(one(binary, ["split", out, "--val", str(val)], env, task_log))
    if style:
        style_args = ["style", out, "--tier", tier]
        if weights:
            style_args += ["--weights", weights]
        log(f"style: {n} units")
        units(binary, style_args, n, env, task_log)
        log(one(binary, ["finalize", out], env, task_log) or "finalized style")
        log(one(binary, ["triplets", out, "--k", str(k)], env, task_log))
    report = one(binary, ["qa", out], env, task_log)
    log(f"dataset: {out}")
    log(f"report:  {report}")
    return report


def join(prefix, name):
    """NAME under a corpus prefix (a folder or an object-store URL)."""
    return prefix.rstrip("/") + "/" + name


def scene_list(spec):
    """Scene folders from a file (one a line; blank lines and # comments skipped) or a glob."""
    if os.path.isfile(spec):
        with open(spec, encoding="utf-8") as f:
            lines = [ln.strip() for ln in f]
        return [ln for ln in lines if ln and not ln.startswith("#")]
    found = sorted(glob.glob(spec))
    if not found:
        raise SystemExit(f"--scenes {spec}: neither a file of scene folders nor a glob matching any")
    return found


def names_of(scenes):
    """A dataset name per scene: its folder's name, -2, -3 … when two share one."""
    seen, out = {}, []
    for s in scenes:
        base = os.path.basename(os.path.normpath(s)) or "scene"
        seen[base] = seen.get(base, 0) + 1
        out.append(base if seen[base] == 1 else f"{base}-{seen[base]}")
    return out


def failure(e):
    """The failing command's own message from a task's exception (Ray wraps it)."""
    cause = getattr(e, "cause", None)
    return str(cause if cause is not None else e).strip()


def run_corpus(scenes, out, n, binary="nrw-etl", parallel=None, log=print, **kw):
    """One dataset per scene under OUT, the scenes' pipelines at once (`parallel` at a
    time, default all), then OUT/corpus.parquet; returns the index's rows as printed."""
    names = names_of(scenes)
    env = dict(kw.get("env") or {})

    def one_scene(scene, name):
        try:
            run(scene, join(out, name), n, binary=binary, log=lambda m: log(f"[{name}] {m}"), **kw)
            return None
        except Exception as e:  # noqa: BLE001 (a scene's failure is data for the index)
            log(f"[{name}] failed: {failure(e)}")
            return failure(e)

    with concurrent.futures.ThreadPoolExecutor(max_workers=parallel or len(scenes) or 1) as pool:
        errors = list(pool.map(one_scene, scenes, names))
    entries = [{"scene": s, "name": m, "dataset": join(out, m), "error": e}
               for s, m, e in zip(scenes, names, errors)]
    printed = one(binary, ["corpus", out, "--entries", json.dumps(entries)], env, kw.get("task_log"))
    log(printed)
    log(f"corpus index: {join(out, 'corpus.parquet')}")
    return printed


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", nargs="?", help="COLMAP scene folder, readable on every node")
    p.add_argument("--scenes", help="many scenes: a file of scene folders (one a line) or a glob")
    p.add_argument("--out", required=True,
                   help="dataset (with --scenes: the corpus prefix): s3://bucket/prefix, gs://, az://, or a shared folder")
    p.add_argument("--units", type=int, default=None, help="work units per stage [default: the cluster's CPUs]")
    p.add_argument("--parallel", type=int, default=None, help="with --scenes: scenes at once [default: all]")
    p.add_argument("--address", default=None, help="Ray cluster address [default: a local Ray]")
    p.add_argument("--binary", default="nrw-etl", help="nrw-etl on every node [default: from PATH]")
    p.add_argument("--val", type=int, default=100, help="validation photos (the paper: 100)")
    p.add_argument("--k", type=int, default=20, help="triplet neighbours (the paper: 20)")
    p.add_argument("--tier", default="vgg16-512", help="style tier (color-stats needs no weights)")
    p.add_argument("--weights", default=None, help="VGG16 safetensors, readable on every node")
    p.add_argument("--ingest-arg", action="append", default=[], help="extra ingest argument (repeat)")
    p.add_argument("--densify", action="store_true",
                   help="densify the scene first (multi-view stereo into SCENE/dense, on a shared file system)")
    p.add_argument("--densify-arg", action="append", default=[],
                   help="extra densify argument (repeat), e.g. --densify-arg=--max-image-size=640")
    p.add_argument("--task-log", default=None,
                   help="append each task attempt (node, command, exit code) to this file, as JSON lines")
    a = p.parse_args(argv)
    if (a.scene is None) == (a.scenes is None):
        p.error("give one SCENE or --scenes LIST")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    ray.init(address=a.address)
    n = a.units or max(1, int(ray.cluster_resources().get("CPU", 1)))
    settings = dict(val=a.val, k=a.k, tier=a.tier, weights=a.weights, ingest_args=a.ingest_arg,
                    task_log=a.task_log, densify_args=a.densify_arg if a.densify else None)
    if a.scenes:
        run_corpus(scene_list(a.scenes), a.out, n, a.binary, a.parallel, **settings)
    else:
        run(a.scene, a.out, n, a.binary, **settings)
    return 0


if __name__ == "__main__":
    sys.exit(main())
