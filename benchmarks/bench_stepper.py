"""Latency of the filter stepper: state update (Stepper.goto) and redraw (figure -> PNG -> Output).

Drives the widget headlessly as the slider does, on dataset 03 and on dataset 10 (the real
file or its labelled stand-in), and prints median and 95th percentile of

* state update, forward: ``goto(t + 1)`` at the frontier (one filter step),
* state update, history: ``goto`` to an earlier frame (read back, no filter work),
* redraw: update the artists, render the PNG, put it into the ``ipywidgets.Output``.

Targets: state update < 20 ms, redraw < 200 ms per step.

    VISLA_EDU_DATA=/path/to/course/files python benchmarks/bench_stepper.py [--frames 300] [--mode slam]
"""

import argparse
import time

import numpy as np

from visla_edu import data
from visla_edu.stepper.widget import StepperWidget


def _stats(seconds):
    ms = 1e3 * np.asarray(seconds)
    return f"median {np.median(ms):7.2f} ms   p95 {np.percentile(ms, 95):7.2f} ms   max {ms.max():7.2f} ms"


def bench(name, mode, frames, follow, seed=0):
    t0 = time.perf_counter()
    widget = StepperWidget(name, mode=mode, follow=follow)
    setup = time.perf_counter() - t0
    stepper = widget.stepper
    frames = min(frames, stepper.num_frames - 1)
    forward_update, forward_redraw = [], []
    for t in range(1, frames + 1):
        widget.time_slider.value = t
        forward_update.append(stepper.last_update_seconds)
        forward_redraw.append(widget.last_redraw_seconds)
    assert stepper.steps_computed == frames + 1
    rng = np.random.default_rng(seed)
    back_update, back_redraw = [], []
    for t in rng.integers(0, frames, size=min(frames, 200)):
        if int(t) == widget.time_slider.value:
            continue
        widget.time_slider.value = int(t)
        back_update.append(stepper.last_update_seconds)
        back_redraw.append(widget.last_redraw_seconds)
    assert stepper.steps_computed == frames + 1  # the history reads did no filter work
    ds = stepper.dataset
    print(f"\n{ds.name} ({ds.label or 'no label'})")
    print(f"  mode {mode}, {frames} frames forward then {len(back_update)} random jumps back, "
          f"map view {'follow' if follow else 'whole drive'}; widget set-up {setup:.2f} s")
    print(f"  state update, forward (1 filter step): {_stats(forward_update)}")
    print(f"  state update, history read:            {_stats(back_update)}")
    print(f"  redraw, stepping forward:              {_stats(forward_redraw)}")
    print(f"  redraw, jumping back:                  {_stats(back_redraw)}")
    return forward_update, back_update, forward_redraw + back_redraw


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300, help="frames to step forward (default 300)")
    parser.add_argument("--mode", default="slam", help="filter mode (default slam)")
    parser.add_argument("--datasets", nargs="+", default=["03", "10"], help="dataset names (default 03 10)")
    parser.add_argument("--whole", action="store_true", help="map view of the whole drive instead of following")
    args = parser.parse_args(argv)
    print(f"data directory: {data.data_dir()}; available: {', '.join(data.available())}")
    worst = {}
    for name in args.datasets:
        try:
            fwd, back, redraw = bench(name, args.mode, args.frames, follow=not args.whole)
        except FileNotFoundError as err:
            print(f"\n{name}: skipped ({err})")
            continue
        worst[name] = (np.percentile(fwd, 95), np.percentile(back, 95), np.percentile(redraw, 95))
    print("\ntargets: state update < 20 ms, redraw < 200 ms (p95 shown)")
    for name, (fwd, back, redraw) in worst.items():
        ok = fwd < 0.020 and back < 0.020 and redraw < 0.200
        print(f"  {name:>4}: update {1e3 * fwd:5.1f} (forward) / {1e3 * back:5.3f} (history) ms, "
              f"redraw {1e3 * redraw:5.1f} ms -> {'ok' if ok else 'OVER TARGET'}")


if __name__ == "__main__":
    main()
