#!/usr/bin/env python3
"""The side-by-side table with the ratio to each peer per cell.

Reads what the peers' harness, $PEERS/run_table.py (outside this repository; see
docs/performance.md), wrote (results.jsonl or results_merged.jsonl) after a run with our
command as an --extra peer (named "ours" unless --ours says otherwise), and prints a Markdown
table per volume: our median ms and each peer's, and beside each peer ours divided by theirs
(below 1: we are faster). Several files are rounds of the same run: each ratio is taken
within its round, and a cell shows the range over the rounds.

  /usr/bin/python3 $PEERS/run_table.py --peers vtk91-fixed,vtk91-gpu,volpack \\
      --extra 'ours=build/tests/bench/volcast-bench peers --backend opencl --volume {volume} --size {sizes} \\
               --frames {frames} --sample-distance {sample_distance}' --out-dir out/peers
  python3 tests/bench/peer_ratios.py out/peers/results_merged.jsonl > out/peers/RATIOS.md
  # three rounds, the native path as "ours-cpu" (docs/cpu_renderer.md, "Beside VTK 9.1"):
  python3 tests/bench/peer_ratios.py --ours ours-cpu out/peers/r1/results.jsonl out/peers/r2/results.jsonl \\
      out/peers/r3/results.jsonl

Standard library only.
"""
import argparse
import json

PAPER = {  # the paper's Table 1 (NVIDIA Quadro 1000M, 2012), ms per frame
    "small": {"512x512": 31.67, "800x600": 34.20, "1024x768": 50.83, "1280x1024": 97.09, "1920x1080": 114.94},
    "large": {"512x512": 81.97, "800x600": 114.63, "1024x768": 163.93, "1280x1024": 218.34, "1920x1080": 280.90},
}
SIZES = ["512x512", "800x600", "1024x768", "1280x1024", "1920x1080"]


def read_round(path):
    """(volume, peer, size) -> (median ms, CPUs other processes kept busy) of one run."""
    cells = {}
    with open(path) as f:
        for line in f:
            if not line.strip():
                continue
            rec = json.loads(line)
            if not rec.get("render_ms"):
                continue
            size = "x".join(str(v) for v in rec["resolution"])
            busy = (rec.get("threads") or {}).get("cpus_busy_with_other_processes") or 0.0
            cells[(rec["volume_preset"], rec["peer_id"], size)] = (rec["render_ms"]["median"], busy)
    return cells


def span(values, digits):
    """A value, or the range of several, at the given decimals."""
    lo, hi = min(values), max(values)
    return f"{lo:.{digits}f}" if round(lo, digits) == round(hi, digits) else f"{lo:.{digits}f}–{hi:.{digits}f}"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("files", nargs="*", default=["out/peers/results_merged.jsonl"],
                        help="the harness's results, one file per round")
    parser.add_argument("--ours", default="ours", help="the peer name our command ran under")
    args = parser.parse_args()
    rounds = [read_round(path) for path in args.files]
    volumes = sorted({v for cells in rounds for v, _, _ in cells},
                     key=lambda v: ["small", "large"].index(v) if v in PAPER else 9)
    peers = sorted({p for cells in rounds for _, p, _ in cells if p != args.ours})
    mark = lambda busy: "*" if any(b > 0.25 for b in busy) else ""
    for vol in volumes:
        print(f"\n#### {vol} phantom: ms per frame (median); in brackets {args.ours} ÷ theirs\n")
        print(f"| resolution | {args.ours} | paper (GPU, 2012) | " + " | ".join(peers) + " |")
        print("|---|" + "---|" * (2 + len(peers)))
        for size in SIZES:
            ours = [cells[(vol, args.ours, size)] for cells in rounds if (vol, args.ours, size) in cells]
            if not ours:
                continue
            row = [size, span([o[0] for o in ours], 0) + mark([o[1] for o in ours])]
            paper = PAPER.get(vol, {}).get(size)
            row.append(f"{paper:.0f} ({span([o[0] / paper for o in ours], 1)}×)" if paper else "")
            for p in peers:
                pairs = [(cells[(vol, args.ours, size)], cells[(vol, p, size)]) for cells in rounds
                         if (vol, args.ours, size) in cells and (vol, p, size) in cells]
                if not pairs:
                    row.append("n/a")
                    continue
                theirs = [t for _, t in pairs]
                row.append(span([t[0] for t in theirs], 0) + mark([t[1] for t in theirs]) +
                           f" ({span([o[0] / t[0] for o, t in pairs], 2)}×)")
            print("| " + " | ".join(row) + " |")
    print("\n`*`: other processes kept more than 0.25 CPU busy while the cell was timed (in some round).")


if __name__ == "__main__":
    main()
