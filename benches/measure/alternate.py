"""Two hybc builds alternated on the shipped models' sweeps, in the same minutes.

    python3 benches/measure/alternate.py OLD_HYBC NEW_HYBC [ROUNDS] [--scale S]
    python3 benches/measure/alternate.py OLD_HYBC NEW_HYBC --instructions [SCALE]

Run from the repository root. For each workload the builds run one after the other ROUNDS times
(default 5); printed per workload: the median CPU time (user + system, /usr/bin/time) of each
build and the median of the pairwise ratios new / old with their range, as a Markdown row. The
machines here move by 3x between days: only ratios measured this way are compared. `--scale S`
multiplies the point counts: /usr/bin/time counts in 10 ms ticks, so the short sweeps' ratios
need S of 5 or more to mean anything.

With `--instructions`, each build runs each workload once under callgrind (valgrind) and the
row gives the instructions executed by each and their ratio: deterministic, so a loaded machine
does not move it, but blind to what instructions cost (cache misses, vector width). SCALE
(default 0.1) shrinks the point counts, since callgrind runs some 50 times slower.
"""
import subprocess, statistics, sys, re
from pathlib import Path
ROOT = Path(__file__).resolve().parents[2]
M = ROOT / 'models'
OLD, NEW = sys.argv[1], sys.argv[2]
cpu_scale = 1.0
if '--scale' in sys.argv:
    k = sys.argv.index('--scale')
    cpu_scale = float(sys.argv[k + 1])
    del sys.argv[k:k + 2]
def first_param(m):
    for line in (M/m).read_text().splitlines():
        mm = re.match(r'param\s+(\w+)\s*=\s*([-0-9.eE]+)', line)
        if mm: return mm.group(1), float(mm.group(2))
work = {
  'ball sweep e=0.5:0.95 x20000 grad e,h0': ['sweep','models/ball.hyb','--vary','e=0.5:0.95:20000','--grad','e,h0','--threads','1','-o','/dev/null'],
  'ball sweep e=0.75:0.95 x100000 grad all': ['sweep','models/ball.hyb','--vary','e=0.75:0.95:100000','--grad','all','--threads','1','-o','/dev/null'],
}
for m in ['soft_ball.hyb','compass_gait.hyb','dosing.hyb','engine_redline.hyb','hopper.hyb','juggler.hyb','pendulum_wall.hyb','thermostat.hyb','tilted_ball.hyb','walker.hyb']:
    p, v = first_param(m)
    lo, hi = sorted([v*0.99, v*1.01])
    n = 2000 if m not in ('walker.hyb','compass_gait.hyb','juggler.hyb') else 300
    work[f'{m} sweep {p} x{n} grad all'] = ['sweep', f'models/{m}', '--vary', f'{p}={lo}:{hi}:{n}', '--grad', 'all', '--threads', '1', '-o', '/dev/null']
instructions = len(sys.argv) > 3 and sys.argv[3] == '--instructions'
def shrink(args, scale):
    """The point counts of a sweep's `--vary` multiplied by `scale` (at least 10)."""
    out = []
    for a in args:
        m = re.match(r'^(\w+=[^:]+:[^:]+:)(\d+)$', a)
        out.append(m.group(1) + str(max(10, int(int(m.group(2)) * scale))) if m else a)
    return out
if instructions:
    import tempfile
    scale = float(sys.argv[4]) if len(sys.argv) > 4 else 0.1
    def instr(b, args):
        with tempfile.NamedTemporaryFile() as f:
            r = subprocess.run(['valgrind', '--tool=callgrind', f'--callgrind-out-file={f.name}', b] + args,
                               cwd=ROOT, capture_output=True, text=True)
        return int(re.search(r'refs:\s+([\d,]+)', r.stderr).group(1).replace(',', ''))
    for name, args in work.items():
        args = shrink(args, scale)
        o, n = instr(OLD, args), instr(NEW, args)
        label = ' '.join(a for a in args if '=' in a)
        print(f'| {name} ({label}) | {o / 1e6:.0f}M | {n / 1e6:.0f}M | {n / o:.2f} |', flush=True)
    sys.exit(0)
rounds = int(sys.argv[3]) if len(sys.argv) > 3 else 5
def cpu(b, args):
    r = subprocess.run(['/usr/bin/time','-f','%U %S', b] + args, cwd=ROOT, capture_output=True, text=True)
    u, s = r.stderr.strip().splitlines()[-1].split()
    return float(u) + float(s)
for name, args in work.items():
    args = shrink(args, cpu_scale)
    old, new, ratios = [], [], []
    for _ in range(rounds):
        o = cpu(OLD, args); n = cpu(NEW, args)
        old.append(o); new.append(n); ratios.append(n / o if o > 0 else float('nan'))
    if min(old) < 0.01 <= min(new):
        print(f'| {name} | (no time: the old build cannot run it) | {statistics.median(new):.3f} s | |', flush=True)
        continue
    print(f'| {name} | {statistics.median(old):.3f} s | {statistics.median(new):.3f} s | {statistics.median(ratios):.2f} ({min(ratios):.2f}-{max(ratios):.2f}) |', flush=True)
