"""Timings of hybc.jax on the bouncing ball (models/ball.hyb, T = 2.5, rtol 1e-10, atol 1e-12).

    python python/bench/jax_bench.py [--hybc PATH-TO-RELEASE-hybc] [--repeat 5]

Prints, best of --repeat (rounds) after a warm-up call (compile and trace excluded unless said):
- the per-call cost of a jitted f(p) from Python (value only, and value with jax.grad);
- the per-call cost inside jax.lax.fori_loop (the parameter moves every iteration, so XLA cannot
  hoist the call out of the loop);
- the per-point cost of jax.vmap over 1000 and 100,000 values of e (values only, and values with
  d/de through jax.vmap(jax.value_and_grad)), alternating round by round with hybc's NumPy API
  (model.sweep, a library call) and, with --hybc, the native `hybc sweep` (whole command: process
  start, parse, compile, runs, CSV to /dev/null) over the same points; best and median;
- the first jax.grad call (trace + XLA compile + run), the figure to set against diffrax's
  recorded 6.4 s compile.
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
import subprocess
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402

import hybc  # noqa: E402
import hybc.jax as hj  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]


def best(fn, repeat: int) -> float:
    """Best wall time of `repeat` calls of fn() (which blocks until its result is ready)."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hybc", help="path to a release build of the hybc command")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    r = args.repeat

    model = hybc.Model.from_file(ROOT / "models" / "ball.hyb")
    start = time.perf_counter()
    f = hj.function(model, params=["e", "h0"], outputs=["energy"], events=4)
    print(f"hybc.jax.function (parse done; compile with and without sensitivities): "
          f"{(time.perf_counter() - start) * 1e3:.1f} ms")
    p = jnp.array([0.8, 1.0])

    energy = lambda p: f(p)["energy"]  # noqa: E731
    grad = jax.jit(jax.grad(energy))
    start = time.perf_counter()
    grad(p).block_until_ready()
    print(f"first jax.jit(jax.grad) call (trace + compile + run): {(time.perf_counter() - start) * 1e3:.1f} ms")

    calls = 2000
    value = jax.jit(energy)
    value(p).block_until_ready()
    t = best(lambda: [value(p) for _ in range(calls)][-1].block_until_ready(), r)
    print(f"jitted f(p) from Python: {t / calls * 1e6:.1f} us per call")
    t = best(lambda: [grad(p) for _ in range(calls)][-1].block_until_ready(), r)
    print(f"jitted jax.grad(E)(p) from Python: {t / calls * 1e6:.1f} us per gradient")

    n = 10_000

    def loop_body(i, acc):
        e = 0.7 + 0.1 * i / n
        return acc + f(jnp.stack([e, 1.0]))["energy"]

    def grad_body(i, acc):
        e = 0.7 + 0.1 * i / n
        return acc + jax.grad(energy)(jnp.stack([e, 1.0]))[0]

    for name, body in (("f(p)", loop_body), ("jax.grad(E)(p)", grad_body)):
        loop = jax.jit(lambda: jax.lax.fori_loop(0, n, body, 0.0))
        loop().block_until_ready()
        t = best(lambda: loop().block_until_ready(), r)
        print(f"{name} inside jax.lax.fori_loop: {t / n * 1e6:.2f} us per iteration")

    # Batches: each method once per round, alternating, so that every figure sees the same load.
    for points in (1000, 100_000):
        es = jnp.linspace(0.75, 0.95, points)
        e_np = np.asarray(es)
        plain = jax.jit(jax.vmap(lambda e: f(jnp.stack([e, 1.0]))["energy"]))
        with_grad = jax.jit(jax.vmap(jax.value_and_grad(lambda e: f(jnp.stack([e, 1.0]))["energy"])))
        plain(es).block_until_ready()
        with_grad(es)[1].block_until_ready()
        methods = {
            "jax.vmap(f), values": lambda: plain(es).block_until_ready(),
            "jax.vmap(value_and_grad), d/de": lambda: with_grad(es)[1].block_until_ready(),
            "model.sweep, values": lambda: model.sweep({"e": e_np}, events=4),
            "model.sweep, grad=['e']": lambda: model.sweep({"e": e_np}, grad=["e"], events=4),
        }
        if args.hybc:
            for label, grad_flag in (("values", []), ("--grad e", ["--grad", "e"])):
                cmd = [args.hybc, "sweep", str(ROOT / "models" / "ball.hyb"), "--vary",
                       f"e=0.75:0.95:{points}", "--events", "4", *grad_flag, "-o", "/dev/null"]
                methods[f"hybc sweep (whole command), {label}"] = (
                    lambda cmd=cmd: subprocess.run(cmd, check=False, capture_output=True))
        times = {name: [] for name in methods}
        for _ in range(r):
            for name, run in methods.items():
                times[name].append(best(run, 1))
        print(f"{points} points, e in [0.75, 0.95], {r} alternating rounds: best (median) per point")
        for name, ts in times.items():
            print(f"  {name}: {min(ts) / points * 1e6:.2f} us ({statistics.median(ts) / points * 1e6:.2f} us)")


if __name__ == "__main__":
    main()
