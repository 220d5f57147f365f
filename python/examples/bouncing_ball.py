"""The tutorial's workflow with hybc's NumPy API: event times, gradients through the bounces,
the tilted floor's slope gradient, a sweep of 1000 restitutions and a fit of e.

Run from anywhere: `python python/examples/bouncing_ball.py` (after `pip install ./python`).
Every number is checked against its closed form (../shared/reference/closed-forms.md).
"""

import math
import pathlib

import numpy as np

import hybc

MODELS = pathlib.Path(__file__).resolve().parents[2] / "models"
g, h0 = 9.81, 1.0

ball = hybc.Model.from_file(MODELS / "ball.hyb")
print("parameters:", ball.params)

# 1. Event times and dt1/dh0 against the closed form.
run = ball.simulate({"e": 0.8}, grad=["e", "h0"], t_end=2.5, rtol=1e-10)
v1 = math.sqrt(2 * g * h0)
closed = [math.sqrt(2 * h0 / g)]
while len(closed) < len(run.event_times):
    closed.append(closed[-1] + 2 * 0.8 ** len(closed) * v1 / g)
print("bounce times:", run.event_times, "closed form:", np.array(closed))
assert np.allclose(run.event_times, closed, atol=1e-9)
print(f"dt1/dh0 = {run.event_dtime[0, 1]:.10f} (closed form 1/sqrt(2 g h0) = {1 / v1:.10f})")

# 2. E(T) and its gradient: four bounces before T = 2.5, E = g h0 e^8.
energy, (de, dh0) = run.outputs["energy"], run.doutputs["energy"]
print(f"E(T) = {energy:.10f}, dE/de = {de:.9f}, dE/dh0 = {dh0:.10f}")
assert math.isclose(energy, g * h0 * 0.8**8, rel_tol=1e-8)
assert math.isclose(de, 8 * g * h0 * 0.8**7, rel_tol=1e-7)

# 3. The tilted floor: the first bounce moves with the slope (the tutorial printed -0.0000).
tilted = hybc.Model.from_file(MODELS / "tilted_ball.hyb")
slope = tilted.simulate(grad=["s"]).event_dtime[0, 0]
print(f"tilted floor: dt1/ds = {slope:+.4f}")
assert round(slope, 4) == 0.1581

# 4. Grazing and Zeno are reported, never silent numbers.
zeno = ball.simulate(grad=["e"], t_end=10)
print(f"t_end = 10: stopped_by {zeno.stopped_by!r}: {zeno.error}")
assert zeno.status == "zeno" and math.isnan(zeno.outputs["energy"])

# 5. 1000 restitutions in parallel, the columns of `hybc sweep`.
e = np.linspace(0.65, 0.9, 1000)
table = ball.sweep({"e": e}, grad=["e"], events=5)
print(f"sweep: {len(e)} points, statuses {sorted(set(table['status']))}, "
      f"bounces before T from {table['events'].min()} to {table['events'].max()}")
assert (table["t1"] == table["t1"][0]).all()  # the first bounce does not depend on e

# 6. Fit e so that E(T) hits a target, with Newton steps on dE/de from the run.
# E(T) = 2 lies on the branch with four bounces before T (e near 0.82).
target, e_fit = 2.0, 0.8
for step in range(20):
    r = ball.simulate({"e": e_fit}, grad=["e"])
    residual = r.outputs["energy"] - target
    if abs(residual) < 1e-10:
        break
    e_fit -= residual / r.doutputs["energy"][0]
k = len(r.event_times)
print(f"fit: e = {e_fit:.10f} gives E(T) = {r.outputs['energy']:.12f} after {step} steps "
      f"(closed form ({target} / (g h0))^(1/{2 * k}) = {(target / (g * h0)) ** (1 / (2 * k)):.10f})")
assert math.isclose(e_fit, (target / (g * h0)) ** (1 / (2 * k)), rel_tol=1e-8)

# 7. The same through JAX (hybc.jax, when JAX is installed): jax.grad, jax.jacfwd and jax.vmap
# each run one native call; a fit with jax.grad steps runs inside one jitted fori_loop.
try:
    import jax
except ImportError:
    print("JAX is not installed: the hybc.jax part is skipped")
    raise SystemExit(0)

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402

import hybc.jax  # noqa: E402

f = hybc.jax.function(ball, params=["e", "h0"], outputs=["energy"], events=4, t_end=2.5)
p = jnp.array([0.8, 1.0])
out = f(p)
print(f"JAX: E(T) = {float(out['energy']):.10f}, {int(out['n_events'])} bounces, "
      f"status {hybc.jax.status_name(out['status'])}")
dE = jax.jit(jax.grad(lambda p: f(p)["energy"]))(p)
print(f"JAX: jax.grad E(T) = {np.asarray(dE)} (closed form [8 g h0 e^7, g e^8])")
assert np.allclose(dE, [8 * g * h0 * 0.8**7, g * 0.8**8], rtol=1e-7)
dt = jax.jacfwd(lambda p: f(p)["event_times"])(p)
print(f"JAX: dt1/dh0 = {float(dt[0, 1]):.10f}")
assert math.isclose(dt[0, 1], 1 / v1, rel_tol=1e-7)

es = jnp.linspace(0.65, 0.9, 1000)
batch = jax.jit(jax.vmap(lambda e: f(jnp.stack([e, 1.0]))))(es)
names = sorted({hybc.jax.status_name(s) for s in np.asarray(batch["status"])})
print(f"JAX: vmap over {len(es)} restitutions in one native call: statuses {names} "
      f"(zeno: the bounces accumulate before T, E is NaN there)")
assert np.all(np.isnan(batch["energy"]) == (batch["status"] == hybc.jax.ZENO))

loss = lambda e: (f(jnp.stack([e, 1.0]))["energy"] - target) ** 2  # noqa: E731
fit = jax.jit(lambda e0: jax.lax.fori_loop(0, 60, lambda _, e: e - 1e-3 * jax.grad(loss)(e), e0))
e_jax = float(fit(jnp.float64(0.8)))
print(f"JAX: fit with jax.grad steps: e = {e_jax:.10f}")
assert math.isclose(e_jax, (target / (g * h0)) ** (1 / 8), rel_tol=1e-8)
