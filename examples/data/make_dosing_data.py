"""Synthetic measurements for `hybc fit models/dosing.hyb --data examples/data/dosing_conc.csv`.

The plasma concentration of models/dosing.hyb in closed form (one compartment, first-order
absorption, two oral doses: each dose D at t_d adds D ka / (V (ka - ke)) (exp(-ke s) - exp(-ka s))
for s = t - t_d > 0), at the true rates ka = 1.3 /h and ke = 0.25 /h (the model's defaults are 1
and 0.2), every half hour from 0.5 h to 12 h, with Gaussian noise of standard deviation 0.02 mg/L
from a fixed seed. Standard library only:

    python3 examples/data/make_dosing_data.py > examples/data/dosing_conc.csv
"""

import math
import random

KA, KE = 1.3, 0.25
DOSE, T_DOSE, TAU, V = 100.0, 2.0, 6.0, 40.0
SIGMA = 0.02
SEED = 26


def conc(t: float) -> float:
    total = 0.0
    for t_d in (T_DOSE, T_DOSE + TAU):
        s = t - t_d
        if s > 0:
            total += DOSE * KA / (KA - KE) * (math.exp(-KE * s) - math.exp(-KA * s))
    return total / V


def main() -> None:
    rng = random.Random(SEED)
    print("time,conc,sigma_conc")
    for k in range(1, 25):
        t = 0.5 * k
        print(f"{t},{conc(t) + rng.gauss(0.0, SIGMA):.6f},{SIGMA}")


if __name__ == "__main__":
    main()
