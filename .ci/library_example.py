"""The library example of docs/cli.md (examples/library, an outside crate built without hybc's default
features) must print the numbers `hybc run` prints for the same run: every event time, the energy
and dE/de, equal as f64. Run from the repository root with the two commands' outputs as files."""
import json
import re
import sys

example, run_json = open(sys.argv[1]).read(), json.load(open(sys.argv[2]))
lines = example.strip().splitlines()
times = [float(line) for line in lines[:-1]]
energy, denergy = (float(m) for m in re.findall(r"Some\(([^)]*)\)", lines[-1]))
expected_times = [e["time"] for e in run_json["events"]]
expected = (run_json["final"]["outputs"]["energy"], run_json["final"]["doutputs"]["energy"]["e"])
if times != expected_times or (energy, denergy) != expected:
    sys.exit(f"library example printed {times} {energy} {denergy}, hybc run {expected_times} {expected}")
print(f"library example: {len(times)} event times, energy and dE/de equal to hybc run's")
