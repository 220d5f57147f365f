"""hybc.jax's reverse mode by the adjoint against forward sensitivities, as the inputs grow: the
bouncing ball under a force control `pwl(t, 0, 2.5, u)` of K knots (5 bounces before T = 2.5,
rtol 1e-10, atol 1e-12), the gradient of its final energy with respect to the K knots, e and h0.

    python python/bench/jax_adjoint_bench.py [--knots 10,100,1000,2000] [--repeat 5]

Per K, jitted and warmed up, the methods alternate within each repetition; best and median of
--repeat:
- `f(p)`: the plain call (values only);
- `jax.grad` by the adjoint (the default `sens="adjoint"`: a recorded run, one backward pass);
- `jax.grad` with `sens="forward"` (the forward Jacobians transposed: K + 2 sensitivity columns);
- `jax.jacfwd` (forward mode: the same K + 2 columns).
The handler's counters are checked: the adjoint's gradients ran no forward sensitivities.
"""

from __future__ import annotations

import argparse
import statistics
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402

import hybc  # noqa: E402
import hybc.jax as hj  # noqa: E402

MODEL = """model controlled
param g = 9.81
param e = 0.8 in [0, 1]
param h0 = 1.0
param u[{K}] = 0
state y = h0
state v = 0
der(y) = v
der(v) = -g + pwl(t, 0, 2.5, u)
event touchdown when y <= 0 {{
    v := -e * v
}}
output energy = 0.5 * v^2 + g * y
simulate t_end = 2.5, rtol = 1e-10, atol = 1e-12
"""


def timed(fn, p) -> float:
    t = time.perf_counter()
    jax.block_until_ready(fn(p))
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--knots", default="10,100,1000,2000")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    print(
        "| K | `f(p)` | `jax.grad` (adjoint) | `jax.grad` (`sens=\"forward\"`) | `jax.jacfwd` "
        "| adjoint / plain | forward grad / adjoint grad |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for k in (int(x) for x in args.knots.split(",")):
        model = hybc.Model(MODEL.format(K=k))
        s = np.linspace(0.0, 1.0, k)
        p = jnp.concatenate([jnp.asarray(0.8 * np.sin(2 * np.pi * 3 * s) + 0.3 * s), jnp.array([0.8, 1.0])])
        by_adjoint = hj.function(model, params=["u", "e", "h0"], outputs=["energy"], events=6)
        by_forward = hj.function(model, params=["u", "e", "h0"], outputs=["energy"], events=6, sens="forward")
        methods = {
            "plain": jax.jit(lambda p: by_adjoint(p)["energy"]),
            "adjoint": jax.jit(jax.grad(lambda p: by_adjoint(p)["energy"])),
            "forward": jax.jit(jax.grad(lambda p: by_forward(p)["energy"])),
            "jacfwd": jax.jit(jax.jacfwd(lambda p: by_adjoint(p)["energy"])),
        }
        for fn in methods.values():
            jax.block_until_ready(fn(p))
        before = by_adjoint.counts()
        jax.block_until_ready(methods["adjoint"](p))
        after = by_adjoint.counts()
        ran = {key: after[key] - before[key] for key in after}
        assert ran["forward"] == 0 and ran["adjoint"] == 1, ran
        times: dict[str, list[float]] = {name: [] for name in methods}
        for _ in range(args.repeat):
            for name, fn in methods.items():
                times[name].append(timed(fn, p))
        best = {name: min(ts) for name, ts in times.items()}
        med = {name: statistics.median(ts) for name, ts in times.items()}

        def cell(name):
            return f"{best[name] * 1e3:.3g} ms ({med[name] * 1e3:.3g})"

        print(
            f"| {k} | {cell('plain')} | {cell('adjoint')} | {cell('forward')} | {cell('jacfwd')} | "
            f"{best['adjoint'] / best['plain']:.1f} | {best['forward'] / best['adjoint']:.2f} |"
        )


if __name__ == "__main__":
    main()
