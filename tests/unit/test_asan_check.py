"""scripts/asan_check.py reads the sanitizer tier's logs: what fails CI and what is only reported."""
import importlib.util
import pathlib

import pytest

SCRIPT = pathlib.Path(__file__).resolve().parents[2] / "scripts" / "asan_check.py"
spec = importlib.util.spec_from_file_location("asan_check", SCRIPT)
asan_check = importlib.util.module_from_spec(spec)
spec.loader.exec_module(asan_check)

PYTHON_LEAK = """
=================================================================
==100==ERROR: LeakSanitizer: detected memory leaks

Direct leak of 64 byte(s) in 1 object(s) allocated from:
    #0 0x7f00 in malloc (/usr/lib/x86_64-linux-gnu/libasan.so.8+0xd9c18)
    #1 0x5600 in PyMem_RawMalloc (/usr/bin/python3.11+0x1234)

SUMMARY: AddressSanitizer: 64 byte(s) leaked in 1 allocation(s).
"""
CORE_LEAK = PYTHON_LEAK.replace("(/usr/bin/python3.11+0x1234)", "(/x/build-asan/_native.cpython-311-x86_64-linux-gnu.so+0x99)")
TRACER_CRASH = """Tracer caught signal 11: addr=0x79d8 pc=0x7fdbfc4e80f0 sp=0x7fdbf53ffd10
==101==LeakSanitizer has encountered a fatal error.
==101==HINT: For debugging, try setting environment variable LSAN_OPTIONS=verbosity=1:log_threads=1
==101==HINT: LeakSanitizer does not work under ptrace (strace, gdb, etc)
"""
NO_LSAN = """==102==LeakSanitizer has encountered a fatal error.
==102==HINT: LeakSanitizer does not work under ptrace (strace, gdb, etc)
"""
HEAP_OVERFLOW = """=================================================================
==103==ERROR: AddressSanitizer: heap-buffer-overflow on address 0x602000000011
"""


def run(tmp_path, logs):
    for i, text in enumerate(logs):
        (tmp_path / f"asan.{100 + i}").write_text(text)
    return asan_check.main(str(tmp_path))


@pytest.mark.parametrize("logs,status", [
    ([PYTHON_LEAK], 0),                 # Python's own leak: counted, not failed
    ([PYTHON_LEAK, CORE_LEAK], 1),      # a leak with a frame in the core
    ([PYTHON_LEAK, HEAP_OVERFLOW], 1),  # any sanitizer error
    ([PYTHON_LEAK, TRACER_CRASH], 0),   # one process's leak check crashed: reported, not failed
    ([TRACER_CRASH, TRACER_CRASH], 1),  # every one crashed: nothing was checked
    ([PYTHON_LEAK, NO_LSAN], 1),        # LeakSanitizer could not run at all
])
def test_what_fails(tmp_path, capsys, logs, status):
    assert run(tmp_path, logs) == status
    if logs == [PYTHON_LEAK, TRACER_CRASH]:
        assert "leaks unchecked in 1 process(es)" in capsys.readouterr().err
