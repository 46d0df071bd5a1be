"""The command's progress bar counts sampling time only: its rate and ETA start when the
kernels are ready, not before the compile (a first run's 60 s of compiling once made a
26 s render show an ETA of hours)."""
import io
import time

from pathtracer.progress import Progress


def test_the_bar_clock_starts_when_sampling_starts():
    stream = io.StringIO()
    p = Progress(spp=100, time_limit=None, pixels=1000, stream=stream)
    time.sleep(0.6)                   # the compile
    p.start_sampling()
    time.sleep(0.1)
    p.update(50, 0.1)                 # half the samples in 0.1 s of sampling
    d = p.bar.format_dict
    assert d["elapsed"] < 0.5, d["elapsed"]
    # the ETA from the sampling rate: about 0.1 s more, not the 0.7 s a clock from the
    # bar's creation gives
    remaining = (d["total"] - d["n"]) * d["elapsed"] / d["n"]
    assert remaining < 0.5, remaining
    p.close()
    assert "50 spp" in stream.getvalue()
