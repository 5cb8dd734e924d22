"""Passes `cargo test` output through and writes the ten slowest test binaries to the file
named by argv[1]: each binary's wall time is the time from its `Running`/`Doc-tests` line to
the next one (cargo runs them one after another once everything is built)."""
import sys
import time

start = time.time()
current, began, times = None, None, []
for line in sys.stdin:
    sys.stdout.write(line)
    sys.stdout.flush()
    text = line.strip()
    if text.startswith("Running ") or text.startswith("Doc-tests "):
        now = time.time()
        if current is not None:
            times.append((now - began, current))
        current, began = text, now
if current is not None:
    times.append((time.time() - began, current))
total = time.time() - start
times.sort(reverse=True)
with open(sys.argv[1], "w") as out:
    out.write(f"cargo test: {total:.0f} s in all (build included); the ten slowest test binaries:\n")
    for seconds, name in times[:10]:
        out.write(f"{seconds:8.1f} s  {name}\n")
