#!/usr/bin/env python3
"""Before/after pictures of the paper's three artifacts on real scans, and a per-switch table.

Follows the paper "Common artifacts in volume rendering" and the quality switches of
docs/design.md ("The quality switches"); the pictures and table are in docs/remedies.md:

  onion rings      engine, a narrow strong opacity peak, step 2: plain / jitter / pre-integrated
  stars            aneurism, thin vessels seen very close, step 0.25: linear / cubic
  jerky edges      engine cut by a clip plane, step 3: boundary_segment off / on
  per-switch table bonsai: a baseline, then each switch changed alone; median time of the
                   repeated frames, first-frame preprocessing, samples per ray, and RMSE/PSNR
                   against the exact reference of the same reconstruction

Every picture is compared with the double-precision reference (`volcast-render --reference`).
The script writes its scene files, images, logs, table.md/.json/.csv and pictures.md into
--out; with --docs DIR it also copies the pictures named in pictures.md into DIR.

Standard library only. The scans are read in place from the shared data folder (never copied):
the scene files name them by a path relative to the scene file's folder.

  python3 tests/bench/remedies.py --render-exe build/renderer/volcast-render --docs docs/images

(--out defaults to out/remedies, relative to the current folder; run it from the repository root.)
"""

import argparse
import csv
import json
import os
import platform
import shutil
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "volumes"

# The baseline of the per-switch table: every switch named, so a changed default elsewhere
# cannot change the baseline silently.
BASELINE_QUALITY = {
    "step": 1.0, "jitter": False, "preintegrated": False, "interpolation": "linear",
    "boundary_segment": True, "early_termination": 0.99, "empty_space_skipping": True,
    "mip_level": 0, "image_scale": 1.0, "shading": False, "seed": 0,
}

# (row name, the switch changed alone, which reference it is measured against)
TABLE_ROWS = [
    ("baseline", {}, "linear"),
    ("step 0.5", {"step": 0.5}, "linear"),
    ("step 2", {"step": 2.0}, "linear"),
    ("jitter", {"jitter": True}, "linear"),
    ("preintegrated", {"preintegrated": True}, "linear"),
    ("cubic", {"interpolation": "cubic"}, "cubic"),
    ("boundary_segment off", {"boundary_segment": False}, "linear"),
    ("early_termination 1 (off)", {"early_termination": 1.0}, "linear"),
    ("empty_space_skipping off", {"empty_space_skipping": False}, "linear"),
    ("mip_level 1", {"mip_level": 1}, "linear"),
    ("image_scale 0.5", {"image_scale": 0.5}, "linear"),
    ("shading", {"shading": True}, "shaded"),
]

# What each reference changes from the baseline (the reference integrates exactly, so step,
# jitter, pre-integration, early termination, skipping, mip level and image scale do not apply;
# the reconstruction and the shading do).
REFERENCES = {
    "linear": {},
    "cubic": {"interpolation": "cubic"},
    "shaded": {"shading": True},
}


# --------------------------------------------------------------------------------------------
# PNG reading and writing (8-bit, non-interlaced), to lay pictures side by side without PIL.

def read_png(path):
    """Return (width, height, rows of RGB bytes) of an 8-bit non-interlaced PNG."""
    data = Path(path).read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path}: not a PNG file")
    pos, idat, ch, w, h = 8, bytearray(), None, 0, 0
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        pos += 12 + n
        if kind == b"IHDR":
            w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
            if depth != 8 or interlace or ctype not in (0, 2, 4, 6):
                raise ValueError(f"{path}: unsupported PNG (bit depth {depth}, colour type {ctype}, "
                                 f"interlace {interlace})")
            ch = {0: 1, 2: 3, 4: 2, 6: 4}[ctype]
        elif kind == b"IDAT":
            idat += body
    raw = zlib.decompress(bytes(idat))
    stride = w * ch
    rows, prev = [], bytearray(stride)
    for y in range(h):
        start = y * (stride + 1)
        f, line = raw[start], bytearray(raw[start + 1:start + 1 + stride])
        if f == 1:
            for i in range(ch, stride):
                line[i] = (line[i] + line[i - ch]) & 255
        elif f == 2:
            for i in range(stride):
                line[i] = (line[i] + prev[i]) & 255
        elif f == 3:
            for i in range(stride):
                a = line[i - ch] if i >= ch else 0
                line[i] = (line[i] + ((a + prev[i]) >> 1)) & 255
        elif f == 4:
            for i in range(stride):
                a = line[i - ch] if i >= ch else 0
                b = prev[i]
                c = prev[i - ch] if i >= ch else 0
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else (b if pb <= pc else c))) & 255
        elif f != 0:
            raise ValueError(f"{path}: bad PNG filter {f} in row {y}")
        prev = line
        if ch == 3:
            rows.append(bytes(line))
        else:  # grey, grey+alpha, RGBA: take the colour channels as they are
            px = [line[i:i + ch] for i in range(0, stride, ch)]
            rows.append(b"".join(bytes(p[:3]) if ch == 4 else bytes((p[0],) * 3) for p in px))
    return w, h, rows


def write_png(path, w, h, rows):
    """Write RGB rows as an 8-bit PNG, choosing per row the filter (none, sub, up) that packs best."""
    out, prev = bytearray(), bytes(3 * w)
    for r in rows:
        sub = bytearray(r)
        for i in range(len(r) - 1, 2, -1):
            sub[i] = (r[i] - r[i - 3]) & 255
        up = bytes((a - b) & 255 for a, b in zip(r, prev))
        f, best = min(((0, bytes(r)), (1, bytes(sub)), (2, up)),
                      key=lambda c: sum(v if v < 128 else 256 - v for v in c[1]))
        out += bytes([f]) + best
        prev = r

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    Path(path).write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                           + chunk(b"IDAT", zlib.compress(bytes(out), 9)) + chunk(b"IEND", b""))


def montage(paths, out, gap=4, background=(48, 48, 48)):
    """Lay PNGs side by side, top-aligned, with a grey gap between them."""
    images = [read_png(p) for p in paths]
    height = max(h for _, h, _ in images)
    width = sum(w for w, _, _ in images) + gap * (len(images) - 1)
    g = bytes(background) * gap
    rows = [g.join(rr[y] if y < h else bytes(background) * w for w, h, rr in images) for y in range(height)]
    write_png(out, width, height, rows)


# --------------------------------------------------------------------------------------------
# Running volcast-render

class Runner:
    def __init__(self, exe, out, data_dir, tolerance, verbose, device="opencl"):
        self.exe, self.out, self.data_dir, self.device = exe, out, data_dir, device
        self.tolerance, self.verbose = tolerance, verbose
        self.scenes = out / "scenes"
        self.images = out / "images"
        self.logs = out / "logs"
        for d in (self.scenes, self.images, self.logs):
            d.mkdir(parents=True, exist_ok=True)
        self.problems = []
        self.calls = 0

    def volume(self, name):
        """A scan's path relative to the scene folder, as docs/design.md's scene file resolves it."""
        path = self.data_dir / f"{name}.nhdr"
        if not path.is_file():
            sys.exit(f"remedies.py: {path} not found (give the shared volumes folder with --data-dir)")
        return os.path.relpath(path, self.scenes)

    def render(self, name, scene, *, reference=False, ext="png", repeat=None, compare=None):
        """Write scene to scenes/NAME.json, render it to images/NAME.EXT and return the JSON report."""
        scene_path = self.scenes / f"{name}.json"
        scene_path.write_text(json.dumps(scene, indent=2) + "\n")
        image = self.images / f"{name}.{ext}"
        cmd = [str(self.exe), str(scene_path), "-o", str(image)]
        if reference:
            cmd += ["--reference", "--tolerance", repr(self.tolerance)]
        else:
            cmd += ["--device", self.device]
        if repeat:
            cmd += ["--repeat", str(repeat)]
        if compare:
            cmd += ["--compare", str(compare)]
        started = time.monotonic()
        proc = subprocess.run(cmd, capture_output=True, text=True)
        seconds = time.monotonic() - started
        self.calls += 1
        (self.logs / f"{name}{'.ref' if reference else ''}.log").write_text(
            " ".join(cmd) + f"\n# rc {proc.returncode}, {seconds:.2f} s\n--- stdout\n{proc.stdout}--- stderr\n{proc.stderr}")
        if proc.returncode != 0:
            sys.exit(f"remedies.py: volcast-render failed on {scene_path} (rc {proc.returncode}):\n{proc.stderr}")
        lines = [l for l in proc.stdout.splitlines() if l.startswith("{")]
        if not lines:
            sys.exit(f"remedies.py: volcast-render printed no JSON for {scene_path}:\n{proc.stdout}")
        report = json.loads(lines[-1])
        report["_wall_s"] = seconds
        if proc.stderr.strip():
            self.note(f"{name}: volcast-render wrote to stderr: {proc.stderr.strip()[:300]}")
        if self.verbose:
            print(f"  {name}{' (reference)' if reference else ''}: {seconds:.1f} s", flush=True)
        c = report.get("compare")
        if c is not None and (c.get("psnr") is None and c.get("rmse") not in (0, 0.0)):
            self.note(f"{name}: comparison has no finite PSNR (rmse {c.get('rmse')})")
        return report

    def note(self, text):
        self.problems.append(text)
        print(f"  NOTE {text}", flush=True)


def with_quality(scene, **changes):
    s = json.loads(json.dumps(scene))
    s.setdefault("quality", {}).update(changes)
    return s


def psnr_of(report):
    c = report.get("compare") or {}
    return c.get("psnr"), c.get("rmse")


# --------------------------------------------------------------------------------------------
# The three artifacts

def artifact_scenes(r, size):
    """Each artifact: (key, title, base scene, [(panel key, caption, quality changes)], references)."""
    image = {"width": size, "height": size}
    engine = r.volume("engine")
    aneurism = r.volume("aneurism")

    # Onion rings (paper Fig. 1-2): a narrow, strong opacity peak around value 90, which the
    # engine's metal crosses on every surface, sampled every 2 voxels.
    onion = {
        "volume": engine,
        "transfer_function": {"points": [[0, 0, 0, 0, 0], [78, 1.0, 0.8, 0.5, 0.0], [90, 1.0, 0.8, 0.5, 0.8],
                                         [102, 1.0, 0.8, 0.5, 0.0], [255, 0, 0, 0, 0]]},
        "camera": {"eye": [577.5, -222.5, 313.5], "target": [127.5, 127.5, 63.5], "up": [0, 0, 1],
                   "projection": "perspective", "fov_y_deg": 22},
        "image": image,
        "quality": {"step": 2.0, "interpolation": "linear"},
    }
    # Linear-interpolation stars (Fig. 3): thin vessels of the aneurism scan seen from 1.6°
    # away, a high threshold; shaded so the shapes read. Pre-integration in every panel keeps
    # the slicing rings of such a steep transfer function out, so the panels differ only in
    # the reconstruction.
    stars = {
        "volume": aneurism,
        "transfer_function": {"points": [[0, 0, 0, 0, 0], [80, 0.9, 0.3, 0.2, 0.0], [100, 1.0, 0.85, 0.7, 0.95],
                                         [255, 1, 1, 1, 0.98]]},
        "camera": {"eye": [800, 150, 40], "target": [127.5, 150, 40], "up": [0, 0, 1],
                   "projection": "perspective", "fov_y_deg": 1.6},
        "image": image,
        "quality": {"step": 0.25, "interpolation": "linear", "preintegrated": True, "shading": True},
    }
    # Jerky edges (Fig. 4): the engine cut by an oblique clip plane that keeps the half toward
    # the eye, so rays end on it; seen close up at step 3 with a smooth, translucent transfer
    # function (few onion rings), where the cut meets the block's top.
    jerky = {
        "volume": engine,
        "transfer_function": {"points": [[0, 0, 0, 0, 0], [50, 0.8, 0.7, 0.5, 0.0], [140, 0.95, 0.85, 0.65, 0.12],
                                         [255, 1, 1, 1, 0.2]]},
        "camera": {"eye": [600, -300, 300], "target": [85, 81, 79], "up": [0, 0, 1],
                   "projection": "perspective", "fov_y_deg": 10},
        "image": image,
        "quality": {"step": 3.0, "interpolation": "linear"},
        "clip_planes": [{"point": [127.5, 127.5, 63.5], "normal": [1, -0.5, 0.5]}],
    }
    return [
        ("onion", "Onion rings (engine, step 2, opacity peak at 90 ± 12)", onion,
         [("plain", "plain sampling (before)", {}),
          ("jitter", "`jitter` (after)", {"jitter": True}),
          ("preintegrated", "`preintegrated` (after)", {"preintegrated": True})],
         [("reference", "exact reference", {})]),
        ("stars", "Linear-interpolation stars (aneurism, thin vessels, step 0.25, shaded)", stars,
         [("linear", "`interpolation: linear` (before)", {}, "reference_cubic"),
          ("cubic", "`interpolation: cubic` (after)", {"interpolation": "cubic"})],
         [("reference_linear", "exact reference, linear", {}),
          ("reference_cubic", "exact reference, cubic", {"interpolation": "cubic"})]),
        ("jerky", "Jerky edges (engine cut by a clip plane, step 3)", jerky,
         [("off", "`boundary_segment: false` (before)", {"boundary_segment": False}),
          ("on", "`boundary_segment: true` (after)", {"boundary_segment": True})],
         [("reference", "exact reference", {})]),
    ]


def run_artifacts(r, size):
    results = []
    for key, title, base, panels, references in artifact_scenes(r, size):
        print(f"{title}", flush=True)
        refs = {}
        for rkey, caption, change in references:
            name = f"{key}_{rkey}"
            rep = r.render(name, with_quality(base, **change), reference=True, ext="exr")
            # The same reference again as an 8-bit picture to look at (the reference is
            # deterministic; volcast-render writes one file per run).
            r.render(name, with_quality(base, **change), reference=True, ext="png")
            refs[rkey] = {"caption": caption, "exr": r.images / f"{name}.exr", "png": r.images / f"{name}.png",
                          "seconds": rep["timings_ms"]["render"] / 1e3,
                          "tolerance_reached": rep.get("tolerance_reached"),
                          "reconstruction": change.get("interpolation", base["quality"].get("interpolation"))}
        rows = []
        for pkey, caption, change, *also in panels:
            scene = with_quality(base, **change)
            interp = scene["quality"].get("interpolation", "linear")
            ref_key = next(k for k, v in refs.items() if v["reconstruction"] == interp)
            name = f"{key}_{pkey}"
            rep = r.render(name, scene, compare=refs[ref_key]["exr"])
            psnr, rmse = psnr_of(rep)
            rows.append({"panel": pkey, "caption": caption, "png": str(r.images / f"{name}.png"),
                         "render_ms": rep["timings_ms"]["render"], "samples_per_ray": rep.get("mean_samples_per_ray"),
                         "psnr": psnr, "rmse": rmse, "against": ref_key, "build_options": rep.get("build_options")})
            for other in also:  # the same picture measured against another reference
                extra = r.render(f"{name}_vs_{other}", scene, compare=refs[other]["exr"])
                rows[-1].setdefault("also", {})[other] = dict(zip(("psnr", "rmse"), psnr_of(extra)))
        for rkey, ref in refs.items():
            rows.append({"panel": rkey, "caption": ref["caption"], "png": str(ref["png"]),
                         "render_ms": ref["seconds"] * 1e3, "samples_per_ray": None, "psnr": None, "rmse": None,
                         "against": None, "tolerance_reached": ref["tolerance_reached"]})
        combined = r.out / f"{key}.png"
        montage([row["png"] for row in rows], combined)
        results.append({"artifact": key, "title": title, "panels": rows, "combined": str(combined)})
    return results


# --------------------------------------------------------------------------------------------
# The per-switch table

def table_scene(r, size):
    return {
        "volume": r.volume("bonsai"),
        "transfer_function": {"points": [[0, 0, 0, 0, 0], [40, 0.3, 0.6, 0.2, 0.0], [60, 0.4, 0.8, 0.3, 0.1],
                                         [120, 0.8, 0.6, 0.3, 0.6], [255, 1, 1, 1, 0.9]]},
        "camera": {"eye": [600, -350, 420], "target": [127.5, 127.5, 110], "up": [0, 0, 1],
                   "projection": "perspective", "fov_y_deg": 32},
        "image": {"width": size, "height": size},
        "quality": dict(BASELINE_QUALITY),
    }


def run_table(r, size, repeat, rounds):
    """Each row rendered `rounds` times, the rounds interleaved over the rows so that a burst of
    load from elsewhere on the machine spreads over all rows; a row's time is the smallest of its
    rounds' medians (each median over repeat - 1 frames with program and tables cached)."""
    base = table_scene(r, size)
    print(f"Per-switch table (bonsai, {size}², --repeat {repeat}, {rounds} rounds)", flush=True)
    refs = {}
    for key, change in REFERENCES.items():
        name = f"table_reference_{key}"
        rep = r.render(name, with_quality(base, **change), reference=True, ext="exr")
        refs[key] = {"exr": r.images / f"{name}.exr", "render_ms": rep["timings_ms"]["render"],
                     "preprocess_ms": rep["timings_ms"].get("preprocess", 0.0),
                     "tolerance_reached": rep.get("tolerance_reached")}
    reports = {label: [] for label, _, _ in TABLE_ROWS}
    for k in range(rounds):
        for label, change, ref in TABLE_ROWS:
            name = "table_" + label.split(" (")[0].replace(" ", "_").replace(".", "")
            reports[label].append(r.render(name, with_quality(base, **change), repeat=repeat,
                                           compare=refs[ref]["exr"]))
    rows = []
    for label, change, ref in TABLE_ROWS:
        reps = reports[label]
        rep = reps[0]
        medians = [(x["timings_ms"].get("render_repeated") or {}).get("median") for x in reps]
        medians = [m for m in medians if m is not None]
        pres = []
        for x in reps:
            pre = x["timings_ms"].get("preprocess", {})
            pres.append(sum(pre.values()) if isinstance(pre, dict) else pre)
        t = rep["timings_ms"]
        psnr, rmse = psnr_of(rep)
        row = {
            "row": label, "change": change, "reference": ref,
            "median_render_ms": min(medians) if medians else None, "round_medians_ms": medians,
            "repeated_frames_per_round": (t.get("render_repeated") or {}).get("count"),
            "first_frame_render_ms": [x["timings_ms"].get("render") for x in reps],
            "preprocess_ms": sorted(pres)[len(pres) // 2], "preprocess_rounds_ms": pres,
            "preprocess": t.get("preprocess", {}),
            "kernel_build_ms": [x["timings_ms"].get("kernel_build") for x in reps],
            "upload_ms": t.get("upload"),
            "samples_per_ray": rep.get("mean_samples_per_ray"),
            "skipped_segments_per_ray": rep.get("skipped_segments_per_ray"),
            "early_terminated_fraction": rep.get("early_terminated_fraction"),
            "rays": rep.get("rays"), "rmse": rmse, "psnr": psnr,
            "max_abs": (rep.get("compare") or {}).get("max_abs"),
            "build_options": rep.get("build_options"), "device": rep.get("device"),
        }
        if any(psnr_of(x) != (psnr, rmse) for x in reps[1:]) and not change.get("jitter"):
            r.note(f"table row '{label}': the rounds' images differ ({[psnr_of(x)[0] for x in reps]})")
        rows.append(row)
        check_row(r, row)
    return {"scene": base, "references": {k: {kk: (str(vv) if isinstance(vv, Path) else vv) for kk, vv in v.items()}
                                          for k, v in refs.items()}, "rows": rows}


def check_row(r, row):
    """Flag what a switch should not do: a NaN, a build option missing, a row that did not change."""
    opts = row["build_options"] or ""
    q = dict(BASELINE_QUALITY, **row["change"])
    expect = {"-DJITTER": q["jitter"], "-DPREINTEGRATED": q["preintegrated"], "-DSHADING": q["shading"],
              "-DBOUNDARY_SEGMENT": q["boundary_segment"], "-DEARLY_TERMINATION": q["early_termination"] < 1,
              "-DEMPTY_SPACE_SKIPPING": q["empty_space_skipping"]}
    for flag, wanted in expect.items():
        if (flag in opts.split()) != wanted:
            r.note(f"table row '{row['row']}': build options '{opts}' {'lack' if wanted else 'have'} {flag}")
    if ("CUBIC" in opts) != (q["interpolation"] == "cubic"):
        r.note(f"table row '{row['row']}': build options '{opts}' do not match interpolation {q['interpolation']}")
    if row["psnr"] is None or row["median_render_ms"] is None:
        r.note(f"table row '{row['row']}': missing PSNR or repeated-frame timing")


def table_markdown(table, repeat):
    lines = [
        f"| row (one switch changed from the baseline) | render ms (median of {repeat - 1} frames) | first-frame preprocess ms "
        "| samples per ray | RMSE | PSNR dB | against reference |",
        "|---|---:|---:|---:|---:|---:|---|",
    ]
    for row in table["rows"]:
        lines.append(f"| {row['row']} | {row['median_render_ms']:.0f} | {row['preprocess_ms']:.1f} "
                     f"| {row['samples_per_ray']:.1f} | {row['rmse']:.2e} | {row['psnr']:.1f} | {row['reference']} |")
    return "\n".join(lines) + "\n"


def write_table(out, table, repeat, meta):
    (out / "table.json").write_text(json.dumps({"meta": meta, **table}, indent=2) + "\n")
    with open(out / "table.csv", "w", newline="") as f:
        cols = ["row", "median_render_ms", "round_medians_ms", "repeated_frames_per_round", "preprocess_ms",
                "samples_per_ray", "skipped_segments_per_ray",
                "early_terminated_fraction", "rmse", "psnr", "max_abs", "reference", "build_options"]
        w = csv.DictWriter(f, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        for row in table["rows"]:
            w.writerow(row)
    refs = table["references"]
    md = table_markdown(table, repeat)
    md += ("\nReferences (exact, double precision, tolerance requested "
           f"{meta['tolerance']:g}): " + ", ".join(
               f"{k} {v['render_ms'] / 1e3:.1f} s (reached {v['tolerance_reached']:.1e})" for k, v in refs.items()) + ".\n")
    m = meta["machine"]
    md += (f"\nRender ms: each row rendered with `--repeat {repeat}` in {meta['rounds']} interleaved rounds; the "
           f"smallest round median is shown (all rounds in table.json). Preprocess: the first frame's "
           f"`timings_ms.preprocess` summed (median of the rounds). Machine: {m['cpu']}, {m['cores']} cores, "
           f"OpenCL device `{meta.get('device')}`; load average {meta['load_average_before'][0]:.1f} before, "
           f"{os.getloadavg()[0]:.1f} after.\n")
    (out / "table.md").write_text(md)
    return md


# --------------------------------------------------------------------------------------------

def pictures_markdown(results, docs_prefix):
    """One table per artifact: pictures, then PSNR against the exact reference and render time."""
    def numbers(p):
        if p["psnr"] is None:
            return f"reference, {p['render_ms'] / 1e3:.1f} s"
        text = f"{p['psnr']:.1f} dB, {p['render_ms']:.0f} ms"
        for other, v in (p.get("also") or {}).items():
            text += f" ({v['psnr']:.1f} dB against the {other.replace('reference_', '')} reference)"
        return text

    md = []
    for art in results:
        md.append(f"**{art['title']}**\n")
        md.append("| " + " | ".join(p["caption"] for p in art["panels"]) + " |")
        md.append("|" + "---|" * len(art["panels"]))
        md.append("| " + " | ".join(f"![{p['caption']}]({docs_prefix}{art['artifact']}_{p['panel']}.png)"
                                    for p in art["panels"]) + " |")
        md.append("| " + " | ".join(numbers(p) for p in art["panels"]) + " |")
        md.append("")
    return "\n".join(md)


def machine():
    cpu = platform.processor() or platform.machine()
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "system": platform.platform()}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="out/remedies", help="output folder (default: out/remedies)")
    ap.add_argument("--render-exe", default="build/renderer/volcast-render", help="the volcast-render executable")
    ap.add_argument("--data-dir", default=os.environ.get("VOLCAST_DATA_DIR", str(DEFAULT_DATA)),
                    help="the shared volumes folder (default: $VOLCAST_DATA_DIR, else shared/data/volumes beside the checkout)")
    ap.add_argument("--docs", default=None, help="also copy the pictures into this folder (e.g. docs/images)")
    ap.add_argument("--only", choices=["artifacts", "table"], default=None, help="run one part only")
    ap.add_argument("--size", type=int, default=256, help="artifact pictures' size in pixels (default 256)")
    ap.add_argument("--table-size", type=int, default=256, help="per-switch table image size (default 256)")
    ap.add_argument("--repeat", type=int, default=6, help="frames per table row; the later ones are timed (default 6)")
    ap.add_argument("--rounds", type=int, default=3,
                    help="times each table row is rendered, interleaved; its time is the best round's median (default 3)")
    ap.add_argument("--device", default="opencl",
                    help="volcast-render's back end for the pictures and timings (default opencl: docs/remedies.md "
                         "describes the OpenCL ray caster; cpu for the native path)")
    ap.add_argument("--tolerance", type=float, default=1e-5, help="reference tolerance per pixel (default 1e-5)")
    ap.add_argument("-q", "--quiet", action="store_true")
    args = ap.parse_args()
    if args.repeat < 2:
        ap.error("--repeat must be at least 2 (the first frame is not timed)")
    if args.rounds < 1:
        ap.error("--rounds must be at least 1")

    exe = Path(args.render_exe)
    if not exe.is_absolute() and not exe.exists() and (REPO / exe).exists():
        exe = REPO / exe
    if not exe.exists():
        sys.exit(f"remedies.py: {exe} not found; build it (cmake --build build --target volcast-render) "
                 "or pass --render-exe")
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    r = Runner(exe.resolve(), out, Path(args.data_dir).resolve(), args.tolerance, not args.quiet, args.device)

    started = time.monotonic()
    meta = {"command": " ".join([Path(sys.argv[0]).as_posix()] + sys.argv[1:]), "machine": machine(),
            "load_average_before": os.getloadavg(), "tolerance": args.tolerance, "repeat": args.repeat,
            "rounds": args.rounds,
            "started": time.strftime("%Y-%m-%d %H:%M:%S")}
    try:
        meta["commit"] = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
                                        capture_output=True, text=True).stdout.strip() or None
    except OSError:
        meta["commit"] = None

    results, table = None, None
    if args.only in (None, "artifacts"):
        results = run_artifacts(r, args.size)
        (out / "pictures.json").write_text(json.dumps(results, indent=2) + "\n")
        (out / "pictures.md").write_text(pictures_markdown(results, "docs/images/"))
    if args.only in (None, "table"):
        table = run_table(r, args.table_size, args.repeat, args.rounds)
        device = next((row["device"] for row in table["rows"] if row.get("device")), None)
        meta["device"] = device
        md = write_table(out, table, args.repeat, dict(meta, tolerance=args.tolerance))
        print("\n" + md)

    meta["load_average_after"] = os.getloadavg()
    meta["seconds"] = time.monotonic() - started
    meta["renders"] = r.calls
    meta["notes"] = r.problems
    (out / "run.json").write_text(json.dumps(meta, indent=2) + "\n")

    if args.docs and results:
        docs = Path(args.docs)
        docs.mkdir(parents=True, exist_ok=True)
        for art in results:
            for p in art["panels"]:
                dst = docs / f"{art['artifact']}_{p['panel']}.png"
                shutil.copyfile(p["png"], dst)
                if dst.stat().st_size > 150_000:
                    r.note(f"{dst} is {dst.stat().st_size // 1000} KB (over 150 KB)")
    print(f"done in {meta['seconds']:.0f} s, {r.calls} renders; output in {out}")
    for p in r.problems:
        print(f"NOTE {p}")


if __name__ == "__main__":
    main()
