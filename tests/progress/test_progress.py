"""The throttled progress line: at most one report a second, the forced last one always, none before
``first_after_s``, and messages built only when reported."""
from hypothesis import given, strategies as st

from identcheck import progress as P


@given(st.lists(st.floats(0, 5, allow_nan=False), min_size=1, max_size=60), st.sampled_from([0.0, 1.0]))
def test_reports_are_a_second_apart_and_the_forced_one_always_comes(gaps, first_after):
    clock = [100.0]
    P.time.monotonic, real = (lambda: clock[0]), P.time.monotonic
    try:
        said, built = [], []
        line = P.Progress(said.append, first_after_s=first_after)
        times = []
        for i, gap in enumerate(gaps):
            clock[0] += gap
            last = i == len(gaps) - 1

            def message(i=i):
                built.append(i)
                return f"item {i}"
            before = len(said)
            line(message, force=last)
            if len(said) > before:
                times.append(clock[0] - 100.0)
        assert said and said[-1] == f"item {len(gaps) - 1}"              # the forced last report
        assert len(built) == len(said)                                   # built only when reported
        unforced = times[:-1]
        assert all(b - a >= 1.0 for a, b in zip(unforced, unforced[1:]))
        assert all(t >= first_after for t in unforced)
    finally:
        P.time.monotonic = real


def test_silent_without_a_callback():
    P.Progress(None)(lambda: 1 / 0, force=True)          # the message is never built


def test_cli_progress_lines_stay_whole_when_threads_report_at_once(monkeypatch):
    """Bootstrap draws report from worker threads: every line must come out whole, one message per line."""
    import re
    import sys
    import threading
    import time

    from identcheck import cli

    class SlowStream:                    # yields between writes, as a terminal or pipe may
        def __init__(self):
            self.parts = []

        def write(self, text):
            time.sleep(0)
            self.parts.append(text)
            time.sleep(0)

        def flush(self):
            pass
    stream = SlowStream()
    monkeypatch.setattr(sys, "stderr", stream)
    say = cli._progress("fit")

    def worker(w):
        for i in range(40):
            say(f"worker {w} item {i}")
    threads = [threading.Thread(target=worker, args=(w,)) for w in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    lines = "".join(stream.parts).split("\n")
    assert lines[-1] == ""
    assert len(lines[:-1]) == 240
    assert all(re.fullmatch(r"identcheck fit: worker \d item \d+", line) for line in lines[:-1])
