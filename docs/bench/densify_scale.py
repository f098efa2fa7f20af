#!/usr/bin/env python3
"""Densify of a large collection as work units: regenerates docs/bench/densify_scale.md.

    python3 docs/bench/densify_scale.py [--bin target/release/nrw-etl] [--photos 64,256,512]
        [--units 4] [--small-caches-mb 84,40,16,8,3] [--timeout 600]

For each N it makes scenes/many.toml's synthetic collection with N photos (the textured façade
seen by N strangers, a shorter side of 120 px at most), then runs `nrw-etl densify` the way a cluster does:
`--unit I/U --pass photometric` for every I, then `--pass geometric`, then `--finalize`, each
invocation one process under GNU time (wall seconds, peak resident MB) on the machine's
threads. It reports seconds a view of each pass and of fusion, the units' and fusion's peak
memory, fusion's band reads (`fusion read … bands` in finalize's output) and the points, so
that "seconds a view flat in N" and "fusion bounded by its cache" are figures, not claims.

At the largest N fusion runs again on a copy of the finished passes with smaller caches
(`--fusion-cache-mb`, each stopped after --timeout seconds), down to about the share of the
maps' bytes the default 1 GiB holds of the paper's 7,711 views at 0.5 MP, to show what a cache
smaller than the maps costs.

Then one 8-photo collection at about 0.5 MP (scenes/many.toml at 816 px), to price a view at
the paper's size in the same run, and the projection for the paper's 7,711 photos on 1 and
64 machines (each machine one unit at a time on its 2 threads; fusion on one machine).

Not a timed test: a report, with the machine's CPU flags.
"""

import argparse
import os
import platform
import re
import shutil
import struct
import subprocess
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SPEC = os.path.join(ROOT, "scenes", "many.toml")
PAPER_PHOTOS = 7711


def timed(cmd, timeout=None):
    """Run `cmd` under GNU time: (wall s, peak MB, stderr); None past `timeout` seconds."""
    try:
        out = subprocess.run(
            ["/usr/bin/time", "-f", "TIME %e %M"] + cmd,
            capture_output=True,
            text=True,
            timeout=timeout,
        )
    except subprocess.TimeoutExpired:
        return None
    if out.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{out.stderr[-3000:]}")
    m = re.findall(r"TIME ([\d.]+) (\d+)", out.stderr)[-1]
    return float(m[0]), int(m[1]) / 1024.0, out.stderr


def make_scene(binary, work, photos, max_size):
    """scenes/many.toml with `photos` photos whose shorter side is at most `max_size`."""
    text = open(SPEC).read()
    text = re.sub(r"(?m)^count = \d+", f"count = {photos}", text)
    text = re.sub(r"(?m)^min_size = \d+", f"min_size = {max_size * 9 // 10}", text)
    text = re.sub(r"(?m)^max_size = \d+", f"max_size = {max_size}", text)
    spec = os.path.join(work, f"many{photos}_{max_size}.toml")
    open(spec, "w").write(text)
    scene = os.path.join(work, f"many{photos}_{max_size}")
    subprocess.run([binary, "synth", spec, "--out", scene], check=True, capture_output=True)
    return scene


def pixels(scene):
    """Mean pixels a photo (the synthetic photos are PNG: the header's size)."""
    sizes = []
    images = os.path.join(scene, "images")
    for name in sorted(os.listdir(images)):
        with open(os.path.join(images, name), "rb") as f:
            head = f.read(24)
        w, h = struct.unpack(">II", head[16:24])
        sizes.append(w * h)
    return sum(sizes) / len(sizes)


def staging(ws):
    """The folder densify's units build `ws` in until finalize publishes it."""
    return os.path.join(os.path.dirname(ws), "." + os.path.basename(ws) + ".partial")


def run_units(binary, scene, ws, units, keep=False):
    """Both passes as `units` units, then finalize: the timings and what finalize printed.
    With `keep`, a copy of the finished passes is kept for fusing again (`refinalize`)."""
    row = {"photometric": [], "geometric": [], "undistort": 0.0, "ws": ws}
    for pass_ in ("photometric", "geometric"):
        for i in range(units):
            s, mb, err = timed(
                [binary, "densify", scene, "--out", ws, "--unit", f"{i}/{units}", "--pass", pass_]
            )
            u = re.search(r"\(([\d.]+) s of it undistorting", err)
            if u:
                row["undistort"] += float(u.group(1))
            row[pass_].append((s, mb))
    if keep:
        row["passes_copy"] = staging(ws) + ".copy"
        shutil.copytree(staging(ws), row["passes_copy"])
    row["fusion"] = finalize(binary, scene, ws, None)
    return row


def finalize(binary, scene, ws, cache_mb, timeout=None):
    cmd = [binary, "densify", scene, "--out", ws, "--finalize"]
    if cache_mb is not None:
        cmd += ["--fusion-cache-mb", str(cache_mb)]
    done = timed(cmd, timeout)
    if done is None:
        return {"timeout": timeout, "cache_mb": cache_mb}
    s, mb, err = done
    points = int(re.search(r"fused (\d+) points", err).group(1))
    fusing = float(re.search(r"([\d.]+) s fusing", err).group(1))
    reads = re.search(
        r"fusion read (\d+) bands of \d+ rows \((\d+) in (\d+) views\), holding at most ([\d.]+) MiB of their ([\d.]+) MiB",
        err,
    )
    return {
        "wall": s,
        "mb": mb,
        "points": points,
        "fusing": fusing,
        "reads": int(reads.group(1)),
        "bands": int(reads.group(2)),
        "views": int(reads.group(3)),
        "cache_peak": float(reads.group(4)),
        "all_mib": float(reads.group(5)),
        "cache_mb": cache_mb,
    }


def refinalize(binary, scene, row, cache_mb, tag, timeout):
    """Fusion again on a copy of the finished passes, with another cache."""
    ws = row["ws"] + f"_{tag}"
    shutil.copytree(row["passes_copy"], staging(ws))
    return finalize(binary, scene, ws, cache_mb, timeout)


def cpu_flags():
    flags = open("/proc/cpuinfo").read().split("flags")[1].split("\n")[0].split()
    keep = ["avx2", "fma", "avx512f", "avx512bw", "avx512_vnni"]
    return ", ".join(f for f in keep if f in flags)


def cpu_name():
    for line in open("/proc/cpuinfo"):
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return platform.processor()


def share(f, row):
    """The share of the views' map bytes a cache of `f["cache_mb"]` MiB holds."""
    return min(1.0, f["cache_mb"] / row["fusion"]["all_mib"])


def per_view(row, n):
    ph = sum(s for s, _ in row["photometric"]) / n
    ge = sum(s for s, _ in row["geometric"]) / n
    return ph, ge, row["fusion"]["fusing"] / n


def report(args, rows, small, paper, threads):
    lines = [
        "# Densify of a large collection, as work units",
        "",
        "Regenerate: `python3 docs/bench/densify_scale.py "
        f"--bin target/release/nrw-etl --photos {args.photos} --units {args.units}`.",
        "",
        f"Machine: {cpu_name()}; {threads} threads; flags: {cpu_flags()}.",
        "",
        "Scenes: scenes/many.toml (the textured façade, PINHOLE photos 14–24 m away, no "
        f"weather) with N photos whose shorter side is at most {args.size} px; `densify` with its defaults "
        f"(preset `default`) as {args.units} work units a pass, each unit one process run "
        "after the other on this machine (on a cluster, one a machine), then `--finalize`. "
        "Seconds a view = the pass's summed unit seconds (each process timed whole: start, "
        "model, plan, the first unit's undistortion included) over N. Peak memory: GNU time's "
        "maximum resident set of the process.",
        "",
        "| photos N | px a photo | photometric s/view | geometric s/view | fusion s/view | units' peak MB (largest) | finalize peak MB | fused points | fusion band reads / bands | cache held MiB |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n, px, row in rows:
        ph, ge, fu = per_view(row, n)
        unit_mb = max(mb for _, mb in row["photometric"] + row["geometric"])
        f = row["fusion"]
        lines.append(
            f"| {n} | {px:.0f} | {ph:.3f} | {ge:.3f} | {fu:.4f} | {unit_mb:.0f} | "
            f"{f['mb']:.0f} | {f['points']:,} | {f['reads']} / {f['bands']} | {f['cache_peak']:.1f} |"
        )
    (n0, _, r0), (n1, _, r1) = rows[0], rows[-1]
    a, b = per_view(r0, n0), per_view(r1, n1)
    lines += [
        "",
        f"Seconds a view at N = {n1} against N = {n0}: photometric {b[0] / a[0]:.2f}×, "
        f"geometric {b[1] / a[1]:.2f}×, fusion {b[2] / a[2]:.2f}×, both passes and fusion "
        f"{sum(b) / sum(a):.2f}×.",
        "",
        f"### Fusion at N = {n1} with smaller caches",
        "",
        "The same finished passes fused again with `--fusion-cache-mb` set lower. Fusion reads "
        "and holds the maps in bands of 16 rows; the cloud's bytes do not depend on the cache "
        "(a test fuses with a cache of one band and compares bytes); the reads and seconds do.",
        "",
        "| cache MiB | share of the maps' bytes | fusion s | against all held | band reads / bands | cache held MiB | finalize peak MB | points |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for f in [dict(r1["fusion"], cache_mb=1024)] + small:
        held = f"{share(f, r1):.1%}"
        if "timeout" in f:
            lines.append(
                f"| {f['cache_mb']} | {held} | over {f['timeout']} (stopped) | | | | | |"
            )
            continue
        lines.append(
            f"| {f['cache_mb']} | {held} | {f['fusing']:.1f} | "
            f"{f['fusing'] / r1['fusion']['fusing']:.2f}× | {f['reads']} / {f['bands']} | "
            f"{f['cache_peak']:.1f} | {f['mb']:.0f} | {f['points']:,} |"
        )
    lines += projection(rows, paper, small)
    return "\n".join(lines) + "\n"


def projection(rows, paper, small):
    n1, px1, r1 = rows[-1]
    pv = paper["row"]
    n = paper["n"]
    ph, ge, fu = per_view(pv, n)
    stereo = ph + ge
    # Fusion's cost a pixel at the largest N (its walks step into the most views), scaled to
    # the paper's photo size; the 8-photo run's own fusion steps into at most 7 views.
    fu_px = r1["fusion"]["fusing"] / (n1 * px1)
    fu_paper = fu_px * paper["px"]
    # The small cache whose share of these maps' bytes is nearest the share the default 1 GiB
    # holds of the paper's (a view's maps and colour: 19 bytes a pixel).
    paper_share = 1024 / (PAPER_PHOTOS * paper["px"] * 19 / 2**20)
    f_small = min(small, key=lambda f: abs(share(f, r1) - paper_share))
    if "timeout" in f_small:
        thrash = None
        fusion_h = None
    else:
        thrash = f_small["fusing"] / max(r1["fusion"]["fusing"], 1e-9)
        fusion_h = PAPER_PHOTOS * fu_paper * thrash / 3600
    bits_mb = PAPER_PHOTOS * paper["px"] / 8 / 1e6
    pts_view = paper["row"]["fusion"]["points"] / n
    lines = [
        "",
        f"## Projection: the paper's {PAPER_PHOTOS:,} photos at about "
        f"{paper['px'] / 1e6:.2f} MP",
        "",
        f"Measured in this run: {n} photos of scenes/many.toml at {paper['px']:.0f} px a photo: "
        f"photometric {ph:.2f} s a view, geometric {ge:.2f} s ({stereo:.2f} s a view for both). "
        f"Fusion: its cost a pixel at N = {n1} ({fu_px * 1e6:.2f} µs) times the photo's pixels, "
        f"{fu_paper:.2f} s a view, times the slowdown of fusion at N = {n1} with a cache of "
        f"{f_small['cache_mb']} MiB ({share(f_small, r1):.1%} of the maps' bytes, as 1 GiB holds "
        f"{paper_share:.1%} of {PAPER_PHOTOS:,} views of {paper['px'] / 1e6:.2f} MP) against a "
        "cache holding every view: "
        + (
            f"{thrash:.2f}×, so {fu_paper * thrash:.2f} s a view."
            if thrash is not None
            else f"it did not finish in {f_small['timeout']} s, so fusion's time at the paper's "
            "size with the default cache is not bounded by this run."
        )
        + " Stereo runs as units, one a machine; fusion runs on one machine.",
        "",
        "| machines | photometric | geometric | fusion (one machine) | total |",
        "|---|---|---|---|---|",
    ]
    for m in (1, 64):
        p = PAPER_PHOTOS * ph / m / 3600
        g = PAPER_PHOTOS * ge / m / 3600
        if fusion_h is None:
            lines.append(f"| {m} | {p:.1f} h | {g:.1f} h | unbounded | over {p + g:.1f} h |")
        else:
            lines.append(
                f"| {m} | {p:.1f} h | {g:.1f} h | {fusion_h:.2f} h | {p + g + fusion_h:.1f} h |"
            )
    lines += [
        "",
        f"Memory at {PAPER_PHOTOS:,} photos: a stereo unit holds one view and its sources "
        f"(its peak does not grow with N: the table above); fusion holds its cache (1 GiB by "
        f"default) and one bit a pixel of every view ({bits_mb:.0f} MB); it writes each point "
        f"as it is made (about {pts_view:,.0f} points a view here, so about "
        f"{pts_view * PAPER_PHOTOS / 1e6:,.0f} million points at {PAPER_PHOTOS:,} photos, "
        "on disk, not in memory).",
        "",
        "Undistortion: a local workspace's first unit undistorts every photo once; on object "
        "storage every invocation undistorts every photo again in its scratch folder (its "
        "seconds are in each unit's output), a cost that grows with N in every unit.",
    ]
    return lines


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bin", default=os.path.join(ROOT, "target", "release", "nrw-etl"))
    ap.add_argument("--photos", default="64,256,512")
    ap.add_argument("--size", type=int, default=120, help="shorter side of the photos, px")
    ap.add_argument("--units", type=int, default=4)
    ap.add_argument("--small-caches-mb", default="84,40,16,8,3")
    ap.add_argument("--timeout", type=int, default=600, help="seconds a small-cache fusion may take")
    ap.add_argument("--paper-size", type=int, default=612, help="shorter side, px (0.5 MP)")
    ap.add_argument("--work", default=None)
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "bench", "densify_scale.md"))
    args = ap.parse_args()
    binary = os.path.abspath(args.bin)
    work = args.work or tempfile.mkdtemp(prefix="nrw-densify-scale-")
    os.makedirs(work, exist_ok=True)
    threads = os.cpu_count()
    rows = []
    counts = [int(x) for x in args.photos.split(",")]
    for n in counts:
        scene = make_scene(binary, work, n, args.size)
        ws = os.path.join(work, f"dense{n}")
        row = run_units(binary, scene, ws, args.units, keep=n == counts[-1])
        rows.append((n, pixels(scene), row))
        print(f"N = {n}: {per_view(row, n)}", flush=True)
    n1 = rows[-1][0]
    scene1 = os.path.join(work, f"many{n1}_{args.size}")
    small = []
    for k, mb in enumerate(int(x) for x in args.small_caches_mb.split(",") if x):
        small.append(refinalize(binary, scene1, rows[-1][2], mb, f"cache{k}", args.timeout))
        print(f"cache {mb} MiB: {small[-1]}", flush=True)
    scene = make_scene(binary, work, 8, args.paper_size)
    prow = run_units(binary, scene, os.path.join(work, "dense_paper"), 1)
    paper = {"n": 8, "px": pixels(scene), "row": prow}
    text = report(args, rows, small, paper, threads)
    open(args.out, "w").write(text)
    print(text)
    if not args.work:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
