"""scipy's SLSQP driving hybc's own gradients, for the comparison in docs/performance.md.

Each evaluation is one `hybc run --format json --grad ...` (a process per run: the counts compare,
the times do not). Needs scipy (not a dependency of hybc): `python3 -m pip install scipy`, then
`python3 benches/measure/scipy_slsqp.py target/release/hybc`.
"""
import json
import subprocess
import sys

import numpy as np
from scipy.optimize import minimize

HYBC = sys.argv[1] if len(sys.argv) > 1 else "target/release/hybc"


class Problem:
    def __init__(self, model, free, names, objective, constraints):
        self.model, self.free, self.names = model, free, names
        self.objective, self.constraints = objective, constraints
        self.runs, self.cache = 0, {}

    def run(self, x):
        key = tuple(x)
        if key not in self.cache:
            args = [HYBC, "run", self.model, "--format", "json", "--grad", self.free]
            for n, v in zip(self.names, x):
                args += ["--set", f"{n}={float(v)!r}"]
            out = json.loads(subprocess.run(args, capture_output=True, text=True).stdout)
            self.runs += 1
            self.cache = {key: out}
        return self.cache[key]

    def value(self, x, name):
        f = self.run(x)["final"]
        # After a stop event the total derivatives describe the final values.
        d = f.get("dstate_total") or f["dstate"]
        do = f.get("doutputs_total") or f["doutputs"]
        if name in f["state"]:
            return f["state"][name], np.array([d[name][n] for n in self.names])
        return f["outputs"][name], np.array([do[name][n] for n in self.names])


def solve(p, x0, bounds, label):
    cons = []
    for name, kind, bound in p.constraints:
        sign = -1.0 if kind == "le" else 1.0
        cons.append({
            "type": "eq" if kind == "eq" else "ineq",
            "fun": lambda x, n=name, b=bound, s=sign: s * (p.value(x, n)[0] - b),
            "jac": lambda x, n=name, s=sign: s * p.value(x, n)[1],
        })
    r = minimize(lambda x: p.value(x, p.objective), x0, jac=True, method="SLSQP", bounds=bounds,
                 constraints=cons, options={"ftol": 1e-12, "maxiter": 200})
    print(f"{label}: {r.message} nit={r.nit} runs={p.runs} x={np.array2string(r.x, precision=10)} f={r.fun:.10g}")


ball = Problem("models/ball.hyb", "h0,e", ["h0", "e"], "h0_param", [("energy", "eq", 2.0), ("y", "eq", 0.1)])
# The objective h0 is a parameter: its value and unit gradient need no run.
ball.value_orig = ball.value
ball.value = lambda x, n: (x[0], np.array([1.0, 0.0])) if n == "h0_param" else ball.value_orig(x, n)
solve(ball, np.array([1.0, 0.8]), [(0.5, 2.0), (0.0, 1.0)], "ball (h0, e), E = 2, y = 0.1")

names = [f"u[{k}]" for k in range(7)]
hopper = Problem("models/hopper_apex.hyb", "u", names, "effort", [("y", "ge", 0.9)])
solve(hopper, np.full(7, 5.0), [(0.0, 100.0)] * 7, "hopper apex >= 0.9, least effort")
