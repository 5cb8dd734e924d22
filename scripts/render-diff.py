"""Compares two runs of scripts/render-diff.sh: the same exit code per render, the same refusal
(last log line) where it refused, and the EXR bytes where it rendered; where they differ, the
largest difference per channel (with the OpenEXR reference library)."""
import hashlib
import os
import sys


def rows(run):
    with open(os.path.join(run, "summary.txt")) as f:
        return {tuple(line.split()[:3]): line.split()[3] for line in f}


def last_line(path):
    with open(path) as f:
        lines = f.read().strip().splitlines()
    return lines[-1] if lines else ""


def digest(path):
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def largest_differences(a, b):
    import numpy as np
    import OpenEXR

    pa, pb = OpenEXR.File(a).channels(), OpenEXR.File(b).channels()
    out = []
    for name in pa:
        x = np.asarray(pa[name].pixels, dtype=np.float64)
        y = np.asarray(pb[name].pixels, dtype=np.float64)
        out.append(f"{name} {np.abs(x - y).max():.3e} of {np.abs(x).max():.3e}")
    return ", ".join(out)


def main(a, b):
    ra, rb = rows(a), rows(b)
    same = differ = 0
    for key in sorted(ra):
        name = "-".join(key)
        if key not in rb:
            print(f"{name}: only in {a}")
            differ += 1
        elif ra[key] != rb[key]:
            print(f"{name}: exit {ra[key]} against {rb[key]}")
            differ += 1
        elif ra[key] != "rc=0":
            la, lb = (last_line(os.path.join(r, name + ".log")) for r in (a, b))
            same, differ = (same + 1, differ) if la == lb else (same, differ + 1)
            if la != lb:
                print(f"{name}: refused differently:\n  {la}\n  {lb}")
        else:
            ea, eb = (os.path.join(r, name + ".exr") for r in (a, b))
            if digest(ea) == digest(eb):
                same += 1
            else:
                differ += 1
                print(f"{name}: differs: {largest_differences(ea, eb)}")
    print(f"{same} identical, {differ} differ")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
