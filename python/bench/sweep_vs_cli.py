"""Per-point cost of `model.sweep` against the native `hybc sweep`, alternating in the same
minutes: the ball with gradients for all three parameters at the model's settings (T = 2.5,
rtol 1e-10), e evenly spaced in [0.75, 0.95], default threads (one per core).

    cargo build --release --bin hybc && pip install ./python
    python python/bench/sweep_vs_cli.py [rounds]

The CLI's figure is the whole command (process start, parse, compile, runs, CSV rows to a file);
the Python figure is one `model.sweep` call with the model already compiled (the first call
compiles it, about a millisecond) up to the dict of NumPy arrays.
"""

import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import hybc

REPO = pathlib.Path(__file__).resolve().parents[2]
BALL = REPO / "models" / "ball.hyb"
CLI = REPO / "target" / "release" / "hybc"


def cli_seconds(n: int, out: str) -> float:
    started = time.perf_counter()
    subprocess.run(
        [CLI, "sweep", BALL, "--vary", f"e=0.75:0.95:{n}", "--grad", "all", "-o", out], check=True
    )
    return time.perf_counter() - started


def python_seconds(model: hybc.Model, n: int) -> float:
    e = np.linspace(0.75, 0.95, n)
    started = time.perf_counter()
    table = model.sweep({"e": e}, grad=["g", "e", "h0"])
    elapsed = time.perf_counter() - started
    assert len(table["e"]) == n and (table["status"] == "ok").all()
    return elapsed


def main() -> None:
    rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 5
    model = hybc.Model.from_file(BALL)
    python_seconds(model, 10)  # compiles the gradient set once
    times: dict[tuple[str, int], list[float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        out = f"{tmp}/out.csv"
        for _ in range(rounds):
            for n in (1000, 100_000):
                times.setdefault(("hybc sweep", n), []).append(cli_seconds(n, out))
                times.setdefault(("model.sweep", n), []).append(python_seconds(model, n))
    print(f"{'what':<12} {'points':>7} {'best us/point':>14} {'median us/point':>16}")
    for (what, n), ts in sorted(times.items(), key=lambda kv: (kv[0][1], kv[0][0])):
        print(f"{what:<12} {n:>7} {min(ts) / n * 1e6:>14.2f} {statistics.median(ts) / n * 1e6:>16.2f}")


if __name__ == "__main__":
    main()
