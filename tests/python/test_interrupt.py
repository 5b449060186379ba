"""Ctrl-C stops a long solve: the GIL is released during the computation, and SIGINT reaches it through the
engine's stop flag within a second."""

import signal
import subprocess
import sys
import time

import pytest

from conftest import kac_bin

CHILD = """
import sys, time, kac
s = kac.read(sys.argv[1])
print("solving", flush=True)
t = time.monotonic()
try:
    kac.spectrum(s, k=600, threads=1, progress=lambda *a: None)
    print("finished", flush=True)
except KeyboardInterrupt:
    print(f"interrupted {time.monotonic() - t:.3f}", flush=True)
"""


def test_keyboard_interrupt_stops_a_solve(tmp_path):
    mesh = tmp_path / "sphere.off"
    subprocess.run([kac_bin(), "generate", "icosphere", "--level", "6", "--out", str(mesh)], check=True)
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(mesh)], stdout=subprocess.PIPE, text=True)
    assert child.stdout.readline().strip() == "solving"
    time.sleep(2.0)
    sent = time.monotonic()
    child.send_signal(signal.SIGINT)
    out, _ = child.communicate(timeout=30)
    waited = time.monotonic() - sent
    assert out.startswith("interrupted"), out
    assert waited < 1.5, f"the solve stopped {waited:.2f} s after SIGINT"


def test_the_gil_is_released_while_solving(meshes):
    import threading

    import kac

    s = kac.read(meshes["sphere"])
    ticks = []
    done = threading.Event()

    def tick():
        while not done.is_set():
            ticks.append(time.monotonic())
            time.sleep(0.005)

    t = threading.Thread(target=tick)
    t.start()
    try:
        for _ in range(3):
            kac.spectrum(s, k=60, threads=1)
    finally:
        done.set()
        t.join()
    gaps = [b - a for a, b in zip(ticks, ticks[1:])]
    assert ticks and max(gaps) < 0.2, max(gaps)


def test_an_exception_in_the_progress_callback_stops_the_solve(meshes):
    import kac

    s = kac.read(meshes["sphere"])
    calls = []

    def progress(phase, converged, wanted):
        calls.append(phase)
        raise RuntimeError("enough")

    with pytest.raises(RuntimeError, match="enough"):
        kac.spectrum(s, k=200, threads=1, progress=progress)
    assert len(calls) == 1
    # The engine is free again: the next solve runs.
    values, _ = kac.spectrum(s, k=5)
    assert len(values) == 5
