"""Gradients by the adjoint, hybc against diffrax and AMICI in the same minutes (issue #40,
section 4; outside CI).

    python python/bench/adjoint_peers.py [knots] [chain] [--knots 10,100,1000,10000]
        [--sizes 100,300,1000] [--repeat 3] [--peers hybc,diffrax,amici] [--hybc PATH]
        [--amici-knots 10] [--amici-sizes 100] [--examples DIR]    (REUSE_AMICI=1: import AMICI
        models already built in the work directory)

Needs the hybc binary (`cargo build --release --bin hybc`, or --hybc PATH), jax==0.10.2 with
diffrax==0.7.2 (equinox 0.13.8, optimistix 0.1.0), and for AMICI `pip install amici==1.0.1` (a
source build: cmake, swig and a CBLAS, e.g. Debian's libopenblas-dev). A peer that is not
installed is reported as missing, not skipped silently.

The conventions of `stiff_peers.py`: agreement before speed (each gradient's error against a
tight reference is printed beside its time), wall times are the best of --repeat after a
warm-up, and compilation, tracing and JIT are reported apart. hybc's time is the run's own
(`stats.run_seconds` of `hybc run --format json`: parsing and compiling the model excluded), the
best of --repeat processes; its compile is reported beside it.

Workloads (benches/measure/adjoint_knots.rs and adjoint_chain.rs, the same models):
- knots: the ball (g = 9.81, e = 0.8, y(0) = 1) pushed by `pwl(t, 0, 2.5, u)` of K knots, 4
  bounces to t = 2.5, rtol 1e-10, atol 1e-12; the gradient of the final energy with respect to
  all K knots. Reference: hybc's forward sensitivities at rtol 1e-13 (K <= 100) or its adjoint
  at rtol 1e-13 (DOP853) beyond.
- chain: the W5 chain of N cells with a conductance per link (N - 1 parameters), x0 = 1 and
  the others 0, leak c = 0.1, the top-up event `x0 <= 0.6 -> x0 += 0.3` once; Dormand-Prince
  5(4) to T = 10, rtol 1e-8, atol 1e-10; the gradient of the last cell's value. Reference:
  hybc's adjoint with DOP853 at rtol 1e-12, atol 1e-16.

Gradient error: ||g - g_ref||_2 / ||g_ref||_2, and for the chain the largest absolute error too
(the far cell's value lies far below atol at N >= 300: relative errors there measure round-off).
With --examples DIR (the release examples adjoint_knots and adjoint_chain), hybc's adjoint is also
timed warm in process, as the peers are; the CLI's run includes what the adjoint compiles lazily.
docs/performance.md, "Gradients by the adjoint", "Against peers", has the figures.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import re
import subprocess
import tempfile
import time

import numpy as np
from timing import best_of

ROOT = pathlib.Path(__file__).resolve().parents[2]
WORK = pathlib.Path(tempfile.gettempdir()) / "hybc_adjoint_peers"

KNOTS_T, KNOTS_RTOL, KNOTS_ATOL = 2.5, 1e-10, 1e-12
G, E, Y0, U0 = 9.81, 0.8, 1.0, 0.5
CHAIN_T, CHAIN_RTOL, CHAIN_ATOL, CHAIN_D, CHAIN_C = 10.0, 1e-8, 1e-10, 50.0, 0.1


def grad_err(got, want) -> float:
    got, want = np.asarray(got, dtype=float), np.asarray(want, dtype=float)
    return float(np.linalg.norm(got - want) / np.linalg.norm(want))


def abs_err(got, want) -> str:
    """The largest absolute error, for the chain's far cell, whose value (1e-21 at N = 300) lies
    far below atol: there a relative error measures round-off, not the method."""
    return f"max abs err {np.max(np.abs(np.asarray(got, dtype=float) - np.asarray(want, dtype=float))):.1e}"


class Table:
    """The rows of one workload size: tool, time, time / hybc's adjoint, gradient error."""

    def __init__(self, title: str):
        self.title, self.rows, self.hybc = title, [], None
        print(title)

    def add(self, tool: str, seconds: float, err, note: str = "") -> None:
        # The denominator: hybc's adjoint in process (the examples, warm as the peers are) when
        # measured, else the CLI's (whose run includes the lazy compile of the adjoint's kernel).
        if tool.startswith("hybc adjoint") and (self.hybc is None or "in process" in tool):
            self.hybc = seconds
        ratio = "-" if self.hybc is None else f"{seconds / self.hybc:.1f}"
        err_s = "-" if err is None else f"{err:.1e}"
        self.rows.append((tool, seconds, ratio, err_s, note))
        print(f"  {tool:<40} {seconds * 1e3:10.3f} ms  x{ratio:>7}  grad err {err_s:>8}  {note}", flush=True)

    def missing(self, tool: str, why: str) -> None:
        print(f"  {tool:<40} missing: {why}", flush=True)
        self.rows.append((tool, None, "-", "-", f"missing: {why}"))

    def summary(self) -> None:
        """The table again as markdown, each time over hybc's adjoint in process (if measured)
        and over its CLI run."""
        cli = next((r[1] for r in self.rows if r[0] == "hybc adjoint"), None)
        warm = next((r[1] for r in self.rows if r[0] == "hybc adjoint in process"), None)
        print(f"\n{self.title}\n\n| tool | time (ms) | / hybc adjoint in process | / hybc adjoint CLI | gradient error | note |")
        print("| --- | --- | --- | --- | --- | --- |")
        for tool, sec, _, err, note in self.rows:
            if sec is None:
                print(f"| {tool} | - | - | - | - | {note} |")
                continue
            over = lambda base: "-" if base is None else f"{sec / base:.1f}"  # noqa: E731
            print(f"| {tool} | {sec * 1e3:.3f} | {over(warm)} | {over(cli)} | {err} | {note} |")
        print(flush=True)


# ---------------------------------------------------------------------------------------------
# hybc: the binary, one process per run


def hybc_run(binary: str, path: pathlib.Path, args: list[str]) -> dict:
    out = subprocess.run([binary, "run", str(path), "--format", "json", *args], check=True, capture_output=True,
                         text=True)
    return json.loads(out.stdout)


def hybc_best(binary: str, path: pathlib.Path, args: list[str], repeat: int) -> tuple[float, float, dict]:
    """Best `run_seconds` of `repeat` processes after one warm-up, the compile time beside it,
    and the last report."""
    report = hybc_run(binary, path, args)
    runs, compiles = [], []
    for _ in range(repeat):
        report = hybc_run(binary, path, args)
        runs.append(report["stats"]["run_seconds"])
        compiles.append(report["stats"]["compile_seconds"])
    return min(runs), min(compiles), report


def hybc_grad(report: dict, of: str, names: list[str]) -> np.ndarray:
    final = report["final"]
    block = final["doutputs"].get(of) if of in final.get("doutputs", {}) else final["dstate"][of]
    return np.array([block[n] for n in names])


def example_knots(examples: str | None, k: int, repeat: int):
    """hybc's adjoint and plain run warm, in process: `adjoint_knots` (medians of `repeat`), in
    seconds, or None without --examples."""
    if not examples:
        return None
    out = subprocess.run([str(pathlib.Path(examples) / "adjoint_knots"), "--repeat", str(repeat), "--forward-upto",
                          "0", str(k)], check=True, capture_output=True, text=True).stdout
    cells = [c.strip() for c in out.strip().splitlines()[-1].strip("|").split("|")]
    return float(cells[3]) * 1e-3, float(cells[2]) * 1e-3


def example_chain(examples: str | None, n: int, repeat: int):
    """As `example_knots`, from `adjoint_chain` (which also runs forward sensitivities once)."""
    if not examples:
        return None
    out = subprocess.run([str(pathlib.Path(examples) / "adjoint_chain"), "--repeat", str(repeat), str(n)],
                         check=True, capture_output=True, text=True).stdout
    plain = float(re.search(r"plain ([0-9.]+) ms", out).group(1))
    adjoint = float(re.search(r"adjoint ([0-9.]+) ms", out).group(1))
    return adjoint * 1e-3, plain * 1e-3


# ---------------------------------------------------------------------------------------------
# Knots: the ball pushed by pwl(t, 0, 2.5, u)


def knots_source(k: int) -> str:
    return (f"model pushed_ball\nparam g = {G}\nparam e = {E}\nparam u[{k}] = {U0}\n"
            f"state y = {Y0}\nstate v = 0\n"
            "der(y) = v\nder(v) = -g + pwl(t, 0, 2.5, u)\n"
            "event touchdown when y <= 0 {\n v := -e * v\n}\n"
            "output energy = 0.5 * v^2 + g * y\n")


def knots_diffrax(k: int, bounces: int, solver_name: str = "Dopri8"):
    """The ball in diffrax: one `diffeqsolve` per flight, the touchdown a falling `Event` on y
    located by Newton (its time differentiable), v := -e v between solves (a Python loop of
    `bounces + 1` segments: as many as hybc's run has, checked by the event times). The input is
    `jnp.interp` on the knots, which the step-size controller lands on (`jump_ts`) as hybc does.
    `jax.grad` through `RecursiveCheckpointAdjoint`."""
    import diffrax
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    jax.config.update("jax_enable_x64", True)
    knots_t = jnp.linspace(0.0, KNOTS_T, k)

    def f(t, x, u):
        return jnp.stack([x[1], -G + jnp.interp(t, knots_t, u)])

    term, solver = diffrax.ODETerm(f), getattr(diffrax, solver_name)()
    controller = diffrax.PIDController(rtol=KNOTS_RTOL, atol=KNOTS_ATOL, jump_ts=knots_t)
    event = diffrax.Event(lambda t, y, args, **kw: y[0], optx.Newton(rtol=1e-13, atol=1e-14), direction=False)
    max_steps = 4 * k + 4096

    def final(u):
        t0, x = 0.0, jnp.array([Y0, 0.0])
        times, steps = [], 0
        for seg in range(bounces + 1):
            sol = diffrax.diffeqsolve(term, solver, t0, KNOTS_T, 1e-3, x, args=u, stepsize_controller=controller,
                                      event=event if seg < bounces else None,
                                      adjoint=diffrax.RecursiveCheckpointAdjoint(), max_steps=max_steps)
            t0, x = sol.ts[-1], sol.ys[-1]
            steps = steps + sol.stats["num_accepted_steps"]
            if seg < bounces:
                times.append(t0)
                x = jnp.stack([x[0], -E * x[1]])
        energy = 0.5 * x[1] ** 2 + G * x[0]
        return energy, (jnp.stack(times) if times else jnp.zeros(0), steps)

    start = time.perf_counter()
    values = jax.jit(final)
    gradient = jax.jit(jax.grad(lambda u: final(u)[0]))
    u = jnp.full(k, U0)
    energy, (times, steps) = values(u)
    g = gradient(u).block_until_ready()
    first = time.perf_counter() - start
    plain = lambda: values(u)[0].block_until_ready()  # noqa: E731
    grad = lambda: np.asarray(gradient(u).block_until_ready())  # noqa: E731
    return plain, grad, first, np.asarray(times), int(steps)


def sbml_doc(model_id: str):
    import libsbml

    doc = libsbml.SBMLDocument(3, 2)
    m = doc.createModel()
    m.setId(model_id)
    return doc, m


def sbml_param(m, pid: str, value: float, constant: bool) -> None:
    p = m.createParameter()
    p.setId(pid), p.setValue(value), p.setConstant(constant)


def sbml_rate(m, var: str, formula: str) -> None:
    import libsbml

    r = m.createRateRule()
    r.setVariable(var)
    math = libsbml.parseL3Formula(formula)
    if math is None:
        raise ValueError(f"libsbml cannot parse {formula[:80]}")
    r.setMath(math)


def sbml_event(m, eid: str, trigger: str, assignments) -> None:
    import libsbml

    e = m.createEvent()
    e.setId(eid), e.setUseValuesFromTriggerTime(True)
    trig = e.createTrigger()
    trig.setMath(libsbml.parseL3Formula(trigger)), trig.setInitialValue(False), trig.setPersistent(True)
    for var, formula in assignments:
        a = e.createEventAssignment()
        a.setVariable(var), a.setMath(libsbml.parseL3Formula(formula))


def sbml_observable(m, oid: str, formula: str) -> None:
    """An AMICI observable (`observable_` assignment rule): its measurement gives the adjoint a
    likelihood to differentiate."""
    import libsbml

    p = m.createParameter()
    p.setId(f"observable_{oid}"), p.setConstant(False)
    r = m.createAssignmentRule()
    r.setVariable(f"observable_{oid}"), r.setMath(libsbml.parseL3Formula(formula))


def knots_sbml(k: int):
    """The ball as SBML: the pwl input a `piecewise` of K - 1 linear pieces, the touchdown an
    event, the energy an observable."""
    doc, m = sbml_doc(f"ball{k}")
    for pid, v in (("g", G), ("e", E)):
        sbml_param(m, pid, v, True)
    for j in range(k):
        sbml_param(m, f"u{j}", U0, True)
    sbml_param(m, "y", Y0, False)
    sbml_param(m, "v", 0.0, False)
    h = KNOTS_T / (k - 1)
    pieces = []
    for j in range(k - 1):
        pieces += [f"u{j} + (u{j + 1} - u{j}) * (time - {j * h!r}) / {h!r}", f"time < {(j + 1) * h!r}"]
    sbml_rate(m, "y", "v")
    sbml_rate(m, "v", f"-g + piecewise({', '.join(pieces)}, u{k - 1})")
    sbml_event(m, "touchdown", "y <= 0 && v < 0", [("v", "-e * v")])
    sbml_observable(m, "energy", "0.5 * v^2 + g * y")
    return doc


def amici_build(doc, name: str):
    import amici
    import libsbml

    workdir = WORK / f"amici_{name}"
    path = WORK / f"{name}.xml"
    if os.environ.get("REUSE_AMICI") and workdir.is_dir():
        import amici.sim.sundials  # noqa: F401  (the built module checks its SWIG version there)

        return amici.import_model_module(name, str(workdir)).get_model(), float("nan")
    libsbml.writeSBMLToFile(doc, str(path))
    start = time.perf_counter()
    model = amici.SbmlImporter(str(path)).sbml2amici(name, str(workdir), compute_conservation_laws=False)
    return model, time.perf_counter() - start


def amici_gradient(model, observable: str, t_end: float, rtol: float, atol: float, params: list[str],
                   method: str = "adjoint"):
    """A runner for AMICI's gradient of the model's single observable at `t_end` with respect to
    `params`, by adjoint sensitivities (CVODES, BDF by default: AMICI's own choice). AMICI's
    adjoint differentiates a likelihood: a measurement of the observable at `t_end`, one below
    its simulated value with sigma 1, makes d llh / dp = -d obs / dp."""
    from amici.sim.sundials import ExpData, SensitivityMethod, SensitivityOrder, run_simulation

    model.set_timepoints([t_end])
    solver = model.create_solver()
    solver.set_relative_tolerance(rtol)
    solver.set_absolute_tolerance(atol)
    solver.set_max_steps(10_000_000)
    names = list(model.get_free_parameter_ids())
    model.set_parameter_list([names.index(p) for p in params])
    # AMICI 1.0.1 makes every state an observable too: only `observable_<name>` is measured
    # (NaN: no measurement).
    ids = list(model.get_observable_ids())
    which = next(i for i, o in enumerate(ids) if o.endswith(f"observable_{observable}"))
    plain = run_simulation(model, solver)
    measured = np.full(len(ids), np.nan)
    measured[which] = float(np.asarray(plain.y)[-1][which]) - 1.0
    edata = ExpData(model)
    edata.set_measurements(list(measured))
    edata.set_noise_scales([1.0] * len(ids))
    solver.set_sensitivity_order(SensitivityOrder.first)
    solver.set_sensitivity_method(SensitivityMethod.adjoint if method == "adjoint" else SensitivityMethod.forward)

    def go():
        rdata = run_simulation(model, solver, edata)
        if rdata.status != 0:
            raise RuntimeError(f"AMICI status {rdata.status}")
        return -np.asarray(rdata.sllh)

    return go


def amici_row(table: Table, build, observable: str, t_end: float, rtol: float, atol: float, params, ref, repeat: int) -> None:
    """AMICI's row: the model built (timed apart), its adjoint gradient timed, or why not."""
    try:
        model, build_s = build()
    except ImportError as e:
        table.missing("AMICI", str(e))
        return
    # The same likelihood by forward sensitivities after the adjoint: checks the set-up when
    # the adjoint errs or fails.
    for method, tool in (("adjoint", "AMICI CVODES adjoint"), ("forward", "AMICI CVODES forward (check)")):
        try:
            go = amici_gradient(model, observable, t_end, rtol, atol, params, method)
            t, g = best_of(go, repeat)
            table.add(tool, t, grad_err(g, ref), f"model build {build_s:.0f} s, {abs_err(g, ref)}")
        except Exception as e:  # noqa: BLE001 - a peer's failure is a row, not a crash
            table.missing(tool, f"failed: {e}")


def knots(binary: str, counts, repeat: int, peers, amici_counts, examples=None) -> None:
    WORK.mkdir(parents=True, exist_ok=True)
    opts = ["--t-end", str(KNOTS_T), "--rtol", str(KNOTS_RTOL), "--atol", str(KNOTS_ATOL)]
    for k in counts:
        path = WORK / f"knots{k}.hyb"
        path.write_text(knots_source(k))
        names = [f"u[{j}]" for j in range(k)]
        table = Table(f"Knots, K = {k}: d energy(2.5) / d u, rtol {KNOTS_RTOL:g}, atol {KNOTS_ATOL:g}")
        tight = ["--t-end", str(KNOTS_T), "--rtol", "1e-13", "--atol", "1e-15", "--grad", "u", "--of", "energy"]
        if k <= 100:
            ref_report = hybc_run(binary, path, tight + ["--sens", "forward"])
            ref_how = "hybc forward, rtol 1e-13"
        else:
            ref_report = hybc_run(binary, path, tight + ["--sens", "adjoint", "--method", "dop853"])
            ref_how = "hybc adjoint DOP853, rtol 1e-13"
        ref = hybc_grad(ref_report, "energy", names)
        print(f"  reference: {ref_how}, |grad| = {np.linalg.norm(ref):.4g}")
        plain_s, plain_c, report = hybc_best(binary, path, opts, repeat)
        hybc_events = np.array([ev["time"] for ev in report["events"]])
        adj_s, adj_c, report = hybc_best(binary, path, opts + ["--grad", "u", "--sens", "adjoint", "--of", "energy"],
                                         repeat)
        table.add("hybc adjoint", adj_s, grad_err(hybc_grad(report, "energy", names), ref),
                  f"compile {adj_c:.2f} s, {report['stats']['steps']} steps")
        table.add("hybc plain run", plain_s, None, f"compile {plain_c:.2f} s")
        warm = example_knots(examples, k, repeat)
        if warm is not None:
            table.add("hybc adjoint in process", warm[0], None, "adjoint_knots, median")
            table.add("hybc plain run in process", warm[1], None, "adjoint_knots, median")
        if "diffrax" in peers:
            try:
                plain, grad, first, times, steps = knots_diffrax(k, len(hybc_events))
                gap = float(np.max(np.abs(times - hybc_events))) if len(times) else 0.0
                t, g = best_of(grad, repeat)
                table.add("diffrax Dopri8 jax.grad", t, grad_err(g, ref),
                          f"JIT + first call {first:.1f} s, {steps} steps, event times within {gap:.0e} of hybc's")
                t, _ = best_of(plain, repeat)
                table.add("diffrax Dopri8 plain", t, None)
            except ImportError as e:
                table.missing("diffrax", str(e))
        if "amici" in peers:
            if k not in amici_counts:
                table.missing("AMICI", f"not built at K = {k} (--amici-knots)")
            else:
                amici_row(table, lambda: amici_build(knots_sbml(k), f"ball{k}"), "energy", KNOTS_T, KNOTS_RTOL, KNOTS_ATOL,
                          [f"u{j}" for j in range(k)], ref, repeat)
        table.summary()


# ---------------------------------------------------------------------------------------------
# Chain: W5 with a conductance per link


def chain_source(n: int) -> str:
    """benches/measure/adjoint_chain.rs's model, as flat text."""
    s = [f"model link_chain\nparam d[{n - 1}] = {CHAIN_D:g} in [0.1, 1000]\nparam c = {CHAIN_C}\n"]
    s += [f"state x{i} = {1.0 if i == 0 else 0.0}\n" for i in range(n)]
    for i in range(n):
        rhs = f"-c * x{i}"
        if i > 0:
            rhs += f" + d[{i - 1}] * (x{i - 1} - x{i})"
        if i + 1 < n:
            rhs += f" - d[{i}] * (x{i} - x{i + 1})"
        s.append(f"der(x{i}) = {rhs}\n")
    s.append("initial mode fill {\n    event top_up when x0 <= 0.6 -> rest {\n        x0 := x0 + 0.3\n    }\n}\n"
             "mode rest {\n}\n")
    s.append(f"output y = x{n - 1}\n")
    return "".join(s)


def chain_diffrax(n: int):
    """The chain in diffrax (Dopri5, the same tolerances): the top-up a falling `Event` on x0 - 0.6
    ending the first solve, x0 += 0.3, a second solve to T. `jax.grad` of the last cell through
    `RecursiveCheckpointAdjoint`."""
    import diffrax
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    jax.config.update("jax_enable_x64", True)

    def f(t, x, d):
        flow = d * (x[:-1] - x[1:])  # from cell i to i + 1
        return -CHAIN_C * x + jnp.concatenate([jnp.zeros(1), flow]) - jnp.concatenate([flow, jnp.zeros(1)])

    term, solver = diffrax.ODETerm(f), diffrax.Dopri5()
    controller = diffrax.PIDController(rtol=CHAIN_RTOL, atol=CHAIN_ATOL)
    event = diffrax.Event(lambda t, y, args, **kw: y[0] - 0.6, optx.Newton(rtol=1e-12, atol=1e-14), direction=False)
    x0 = jnp.zeros(n).at[0].set(1.0)

    def final(d):
        first = diffrax.diffeqsolve(term, solver, 0.0, CHAIN_T, 1e-3, x0, args=d, stepsize_controller=controller,
                                    event=event, max_steps=100_000)
        x_e = first.ys[-1].at[0].add(0.3)
        second = diffrax.diffeqsolve(term, solver, first.ts[-1], CHAIN_T, 1e-3, x_e, args=d,
                                     stepsize_controller=controller, max_steps=100_000)
        steps = first.stats["num_accepted_steps"] + second.stats["num_accepted_steps"]
        return second.ys[-1][-1], (first.ts[-1], steps)

    start = time.perf_counter()
    values = jax.jit(final)
    gradient = jax.jit(jax.grad(lambda d: final(d)[0]))
    d = jnp.full(n - 1, CHAIN_D)
    _, (t_event, steps) = values(d)
    gradient(d).block_until_ready()
    first = time.perf_counter() - start
    plain = lambda: values(d)[0].block_until_ready()  # noqa: E731
    grad = lambda: np.asarray(gradient(d).block_until_ready())  # noqa: E731
    return plain, grad, first, float(t_event), int(steps)


def chain_sbml(n: int):
    """The chain as SBML: cells and a `fired` flag as rate-rule parameters, the top-up an event
    guarded by the flag (the mode `rest`), the last cell an observable."""
    doc, m = sbml_doc(f"link_chain{n}")
    for j in range(n - 1):
        sbml_param(m, f"d{j}", CHAIN_D, True)
    sbml_param(m, "c", CHAIN_C, True)
    for i in range(n):
        sbml_param(m, f"x{i}", 1.0 if i == 0 else 0.0, False)
    sbml_param(m, "fired", 0.0, False)
    for i in range(n):
        rhs = f"-c * x{i}"
        if i > 0:
            rhs += f" + d{i - 1} * (x{i - 1} - x{i})"
        if i + 1 < n:
            rhs += f" - d{i} * (x{i} - x{i + 1})"
        sbml_rate(m, f"x{i}", rhs)
    sbml_rate(m, "fired", "0")
    sbml_event(m, "top_up", "x0 <= 0.6 && fired < 0.5", [("x0", "x0 + 0.3"), ("fired", "1")])
    sbml_observable(m, "last", f"x{n - 1}")
    return doc


def chain(binary: str, sizes, repeat: int, peers, amici_sizes, examples=None) -> None:
    WORK.mkdir(parents=True, exist_ok=True)
    opts = ["--t-end", str(CHAIN_T), "--rtol", str(CHAIN_RTOL), "--atol", str(CHAIN_ATOL), "--method", "dopri5"]
    for n in sizes:
        path = WORK / f"chain{n}.hyb"
        path.write_text(chain_source(n))
        names = [f"d[{j}]" for j in range(n - 1)]
        table = Table(f"Chain, N = {n}: d x{n - 1}(10) / d d, {n - 1} parameters, rtol {CHAIN_RTOL:g}, "
                      f"atol {CHAIN_ATOL:g}")
        ref_report = hybc_run(binary, path, ["--t-end", str(CHAIN_T), "--rtol", "1e-12", "--atol", "1e-16",
                                             "--method", "dop853", "--grad", "d", "--sens", "adjoint", "--of", "y"])
        ref = hybc_grad(ref_report, "y", names)
        print(f"  reference: hybc adjoint DOP853, rtol 1e-12, atol 1e-16; y = {ref_report['final']['outputs']['y']:.4g},"
              f" |grad| = {np.linalg.norm(ref):.4g}")
        plain_s, plain_c, report = hybc_best(binary, path, opts, repeat)
        hybc_event = report["events"][0]["time"]
        adj_s, adj_c, report = hybc_best(binary, path, opts + ["--grad", "d", "--sens", "adjoint", "--of", "y"],
                                         repeat)
        g = hybc_grad(report, "y", names)
        table.add("hybc adjoint", adj_s, grad_err(g, ref),
                  f"compile {adj_c:.2f} s, {report['stats']['steps']} steps, {abs_err(g, ref)}")
        table.add("hybc plain run", plain_s, None, f"compile {plain_c:.2f} s")
        warm = example_chain(examples, n, repeat)
        if warm is not None:
            table.add("hybc adjoint in process", warm[0], None, "adjoint_chain, median")
            table.add("hybc plain run in process", warm[1], None, "adjoint_chain, median")
        if "diffrax" in peers:
            try:
                plain, grad, first, t_event, steps = chain_diffrax(n)
                t, g = best_of(grad, repeat)
                table.add("diffrax Dopri5 jax.grad", t, grad_err(g, ref),
                          f"JIT + first call {first:.1f} s, {steps} steps, {abs_err(g, ref)}, "
                          f"event at {t_event:.6f} (hybc {hybc_event:.6f})")
                t, _ = best_of(plain, repeat)
                table.add("diffrax Dopri5 plain", t, None)
            except ImportError as e:
                table.missing("diffrax", str(e))
        if "amici" in peers:
            if n not in amici_sizes:
                table.missing("AMICI", f"not built at N = {n} (--amici-sizes)")
            else:
                amici_row(table, lambda: amici_build(chain_sbml(n), f"link_chain{n}"), "last", CHAIN_T, CHAIN_RTOL,
                          CHAIN_ATOL, [f"d{j}" for j in range(n - 1)], ref, repeat)
        table.summary()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("workloads", nargs="*", default=["knots", "chain"])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--knots", default="10,100,1000,10000")
    parser.add_argument("--sizes", default="100,300,1000")
    parser.add_argument("--peers", default="hybc,diffrax,amici")
    parser.add_argument("--amici-knots", default="10", help="K at which AMICI's model is built (its import "
                        "of the 99-piece piecewise at K = 100 passed 14 GB of memory unfinished)")
    parser.add_argument("--amici-sizes", default="100", help="N at which AMICI's model is built")
    parser.add_argument("--examples", help="a directory with the release examples adjoint_knots and adjoint_chain "
                        "(cargo build --release --example ...): hybc's adjoint warm, in process")
    parser.add_argument("--hybc", default=os.environ.get("HYBC", str(ROOT / "target/release/hybc")))
    args = parser.parse_args()
    ints = lambda s: tuple(int(x) for x in s.split(",") if x)  # noqa: E731
    peers = tuple(args.peers.split(","))
    for name in args.workloads:
        if name == "knots":
            knots(args.hybc, ints(args.knots), args.repeat, peers, ints(args.amici_knots), args.examples)
        elif name == "chain":
            chain(args.hybc, ints(args.sizes), args.repeat, peers, ints(args.amici_sizes), args.examples)
        else:
            raise SystemExit(f"unknown workload {name}")


if __name__ == "__main__":
    main()
