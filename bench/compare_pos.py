"""Compare two RTKLIB-style .pos files epoch by epoch: same epochs, same Q, positions within a tolerance.

`python bench/compare_pos.py A.pos B.pos [--tol-m 0.0001]` (or two directories: every `*.pos` of A against
the file of the same name in B). Used to check that a speed-only change leaves the solutions unchanged: exit 0
when every epoch matches (same time, same Q and ns, |Δxyz| ≤ tol), 1 otherwise, with a one-line summary per
file (epochs, text-identical lines, Q differences, largest position difference in mm).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def _rows(path: Path) -> tuple[list[str], np.ndarray]:
    """Data lines and their (week, tow, x, y, z, Q, ns) columns; lines starting `%` are headers."""
    lines = [ln for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("%")]
    cols = np.array([[float(v) for v in ln.split()[:7]] for ln in lines]).reshape(-1, 7)
    return lines, cols


def compare(a: Path, b: Path, tol_m: float) -> bool:
    """Print one summary line for the pair; True when they match within `tol_m`."""
    la, ca = _rows(a)
    lb, cb = _rows(b)
    if len(la) != len(lb) or not np.array_equal(ca[:, :2], cb[:, :2]):
        print(f"{a.name}: DIFFERENT EPOCHS ({len(la)} vs {len(lb)} lines)")
        return False
    same_text = sum(x == y for x, y in zip(la, lb))
    q_diff = int(np.sum(ca[:, 5] != cb[:, 5]))
    ns_diff = int(np.sum(ca[:, 6] != cb[:, 6]))
    dpos = np.linalg.norm(ca[:, 2:5] - cb[:, 2:5], axis=1) if len(ca) else np.zeros(1)
    # the files carry 0.1 mm resolution: allow one unit of rounding per axis on top of the tolerance
    ok = q_diff == 0 and ns_diff == 0 and bool(np.all(dpos <= tol_m + 1.8e-4))
    print(f"{a.name}: {len(la)} epochs, {same_text} identical lines, Q differs {q_diff}, ns differs {ns_diff}, "
          f"max |dxyz| {1e3 * float(dpos.max()):.2f} mm -> {'OK' if ok else 'MISMATCH'}")
    return ok


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    ap.add_argument("--tol-m", type=float, default=1e-4, help="position tolerance, m (default 0.1 mm)")
    args = ap.parse_args(argv)
    pairs = ([(p, args.b / p.name) for p in sorted(args.a.glob("*.pos"))] if args.a.is_dir() else [(args.a, args.b)])
    ok = True
    for pa, pb in pairs:
        if not pb.exists():
            print(f"{pa.name}: missing in {args.b}")
            ok = False
            continue
        ok = compare(pa, pb, args.tol_m) and ok
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
