"""Sensitivities through a relaxation oscillation's fast jumps (issue #37 item 1.5).

    python3 benches/measure/vdp_sensitivities.py [HYBC]

Run from the repository root (HYBC defaults to target/release/hybc). Van der Pol at mu = 1e3,
x0 = 2, with an event where x crosses 0 (inside each fast jump), to t = 3000: three events. The
reference for dt_k/dx0 is a central difference of the event times of runs at x0 +- 1e-5, rtol 1e-12
(Rodas5P). Printed, as Markdown rows: each method and rtol, the largest relative error of the
event times' gradients (the first event's, before any jump, and the worst of the later ones) and
of the event times themselves.
"""
import json, subprocess, sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
HYBC = sys.argv[1] if len(sys.argv) > 1 else str(ROOT / 'target/release/hybc')
MODEL = """model vdp
param mu = 1000
param x0 = 2
state x = x0
state y = 0
der(x) = y
der(y) = mu * (1 - x^2) * y - x
event cross when x crosses 0
simulate t_end = 3000, rtol = 1e-8, atol = 1e-10
"""


def run(path, method, rtol, x0=2.0, grad=False):
    args = [HYBC, 'run', str(path), '--method', method, '--rtol', rtol, '--atol', f'{float(rtol) / 100:g}',
            '--set', f'x0={x0!r}', '--format', 'json'] + (['--grad', 'x0'] if grad else [])
    out = subprocess.run(args, capture_output=True, text=True, timeout=600, cwd=ROOT)
    return json.loads(out.stdout)


def main():
    path = Path('/tmp/hybc_vdp_sensitivities.hyb')
    path.write_text(MODEL)
    h = 1e-5
    plus = [e['time'] for e in run(path, 'rodas5p', '1e-12', 2.0 + h)['events']]
    minus = [e['time'] for e in run(path, 'rodas5p', '1e-12', 2.0 - h)['events']]
    times = [e['time'] for e in run(path, 'rodas5p', '1e-12')['events']]
    ref = [(a - b) / (2 * h) for a, b in zip(plus, minus)]
    print('| method | rtol | steps | event times | dt1/dx0 (before a jump) | dt2/dx0, dt3/dx0 (after) |')
    print('| --- | --- | --- | --- | --- | --- |')
    for method in ['rodas5p', 'rodas4', 'auto', 'dop853']:
        for rtol in ['1e-6', '1e-8', '1e-10']:
            d = run(path, method, rtol, grad=True)
            ev = d['events']
            if len(ev) != len(ref):
                print(f'| {method} | {rtol} | {d["stats"]["steps"]} | {len(ev)} events, {len(ref)} expected | | |')
                continue
            t_err = max(abs(e['time'] - t) / t for e, t in zip(ev, times))
            g = [abs(e['dtime']['x0'] - r) / abs(r) for e, r in zip(ev, ref)]
            print(f'| {method} | {rtol} | {d["stats"]["steps"]} | {t_err:.1e} | {g[0]:.1e} | {max(g[1:]):.1e} |',
                  flush=True)


main()
