"""The F12 worker's loop (addon/engine/final.py) against a scripted session and clock: the time
limit stops it between row bands, and frames rendered while a technique compiled (the film
then starts over) do not count towards the sample target. No rendering: the session is fake."""
import numpy as np
import pytest


class ScriptedSession:
    """Traces one row per render_rows call and advances the clock by a second per call; the
    film starts over (samples back to 0) after `fallback_frames` frames, as Session does when a
    technique's pipelines are compiled."""

    def __init__(self, clock, height=10, fallback_frames=0, converged_after=None):
        self.clock, self.height, self.width = clock, height, 4
        self.samples, self.next_row, self.fallback_frames = 0, 0, fallback_frames
        self.fallback_samples = 0
        self.converged_after = converged_after  # adaptive sampling: every pixel converged after these frames
        self.calls_after_converged = 0

    @property
    def converged(self):
        return self.converged_after is not None and self.samples >= self.converged_after

    @property
    def fallback_film(self):
        return self.fallback_frames > 0 and not self.fallback_samples

    def render_rows(self, rows):
        assert rows == 1  # a band of a second is far above BAND_SECONDS: one row at a time
        if self.converged:  # as Session: nothing left to trace
            self.calls_after_converged += 1
            return False
        self.clock[0] += 1.0
        self.next_row += 1
        if self.next_row < self.height:
            return False
        self.next_row = 0
        self.samples += 1
        if not self.fallback_samples and self.samples == self.fallback_frames:
            self.fallback_samples, self.samples = self.samples, 0
        return True

    def cancel(self):
        pass

    def stats(self):
        return {"samples": self.samples, "fallback_samples": self.fallback_samples, "rays": 0, "milliseconds": 1.0}

    def read(self, name):
        return np.zeros((self.height, self.width, 4), np.float32)


@pytest.fixture
def final(bpy, monkeypatch):
    from addon.engine import final

    clock = [0.0]
    monkeypatch.setattr(final.time, "perf_counter", lambda: clock[0])
    return final, clock


def test_the_time_limit_stops_between_bands_once_a_frame_is_whole(final):
    final, clock = final
    session = ScriptedSession(clock)
    worker = final._Worker(session, samples=100, time_limit=12.5, core_passes={"combined"})
    worker.run()
    assert worker.error is None
    # Frame 1 ends at 10 s; frame 2 stops at its first band past 12.5 s, not at its end (20 s).
    assert session.samples == 1 and session.next_row == 3 and clock[0] == 13.0


def test_a_limit_shorter_than_the_first_frame_still_gives_a_whole_frame(final):
    final, clock = final
    session = ScriptedSession(clock)
    final._Worker(session, samples=100, time_limit=0.5, core_passes={"combined"}).run()
    assert session.samples == 1 and session.next_row == 0


def test_frames_rendered_while_a_technique_compiled_do_not_count(final):
    final, clock = final
    session = ScriptedSession(clock, height=2, fallback_frames=6)
    worker = final._Worker(session, samples=4, time_limit=0.0, core_passes={"combined"})
    worker.run()
    assert session.fallback_samples == 6 and session.samples == 4
    assert worker.snapshot[0] == 4


def test_adaptive_sampling_converged_ends_the_render_before_the_target(final):
    final, clock = final
    session = ScriptedSession(clock, height=2, converged_after=3)
    worker = final._Worker(session, samples=100, time_limit=0.0, core_passes={"combined"})
    worker.run()
    assert worker.error is None and session.samples == 3 and worker.snapshot[0] == 3
    assert session.calls_after_converged == 0  # stopped without asking for more
