"""Reads the AddressSanitizer/LeakSanitizer/UBSan logs of `make asan` (scripts/asan.sh).

Fails on any sanitizer error (heap overflow, use after free, undefined behaviour, ...) and on
any leak with a frame in the core (_native, the instrumented module). Leaks whose stacks hold
no frame of the core are Python's, numpy's or Mesa's own objects alive at exit (Python frees
little at exit); they are counted by the module that allocated them, not failed.

LeakSanitizer's exit-time check stops every thread through a tracer thread, and that tracer
sometimes crashes ("Tracer caught signal 11") in the pytest process, which holds Mesa's and the
core's threads (one of two CI runs of the same code, stop 44). That process's leaks are then unchecked,
which is reported, not failed: nothing about the code was found. Any other fatal LeakSanitizer
error (it cannot run at all, e.g. under ptrace) fails, as does a run whose every leak check
crashed.
"""
import collections
import pathlib
import re
import sys

OURS = re.compile(r"_native\.cpython|/native/(src|python)/")
TRACER_CRASH = re.compile(r"Tracer caught signal \d+")
LSAN_FATAL = "LeakSanitizer has encountered a fatal error"


def main(log_dir: str) -> int:
    errors, ours, theirs, unchecked = [], [], collections.Counter(), []
    files = sorted(pathlib.Path(log_dir).glob("*"))
    for path in files:
        text = path.read_text(errors="replace")
        for block in re.split(r"\n(?=Direct leak|Indirect leak|=+\n==\d+==ERROR|SUMMARY)", text):
            if LSAN_FATAL in block and TRACER_CRASH.search(block):
                unchecked.append(path.name)  # the leak check's tracer crashed (see above)
            elif re.search(r"runtime error:|ERROR: (AddressSanitizer|UndefinedBehaviorSanitizer)|CHECK failed|"
                           + LSAN_FATAL, block):
                errors.append(f"{path.name}:\n{block.strip()[:3000]}")
            elif block.startswith(("Direct leak", "Indirect leak")):
                if OURS.search(block):
                    ours.append(f"{path.name}:\n{block.strip()[:3000]}")
                else:
                    frames = re.findall(r"#\d+ 0x[0-9a-f]+ in \S+ \((\S+?)\+|#\d+ 0x[0-9a-f]+\s+\((\S+?)\+", block)
                    modules = [pathlib.Path(a or b).name for a, b in frames if "libasan" not in (a or b)]
                    size = int(re.match(r"\w+ leak of (\d+)", block).group(1))
                    theirs[modules[0] if modules else "?"] += size
    if unchecked and len(unchecked) == len(files):
        errors.append("every process's leak check crashed: no leak was checked")
    for e in errors:
        print("SANITIZER ERROR in", e, file=sys.stderr)
    if unchecked:
        print(f"asan_check: leaks unchecked in {len(unchecked)} process(es), LeakSanitizer's tracer crashed: "
              + ", ".join(unchecked), file=sys.stderr)
    for leak in ours:
        print("LEAK in the core,", leak, file=sys.stderr)
    print(f"asan_check: {len(files)} log(s), {len(errors)} error(s), {len(ours)} leak(s) in the core; "
          "left alone (no core frame): " + (", ".join(f"{m} {b} B" for m, b in theirs.most_common()) or "none"))
    return 1 if errors or ours else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
