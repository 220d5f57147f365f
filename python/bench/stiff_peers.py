"""Stiff workloads of issue #25, hybc against its peers, in the same minutes (outside CI).

    python python/bench/stiff_peers.py [robertson] [softball] [chain] [--repeat 5]
        [--sizes 10,100,1000] [--peers hybc,scipy,diffrax,amici] [--reuse-amici]

Needs a venv with hybc (pip install ./python), scipy, jax==0.10.2 with diffrax, and for AMICI
`pip install amici==1.0.1` (a source build: cmake, swig and a CBLAS, e.g. Debian's
libopenblas-dev). A peer that is not installed is reported as missing, not skipped silently.

Agreement comes before speed: every peer's final values (and derivatives, for the peers that give
them) are compared with a tight hybc run (rtol 1e-12) and the relative error is printed beside the
time; a fast wrong answer does not count. Times are wall clock, best of --repeat after a warm-up
(compilation, tracing and JIT excluded; each is reported once beside it).

Workloads (the issue's numbering):
- W4b: Robertson's kinetics (k1 = 0.04, k2 = 3e7, k3 = 1e4) to t = 1e5, an event when y1 falls to
  0.5 doubles the rate k1 (a state k); final y1, y2, y3 and d/d(k1, k2, k3). rtol 1e-8,
  atol 1e-14 (y2 is of order 1e-5 .. 1e-9: a larger atol loses it).
- W4a: the soft ball (penalty spring-damper contact of stiffness wc, no reset) to T = 10, at rest
  by then; d/d(zeta, h0). wc = 1e2 .. 1e8.
- W5: a diffusion chain of N states with a guard on the middle one, d/d(10 parameters).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time

import numpy as np
from timing import best_of

import hybc

ROOT = pathlib.Path(__file__).resolve().parents[2]
SOFT_BALL_PATH = ROOT / "models/soft_ball.hyb"

ROBERTSON = """model robertson
param k1 = 0.04
param k2 = 3e7
param k3 = 1e4
state y1 = 1
state y2 = 0
state y3 = 0
state k = k1
der(y1) = -k * y1 + k3 * y2 * y3
der(y2) = k * y1 - k3 * y2 * y3 - k2 * y2 * y2
der(y3) = k2 * y2 * y2
der(k) = 0
event faster when y1 <= 0.5 {
    k := 2 * k
}
"""
ROBERTSON_P = (0.04, 3e7, 1e4)
ROBERTSON_T, RTOL, ATOL = 1e5, 1e-8, 1e-14


def rel_err(got, want) -> float:
    got, want = np.asarray(got, dtype=float), np.asarray(want, dtype=float)
    scale = np.maximum(np.abs(want), 1e-300)
    return float(np.max(np.abs(got - want) / scale))


def tol_err(got, want, rtol: float, atol: float) -> float:
    """The largest error in units of the tolerances, |got - want| / (atol + rtol |want|): for a
    state that comes to rest (the soft ball's v) a relative error means nothing."""
    got, want = np.asarray(got, dtype=float), np.asarray(want, dtype=float)
    return float(np.max(np.abs(got - want) / (atol + rtol * np.abs(want))))


def row(name: str, seconds: float, steps, err_values: float, err_grad, note: str = "") -> None:
    grad = "-" if err_grad is None else f"{err_grad:.1e}"
    steps = "-" if steps is None else str(steps)
    print(f"  {name:<34} {seconds * 1e3:10.2f} ms {steps:>9}  values {err_values:.1e}  grads {grad:>8}  {note}")


# Errors printed: relative (Robertson: every value is well away from 0) or in units of the
# tolerances (soft ball); the heading of each workload says which.


# ---------------------------------------------------------------------------------------------
# W4b: Robertson with an event


def robertson_hybc(method: str, rtol: float = RTOL, atol: float = ATOL):
    model = hybc.Model(ROBERTSON, file_name="robertson.hyb")

    def go():
        return model.simulate(grad=["k1", "k2", "k3"], t_end=ROBERTSON_T, rtol=rtol, atol=atol, method=method,
                              max_steps=10_000_000)

    return go


def robertson_values(run) -> tuple[np.ndarray, np.ndarray]:
    y = np.array([run.state[s] for s in ("y1", "y2", "y3")])
    d = np.array([run.dstate[s] for s in ("y1", "y2", "y3")])  # (3, 3): d y_i / d k_j
    return y, d


def robertson_scipy(method: str):
    from scipy.integrate import solve_ivp

    k1, k2, k3 = ROBERTSON_P

    def f(t, y, k):
        y1, y2, y3 = y
        return [-k * y1 + k3 * y2 * y3, k * y1 - k3 * y2 * y3 - k2 * y2 * y2, k2 * y2 * y2]

    def jac(t, y, k):
        y1, y2, y3 = y
        return [[-k, k3 * y3, k3 * y2], [k, -k3 * y3 - 2 * k2 * y2, -k3 * y2], [0, 2 * k2 * y2, 0]]

    def event(t, y, k):
        return y[0] - 0.5

    event.terminal, event.direction = True, -1

    def go():
        first = solve_ivp(f, (0, ROBERTSON_T), [1, 0, 0], method=method, args=(k1,), jac=jac, events=event,
                          rtol=RTOL, atol=ATOL)
        t_e, y_e = first.t_events[0][0], first.y_events[0][0]
        second = solve_ivp(f, (t_e, ROBERTSON_T), y_e, method=method, args=(2 * k1,), jac=jac, rtol=RTOL,
                           atol=ATOL)
        return second.y[:, -1], first.nfev + second.nfev, len(first.t) + len(second.t) - 2

    return go


def robertson_diffrax():
    import diffrax
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    jax.config.update("jax_enable_x64", True)

    def f(t, y, args):
        k, k2, k3 = args
        y1, y2, y3 = y
        return jnp.stack([-k * y1 + k3 * y2 * y3, k * y1 - k3 * y2 * y3 - k2 * y2 * y2, k2 * y2 * y2])

    term = diffrax.ODETerm(f)
    solver = diffrax.Kvaerno5()
    controller = diffrax.PIDController(rtol=RTOL, atol=ATOL)
    event = diffrax.Event(lambda t, y, args, **kw: y[0] - 0.5, optx.Newton(rtol=1e-12, atol=1e-14))

    def final(p):
        k1, k2, k3 = p
        first = diffrax.diffeqsolve(term, solver, 0.0, ROBERTSON_T, 1e-6, jnp.array([1.0, 0.0, 0.0]),
                                    args=(k1, k2, k3), stepsize_controller=controller, event=event, adjoint=diffrax.ForwardMode(),
                                    max_steps=1_000_000)
        t_e, y_e = first.ts[-1], first.ys[-1]
        second = diffrax.diffeqsolve(term, solver, t_e, ROBERTSON_T, 1e-6, y_e, args=(2 * k1, k2, k3), adjoint=diffrax.ForwardMode(),
                                     stepsize_controller=controller, max_steps=1_000_000)
        steps = first.stats["num_accepted_steps"] + second.stats["num_accepted_steps"]
        return second.ys[-1], steps

    values = jax.jit(lambda p: final(p))
    jacobian = jax.jit(jax.jacfwd(lambda p: final(p)[0]))
    p = jnp.array(ROBERTSON_P)

    def go():
        (y, steps), d = values(p), jacobian(p)
        return np.asarray(y), np.asarray(d), int(steps)

    start = time.perf_counter()
    go()
    return go, time.perf_counter() - start


def robertson_amici(workdir: str = "/tmp/hybc_amici_robertson"):
    """AMICI 1.0.1 (CVODES, BDF, forward sensitivities) on the same model as SBML."""
    import amici
    import libsbml

    doc = libsbml.SBMLDocument(3, 2)
    m = doc.createModel()
    m.setId("robertson")
    c = m.createCompartment()
    c.setId("c"), c.setSize(1.0), c.setConstant(True)
    for pid, v in zip(("k1", "k2", "k3"), ROBERTSON_P):
        p = m.createParameter()
        p.setId(pid), p.setValue(v), p.setConstant(True)
    for sid, v in (("y1", 1.0), ("y2", 0.0), ("y3", 0.0), ("k", 0.04)):
        p = m.createParameter()
        p.setId(sid), p.setValue(v), p.setConstant(False)
    init = m.createInitialAssignment()
    init.setSymbol("k"), init.setMath(libsbml.parseL3Formula("k1"))
    for sid, rhs in (("y1", "-k * y1 + k3 * y2 * y3"), ("y2", "k * y1 - k3 * y2 * y3 - k2 * y2 * y2"),
                     ("y3", "k2 * y2 * y2"), ("k", "0")):
        r = m.createRateRule()
        r.setVariable(sid), r.setMath(libsbml.parseL3Formula(rhs))
    e = m.createEvent()
    e.setId("faster"), e.setUseValuesFromTriggerTime(True)
    trig = e.createTrigger()
    trig.setMath(libsbml.parseL3Formula("y1 <= 0.5")), trig.setInitialValue(False), trig.setPersistent(True)
    a = e.createEventAssignment()
    a.setVariable("k"), a.setMath(libsbml.parseL3Formula("2 * k"))
    path = f"{workdir}.xml"
    libsbml.writeSBMLToFile(doc, path)
    start = time.perf_counter()
    model = amici.SbmlImporter(path).sbml2amici("robertson", workdir, compute_conservation_laws=False)
    compile_s = time.perf_counter() - start
    go = amici_runner(model, ROBERTSON_T, RTOL, ATOL, ("k1", "k2", "k3"), ("y1", "y2", "y3"))
    return go, compile_s


def amici_runner(model, t_end: float, rtol: float, atol: float, params, states):
    """A run of an AMICI 1.0 model to `t_end` with forward sensitivities with respect to
    `params`: the final `states`, their derivatives (states x params) and the step count."""
    from amici.sim.sundials import SensitivityMethod, SensitivityOrder, run_simulation

    model.set_timepoints([t_end])
    solver = model.create_solver()
    solver.set_relative_tolerance(rtol)
    solver.set_absolute_tolerance(atol)
    solver.set_max_steps(10_000_000)
    solver.set_sensitivity_order(SensitivityOrder.first)
    solver.set_sensitivity_method(SensitivityMethod.forward)
    names = list(model.get_free_parameter_ids())
    model.set_parameter_list([names.index(p) for p in params])
    ids = list(model.get_state_ids())
    idx = [ids.index(s) for s in states]

    def go():
        rdata = run_simulation(model, solver)
        if rdata.status != 0:
            raise RuntimeError(f"AMICI status {rdata.status}")
        x = np.asarray(rdata.x)[-1]
        sx = np.asarray(rdata.sx)[-1]  # (params, states)
        return x[idx], sx[:, idx].T, int(np.sum(rdata.numsteps))

    return go


def robertson(repeat: int) -> None:
    print(f"W4b Robertson to t = {ROBERTSON_T:g} with one event, rtol {RTOL:g}, atol {ATOL:g} (relative errors)")
    ref_y, ref_d = robertson_values(robertson_hybc("rodas5p", 1e-12, 1e-20)())
    for method in ("rodas5p", "rodas4", "auto"):
        try:
            t, run = best_of(robertson_hybc(method), repeat)
        except Exception as e:  # noqa: BLE001 - a method the build does not have is a row, not a crash
            print(f"  hybc {method:<29} failed: {e}")
            continue
        y, d = robertson_values(run)
        steps = json.loads(run.to_json())["stats"]["steps"]
        row(f"hybc {method} (+ d/dk)", t, steps, rel_err(y, ref_y), rel_err(d, ref_d))
    for method in ("Radau", "BDF"):
        try:
            t, (y, nfev, steps) = best_of(robertson_scipy(method), max(1, repeat // 2))
            row(f"scipy {method} (values only)", t, steps, rel_err(y, ref_y), None, f"{nfev} f evals")
        except ImportError as e:
            print(f"  scipy: missing ({e})")
    try:
        go, first = robertson_diffrax()
        t, (y, d, steps) = best_of(go, repeat)
        row("diffrax Kvaerno5 (+ jacfwd)", t, steps, rel_err(y, ref_y), rel_err(d, ref_d),
            f"first call {first:.1f} s")
    except ImportError as e:
        print(f"  diffrax: missing ({e})")
    try:
        go, compile_s = robertson_amici()
        t, (y, d, steps) = best_of(go, repeat)
        row("AMICI 1.0.1 CVODES (+ forward sens)", t, steps, rel_err(y, ref_y), rel_err(d, ref_d),
            f"model build {compile_s:.0f} s")
    except ImportError as e:
        print(f"  AMICI: missing ({e})")


# ---------------------------------------------------------------------------------------------
# W4a: the soft ball (models/soft_ball.hyb: spring wc^2 max(0, -y), damper 2 zeta wc v in contact)

SOFT_T, SOFT_RTOL, SOFT_ATOL = 10.0, 1e-8, 1e-10
SOFT_P = {"g": 9.81, "zeta": 0.3, "h0": 1.0}


def soft_hybc(wc: float, method: str, rtol: float = SOFT_RTOL, atol: float = SOFT_ATOL):
    model = hybc.Model.from_file(SOFT_BALL_PATH)

    def go():
        return model.simulate({"wc": wc}, grad=["zeta", "h0"], t_end=SOFT_T, rtol=rtol, atol=atol, method=method,
                              max_steps=2_000_000)

    return go


def soft_values(run) -> tuple[np.ndarray, np.ndarray]:
    y = np.array([run.state[s] for s in ("y", "v")])
    d = np.array([run.dstate[s] for s in ("y", "v")])  # (2, 2): d (y, v) / d (zeta, h0)
    return y, d


def soft_rhs(y, v, wc, zeta, g, where, maximum):
    return -g + wc**2 * maximum(0.0, -y) - where(y < 0, 2 * zeta * wc * v, 0.0)


def soft_scipy(wc: float, method: str):
    from scipy.integrate import solve_ivp

    g, zeta, h0 = SOFT_P["g"], SOFT_P["zeta"], SOFT_P["h0"]

    def f(t, x):
        return [x[1], soft_rhs(x[0], x[1], wc, zeta, g, lambda c, a, b: a if c else b, max)]

    def jac(t, x):
        inside = x[0] < 0
        return [[0.0, 1.0], [-(wc**2) if inside else 0.0, -2 * zeta * wc if inside else 0.0]]

    def go():
        r = solve_ivp(f, (0, SOFT_T), [h0, 0.0], method=method, jac=jac, rtol=SOFT_RTOL, atol=SOFT_ATOL)
        return r.y[:, -1], r.nfev, len(r.t) - 1

    return go


def soft_diffrax(wc: float):
    import diffrax
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    g = SOFT_P["g"]

    def f(t, x, args):
        zeta = args
        return jnp.stack([x[1], soft_rhs(x[0], x[1], wc, zeta, g, jnp.where, jnp.maximum)])

    term, solver = diffrax.ODETerm(f), diffrax.Kvaerno5()
    controller = diffrax.PIDController(rtol=SOFT_RTOL, atol=SOFT_ATOL)

    def final(p):
        zeta, h0 = p
        sol = diffrax.diffeqsolve(term, solver, 0.0, SOFT_T, 1e-4, jnp.stack([h0, 0.0]), args=zeta,
                                  stepsize_controller=controller, adjoint=diffrax.ForwardMode(),
                                  max_steps=2_000_000)
        return sol.ys[-1], sol.stats["num_accepted_steps"]

    values = jax.jit(final)
    jacobian = jax.jit(jax.jacfwd(lambda p: final(p)[0]))
    p = jnp.array([SOFT_P["zeta"], SOFT_P["h0"]])

    def go():
        (x, steps), d = values(p), jacobian(p)
        return np.asarray(x), np.asarray(d), int(steps)

    start = time.perf_counter()
    go()
    return go, time.perf_counter() - start


def soft_amici(workdir: str = "/tmp/hybc_amici_softball"):
    """AMICI 1.0.1 (CVODES, BDF, forward sensitivities) on the soft ball as SBML: the contact as a
    `piecewise` on `y < 0` (AMICI turns it into a root function, as hybc's flow switch), `wc` a
    parameter (one model build for every bandwidth). Returns `make(wc)` -> a run function."""
    import amici
    import libsbml

    doc = libsbml.SBMLDocument(3, 2)
    m = doc.createModel()
    m.setId("softball")
    c = m.createCompartment()
    c.setId("c"), c.setSize(1.0), c.setConstant(True)
    for pid, v in (("g", SOFT_P["g"]), ("zeta", SOFT_P["zeta"]), ("h0", SOFT_P["h0"]), ("wc", 1e3)):
        p = m.createParameter()
        p.setId(pid), p.setValue(v), p.setConstant(True)
    for sid, v in (("y", SOFT_P["h0"]), ("v", 0.0)):
        p = m.createParameter()
        p.setId(sid), p.setValue(v), p.setConstant(False)
    init = m.createInitialAssignment()
    init.setSymbol("y"), init.setMath(libsbml.parseL3Formula("h0"))
    for sid, rhs in (("y", "v"), ("v", "-g + piecewise(-wc^2 * y - 2 * zeta * wc * v, y < 0, 0)")):
        r = m.createRateRule()
        r.setVariable(sid), r.setMath(libsbml.parseL3Formula(rhs))
    path = f"{workdir}.xml"
    libsbml.writeSBMLToFile(doc, path)
    start = time.perf_counter()
    model = amici.SbmlImporter(path).sbml2amici("softball", workdir, compute_conservation_laws=False)
    compile_s = time.perf_counter() - start

    def make(wc: float):
        model.set_free_parameter_by_id("wc", wc)
        # AMICI renames a state `y` (its own name for observables) to `amici_y`.
        return amici_runner(model, SOFT_T, SOFT_RTOL, SOFT_ATOL, ("zeta", "h0"), ("amici_y", "v"))

    return make, compile_s


def softball(repeat: int) -> None:
    try:
        amici_make, amici_build = soft_amici()
    except ImportError as e:
        amici_make, amici_build = None, 0.0
        print(f"  AMICI: missing ({e})")
    for wc in (1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8):
        print(f"W4a soft ball, wc = {wc:g}, T = {SOFT_T:g}, rtol {SOFT_RTOL:g}, atol {SOFT_ATOL:g} "
              "(errors in units of atol + rtol |x|)")
        ref_x, ref_d = soft_values(soft_hybc(wc, "rodas5p", 1e-11, 1e-14)())
        # Errors in units of the run's tolerances (the ball is at rest: relative errors of v and
        # of the derivatives, all near 0, mean nothing).
        err = lambda got, want: tol_err(got, want, SOFT_RTOL, SOFT_ATOL)  # noqa: E731
        for method in ("rodas5p", "auto", "dopri5"):
            if method == "dopri5" and wc > 1e4:
                print("  hybc dopri5: skipped above wc = 1e4 (hundreds of thousands of steps)")
                continue
            try:
                t, run = best_of(soft_hybc(wc, method), repeat)
            except Exception as e:  # noqa: BLE001
                print(f"  hybc {method:<29} failed: {e}")
                continue
            x, d = soft_values(run)
            steps = json.loads(run.to_json())["stats"]["steps"]
            row(f"hybc {method} (+ d/d(zeta, h0))", t, steps, err(x, ref_x), err(d, ref_d), run.status)
        try:
            t, (x, nfev, steps) = best_of(soft_scipy(wc, "Radau"), max(1, repeat // 2))
            row("scipy Radau (values only)", t, steps, err(x, ref_x), None, f"{nfev} f evals")
        except ImportError as e:
            print(f"  scipy: missing ({e})")
        try:
            go, first = soft_diffrax(wc)
            t, (x, d, steps) = best_of(go, repeat)
            row("diffrax Kvaerno5 (+ jacfwd)", t, steps, err(x, ref_x), err(d, ref_d),
                f"first call {first:.1f} s")
        except ImportError as e:
            print(f"  diffrax: missing ({e})")
        if amici_make is not None:
            try:
                t, (x, d, steps) = best_of(amici_make(wc), repeat)
                row("AMICI 1.0.1 CVODES (+ forward sens)", t, steps, err(x, ref_x), err(d, ref_d),
                    f"model build {amici_build:.0f} s (once)")
            except RuntimeError as e:
                print(f"  AMICI 1.0.1 failed: {e}")


# ---------------------------------------------------------------------------------------------
# W5: the diffusion chain (benches/support/chain.rs, `diffusion_source`): N cells, conductances
# d[0..9] (ten equal segments), leak c, cells starting on a ramp, one top-up of x0 by 0.3 when it
# falls to 0.6; the final cells and d/d(d[0..9]); T = 10, rtol 1e-8, atol 1e-10.

CHAIN_T, CHAIN_RTOL, CHAIN_ATOL = 10.0, 1e-8, 1e-10
CHAIN_D, CHAIN_C = 50.0, 0.1


def chain_text(n: int) -> str:
    """The model text of `diffusion_source(n, true)`, written here again from its definition."""
    seg = lambda i: 10 * i // n  # noqa: E731
    lines = ["model diffusion_chain", "param d[10] = 50 in [0.1, 1000]", "param c = 0.1"]
    lines += [f"state x{i} = {1.0 - 0.5 * i / n!r}" for i in range(n)]
    for i in range(n):
        rhs = f"-c * x{i}"
        if i > 0:
            rhs += f" + d[{seg(i - 1)}] * (x{i - 1} - x{i})"
        if i + 1 < n:
            rhs += f" - d[{seg(i)}] * (x{i} - x{i + 1})"
        lines.append(f"der(x{i}) = {rhs}")
    lines += ["initial mode fill {", "    event top_up when x0 <= 0.6 -> rest {", "        x0 := x0 + 0.3",
              "    }", "}", "mode rest {", "}", f"output y = x{n - 1}"]
    return "\n".join(lines) + "\n"


def chain_hybc(n: int, method: str, rtol: float = CHAIN_RTOL, atol: float = CHAIN_ATOL):
    model = hybc.Model(chain_text(n), file_name=f"chain{n}.hyb")
    start = time.perf_counter()
    model.simulate(grad=["d"], t_end=0.0 + 1e-9, method=method)  # compiles (and caches)
    compile_s = time.perf_counter() - start

    def go():
        return model.simulate(grad=["d"], t_end=CHAIN_T, rtol=rtol, atol=atol, method=method, max_steps=10_000_000)

    return go, compile_s


def chain_values(run, n: int) -> tuple[np.ndarray, np.ndarray]:
    x = np.array([run.state[f"x{i}"] for i in range(n)])
    d = np.array([run.dstate[f"x{i}"] for i in range(n)])  # (n, 10)
    return x, d


def chain_matrix(n: int, d: np.ndarray, c: float):
    """x' = A x for the chain (scipy.sparse), the same segments as the model."""
    import scipy.sparse as sp

    seg = np.array([10 * i // n for i in range(n - 1)])
    g = d[seg]  # conductance of the link i -- i+1
    main = -c * np.ones(n)
    main[:-1] -= g
    main[1:] -= g
    return sp.diags([g, main, g], [-1, 0, 1], format="csc")


def chain_scipy(n: int, method: str):
    from scipy.integrate import solve_ivp

    a_fill = chain_matrix(n, np.full(10, CHAIN_D), CHAIN_C)
    x0 = 1.0 - 0.5 * np.arange(n) / n

    def event(t, x):
        return x[0] - 0.6

    event.terminal, event.direction = True, -1

    def go():
        f = lambda t, x: a_fill @ x  # noqa: E731
        first = solve_ivp(f, (0, CHAIN_T), x0, method=method, jac=a_fill, events=event, rtol=CHAIN_RTOL,
                          atol=CHAIN_ATOL)
        t_e, x_e = first.t_events[0][0], first.y_events[0][0].copy()
        x_e[0] += 0.3
        second = solve_ivp(f, (t_e, CHAIN_T), x_e, method=method, jac=a_fill, rtol=CHAIN_RTOL, atol=CHAIN_ATOL)
        return second.y[:, -1], len(first.t) + len(second.t) - 2

    return go


def chain_diffrax(n: int):
    import diffrax
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    jax.config.update("jax_enable_x64", True)
    seg = jnp.array([10 * i // n for i in range(n - 1)])

    def f(t, x, d):
        g = d[seg]
        flow = g * (x[:-1] - x[1:])  # from cell i to i + 1
        return -CHAIN_C * x + jnp.concatenate([jnp.zeros(1), flow]) - jnp.concatenate([flow, jnp.zeros(1)])

    term, solver = diffrax.ODETerm(f), diffrax.Kvaerno5()
    controller = diffrax.PIDController(rtol=CHAIN_RTOL, atol=CHAIN_ATOL)
    event = diffrax.Event(lambda t, y, args, **kw: y[0] - 0.6, optx.Newton(rtol=1e-12, atol=1e-14))
    x0 = 1.0 - 0.5 * jnp.arange(n) / n

    def final(d):
        first = diffrax.diffeqsolve(term, solver, 0.0, CHAIN_T, 1e-4, x0, args=d, stepsize_controller=controller,
                                    event=event, adjoint=diffrax.ForwardMode(), max_steps=1_000_000)
        x_e = first.ys[-1].at[0].add(0.3)
        second = diffrax.diffeqsolve(term, solver, first.ts[-1], CHAIN_T, 1e-4, x_e, args=d,
                                     stepsize_controller=controller, adjoint=diffrax.ForwardMode(),
                                     max_steps=1_000_000)
        return second.ys[-1], first.stats["num_accepted_steps"] + second.stats["num_accepted_steps"]

    values = jax.jit(final)
    jacobian = jax.jit(jax.jacfwd(lambda d: final(d)[0]))
    d = jnp.full(10, CHAIN_D)

    def go():
        (x, steps), dx = values(d), jacobian(d)
        return np.asarray(x), np.asarray(dx), int(steps)

    start = time.perf_counter()
    go()
    return go, time.perf_counter() - start


def chain_amici(n: int, workdir_root: str = "/tmp/hybc_amici_chain", reuse: bool = False):
    """AMICI 1.0.1 (CVODES BDF, forward sensitivities) on the chain as SBML: the cells and a
    `fired` flag as rate-rule parameters, the top-up an event guarded by the flag. With `reuse`,
    a model already built in the work directory is imported instead of built again (the build
    at N = 1000 takes many minutes; its time is then reported as not measured)."""
    import amici
    import libsbml

    doc = libsbml.SBMLDocument(3, 2)
    m = doc.createModel()
    m.setId(f"chain{n}")
    for k in range(10):
        p = m.createParameter()
        p.setId(f"d{k}"), p.setValue(CHAIN_D), p.setConstant(True)
    p = m.createParameter()
    p.setId("c"), p.setValue(CHAIN_C), p.setConstant(True)
    for i in range(n):
        p = m.createParameter()
        p.setId(f"x{i}"), p.setValue(1.0 - 0.5 * i / n), p.setConstant(False)
    p = m.createParameter()
    p.setId("fired"), p.setValue(0.0), p.setConstant(False)
    seg = lambda i: 10 * i // n  # noqa: E731
    for i in range(n):
        rhs = f"-c * x{i}"
        if i > 0:
            rhs += f" + d{seg(i - 1)} * (x{i - 1} - x{i})"
        if i + 1 < n:
            rhs += f" - d{seg(i)} * (x{i} - x{i + 1})"
        r = m.createRateRule()
        r.setVariable(f"x{i}"), r.setMath(libsbml.parseL3Formula(rhs))
    r = m.createRateRule()
    r.setVariable("fired"), r.setMath(libsbml.parseL3Formula("0"))
    e = m.createEvent()
    e.setId("top_up"), e.setUseValuesFromTriggerTime(True)
    trig = e.createTrigger()
    trig.setMath(libsbml.parseL3Formula("x0 <= 0.6 && fired < 0.5"))
    trig.setInitialValue(False), trig.setPersistent(True)
    for var, formula in (("x0", "x0 + 0.3"), ("fired", "1")):
        a = e.createEventAssignment()
        a.setVariable(var), a.setMath(libsbml.parseL3Formula(formula))
    workdir = f"{workdir_root}{n}"
    path = f"{workdir}.xml"
    if reuse and pathlib.Path(workdir).is_dir():
        import amici.sim.sundials  # noqa: F401  (the built module checks its SWIG version there)

        module = amici.import_model_module(f"chain{n}", workdir)
        model, compile_s = module.get_model(), float("nan")
    else:
        libsbml.writeSBMLToFile(doc, path)
        start = time.perf_counter()
        model = amici.SbmlImporter(path).sbml2amici(f"chain{n}", workdir, compute_conservation_laws=False)
        compile_s = time.perf_counter() - start
    go = amici_runner(model, CHAIN_T, CHAIN_RTOL, CHAIN_ATOL, [f"d{k}" for k in range(10)],
                      [f"x{i}" for i in range(n)])
    return go, compile_s


ALL_PEERS = ("hybc", "scipy", "diffrax", "amici")


def chain(repeat: int, sizes=(10, 100, 1000), peers=ALL_PEERS, reuse_amici: bool = False) -> None:
    """`peers` chooses who runs (at N = 1000 diffrax's dense Jacobian makes it slow to trace and
    run); the reference is always computed."""
    for n in sizes:
        print(f"W5 chain, N = {n}, 10 gradients, T = {CHAIN_T:g}, rtol {CHAIN_RTOL:g}, atol {CHAIN_ATOL:g} "
              "(errors in units of atol + rtol |x|)")
        ref_go, _ = chain_hybc(n, "rodas5p", 1e-12, 1e-14)
        ref_x, ref_d = chain_values(ref_go(), n)
        err = lambda got, want: tol_err(got, want, CHAIN_RTOL, CHAIN_ATOL)  # noqa: E731
        for method in ("rodas5p", "auto", "dopri5", "dop853") if "hybc" in peers else ():
            try:
                go, compile_s = chain_hybc(n, method)
                t, run = best_of(go, repeat)
            except Exception as e:  # noqa: BLE001
                print(f"  hybc {method:<29} failed: {e}")
                continue
            x, d = chain_values(run, n)
            steps = json.loads(run.to_json())["stats"]["steps"]
            row(f"hybc {method} (+ 10 gradients)", t, steps, err(x, ref_x), err(d, ref_d),
                f"compile {compile_s * 1e3:.0f} ms")
        for method in ("Radau", "BDF") if "scipy" in peers else ():
            try:
                t, (x, steps) = best_of(chain_scipy(n, method), max(1, repeat // 2))
                row(f"scipy {method} (values only)", t, steps, err(x, ref_x), None)
            except ImportError as e:
                print(f"  scipy: missing ({e})")
        try:
            if "diffrax" not in peers:
                raise ImportError("not asked for (--peers)")
            go, first = chain_diffrax(n)
            t, (x, d, steps) = best_of(go, max(1, repeat // 2))
            row("diffrax Kvaerno5 (+ jacfwd)", t, steps, err(x, ref_x), err(d, ref_d), f"first call {first:.1f} s")
        except ImportError as e:
            print(f"  diffrax: missing ({e})")
        try:
            if "amici" not in peers:
                raise ImportError("not asked for (--peers)")
            go, compile_s = chain_amici(n, reuse=reuse_amici)
            t, (x, d, steps) = best_of(go, repeat)
            build = "model reused (--reuse-amici)" if compile_s != compile_s else f"model build {compile_s:.0f} s"
            row("AMICI 1.0.1 CVODES (+ forward sens)", t, steps, err(x, ref_x), err(d, ref_d), build)
        except ImportError as e:
            print(f"  AMICI: missing ({e})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("workloads", nargs="*", default=["robertson"])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--sizes", default="10,100,1000", help="the chain's sizes N, comma-separated")
    parser.add_argument("--peers", default=",".join(ALL_PEERS), help="chain: who runs, comma-separated")
    parser.add_argument("--reuse-amici", action="store_true", help="chain: import AMICI models already built")
    args = parser.parse_args()
    sizes = tuple(int(n) for n in args.sizes.split(","))
    peers = tuple(args.peers.split(","))
    for name in args.workloads:
        if name == "chain":
            chain(args.repeat, sizes, peers, args.reuse_amici)
        else:
            {"robertson": robertson, "softball": softball}[name](args.repeat)


if __name__ == "__main__":
    main()
