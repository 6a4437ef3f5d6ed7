#!/usr/bin/env python3
"""The side-by-side table with the ratio to each peer per cell.

Reads what the peers' harness, $PEERS/run_table.py (outside this repository; see
docs/performance.md), wrote (results_merged.jsonl) after a run with our
command as an --extra peer named "ours", and prints a Markdown table per volume: each peer's
median ms and, beside it, ours divided by theirs (below 1: we are faster).

  /usr/bin/python3 $PEERS/run_table.py --peers vtk91-fixed,vtk91-gpu,volpack \\
      --extra 'ours=build/tests/bench/volcast-bench peers --backend opencl --volume {volume} --size {sizes} \\
               --frames {frames} --sample-distance {sample_distance}' --out-dir out/peers
  python3 tests/bench/peer_ratios.py out/peers/results_merged.jsonl > out/peers/RATIOS.md

Standard library only.
"""
import json
import sys

PAPER = {  # the paper's Table 1 (NVIDIA Quadro 1000M, 2012), ms per frame
    "small": {"512x512": 31.67, "800x600": 34.20, "1024x768": 50.83, "1280x1024": 97.09, "1920x1080": 114.94},
    "large": {"512x512": 81.97, "800x600": 114.63, "1024x768": 163.93, "1280x1024": 218.34, "1920x1080": 280.90},
}
SIZES = ["512x512", "800x600", "1024x768", "1280x1024", "1920x1080"]


def main():
    path = sys.argv[1] if len(sys.argv) > 1 else "out/peers/results_merged.jsonl"
    cells = {}
    for line in open(path):
        if not line.strip():
            continue
        rec = json.loads(line)
        if not rec.get("render_ms"):
            continue
        size = "x".join(str(v) for v in rec["resolution"])
        busy = (rec.get("threads") or {}).get("cpus_busy_with_other_processes") or 0.0
        cells[(rec["volume_preset"], rec["peer_id"], size)] = (rec["render_ms"]["median"], busy)
    volumes = sorted({v for v, _, _ in cells}, key=lambda v: ["small", "large"].index(v) if v in PAPER else 9)
    peers = sorted({p for _, p, _ in cells if p != "ours"})
    for vol in volumes:
        print(f"\n#### {vol} phantom: ms per frame (median); in brackets ours ÷ theirs\n")
        print("| resolution | ours | paper (GPU, 2012) | " + " | ".join(peers) + " |")
        print("|---|" + "---|" * (2 + len(peers)))
        for size in SIZES:
            ours = cells.get((vol, "ours", size))
            if not ours:
                continue
            mark = lambda busy: "*" if busy > 0.25 else ""
            row = [size, f"{ours[0]:.0f}{mark(ours[1])}"]
            paper = PAPER.get(vol, {}).get(size)
            row.append(f"{paper:.0f} ({ours[0] / paper:.1f}×)" if paper else "")
            for p in peers:
                theirs = cells.get((vol, p, size))
                row.append(f"{theirs[0]:.0f}{mark(theirs[1])} ({ours[0] / theirs[0]:.2f}×)" if theirs else "n/a")
            print("| " + " | ".join(row) + " |")
    print("\n`*`: other processes kept more than 0.25 CPU busy while the cell was timed.")


if __name__ == "__main__":
    main()
