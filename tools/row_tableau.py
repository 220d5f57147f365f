#!/usr/bin/env python3
"""Derives the Rosenbrock coefficients hybc steps with (src/sim/row_tableau.rs) from the
published ones, in exact rational arithmetic, and prints them as Rust.

Published (OrdinaryDiffEq.jl's rosenbrock_tableaus.jl, Rodas4Tableau and Rodas5PTableau) are the
coefficients of Hairer & Wanner's *transformed* form (a, C, gamma, c, d, H) as 16-17 digit
decimals. hybc steps with the *original* form (alpha, Gamma, b; Solving ODEs II, IV.7, eq. 7.4),
whose coefficients are of magnitude 7 instead of 165: for a clock `y' = 1` every original stage is
exactly `h`, so the step is `y0 + h sum b` to an ulp, while the transformed stages cancel
terms of size 80 and leave 1e-15 relative per step (and the decimals satisfy the order
conditions only to 6e-15). The transformation back is exact:
    Gamma^-1 = diag(1/gamma) - C,  alpha = a Gamma,  b = alpha_s + Gamma_s (stiffly accurate),
    H_original = H Gamma (dense output over the original stages).
The repair: one dependent coefficient per condition (the first column), computed exactly before
the one rounding to f64; then for the sums the stepper forms on a clock (whose stage slopes are
all exactly 1) a nudge of an entry or two by an ulp or so until the f64 sum, left to right, is
exact too:
    sum_j Gamma_ij = d_i     (gamma_i of H&W: exactness of F_t terms, y' = t)
    sum_j alpha_ij = c_i     (stage times: y' = 1 puts every stage input at y0 + c_i h)
    sum_j b_j = 1,  sum_j e_j = 0 (e = Gamma_s, the error estimate vanishes on a clock)
    sum_j H_rj = 0           (the dense output of a clock is its line)
Run: python3 tools/row_tableau.py  (prints the statics of src/sim/row_tableau.rs)."""
from fractions import Fraction as F

# Published transformed coefficients, digit for digit.
RODAS4 = dict(
    name="rodas4", gamma="0.25",
    a=[[], ["1.544000000000000"], ["0.9466785280815826", "0.2557011698983284"],
       ["3.314825187068521", "2.896124015972201", "0.9986419139977817"],
       ["1.221224509226641", "6.019134481288629", "12.53708332932087", "-0.6878860361058950"],
       ["1.221224509226641", "6.019134481288629", "12.53708332932087", "-0.6878860361058950", "1.0"]],
    cm=[[], ["-5.668800000000000"], ["-2.430093356833875", "-0.2063599157091915"],
        ["-0.1073529058151375", "-9.594562251023355", "-20.47028614809616"],
        ["7.496443313967647", "-10.24680431464352", "-33.99990352819905", "11.70890893206160"],
        ["8.083246795921522", "-7.981132988064893", "-31.52159432874371", "16.31930543123136", "-6.058818238834054"]],
    c=["0.0", "0.386", "0.21", "0.63", "1.0", "1.0"],
    d=["0.25", "-0.1043", "0.1035", "-0.03620000000000023", "0.0", "0.0"],
    dense=[["10.12623508344586", "-7.487995877610167", "-34.80091861555747", "-7.992771707568823", "1.025137723295662", "0.0"],
           ["-0.6762803392801253", "6.087714651680015", "16.43084320892478", "24.76722511418386", "-6.594389125716872", "0.0"]],
)
R5P_A6 = ["-7.502846399306121", "2.561846144803919", "-11.627539656261098", "-0.18268767659942256", "0.030198172008377946"]
RODAS5P = dict(
    name="rodas5p", gamma="0.21193756319429014",
    a=[[], ["3.0"], ["2.849394379747939", "0.45842242204463923"],
       ["-6.954028509809101", "2.489845061869568", "-10.358996098473584"],
       ["2.8029986275628964", "0.5072464736228206", "-0.3988312541770524", "-0.04721187230404641"],
       R5P_A6, R5P_A6 + ["1.0"], R5P_A6 + ["1.0", "1.0"]],
    cm=[[], ["-14.155112264123755"], ["-17.97296035885952", "-2.859693295451294"],
        ["147.12150275711716", "-1.41221402718213", "71.68940251302358"],
        ["165.43517024871676", "-0.4592823456491126", "42.90938336958603", "-5.961986721573306"],
        ["24.854864614690072", "-3.0009227002832186", "47.4931110020768", "5.5814197821558125", "-0.6610691825249471"],
        ["30.91273214028599", "-3.1208243349937974", "77.79954646070892", "34.28646028294783", "-19.097331116725623", "-28.087943162872662"],
        ["37.80277123390563", "-3.2571969029072276", "112.26918849496327", "66.9347231244047", "-40.06618937091002", "-54.66780262877968", "-9.48861652309627"]],
    c=["0.0", "0.6358126895828704", "0.4095798393397535", "0.9769306725060716", "0.4288403609558664", "1.0", "1.0", "1.0"],
    d=["0.21193756319429014", "-0.42387512638858027", "-0.3384627126235924", "1.8046452872882734", "2.325825639765069", "0.0", "0.0", "0.0"],
    dense=[["25.948786856663858", "-2.5579724845846235", "10.433815404888879", "-2.3679251022685204", "0.524948541321073", "1.1241088310450404", "0.4272876194431874", "-0.17202221070155493"],
           ["-9.91568850695171", "-0.9689944594115154", "3.0438037242978453", "-24.495224566215796", "20.176138334709044", "15.98066361424651", "-6.789040303419874", "-6.710236069923372"],
           ["11.419903575922262", "2.8879645146136994", "72.92137995996029", "80.12511834622643", "-52.072871366152654", "-59.78993625266729", "-0.15582684282751913", "4.883087185713722"]],
)


def rnd(x):
    """The nearest f64, as an exact rational."""
    return F(float(x))


def f64_sum(v):
    acc = 0.0
    for x in v:
        acc += float(x)
    return acc


def f64_sum_to(v, target):
    """`v` with its first entry recomputed exactly, `target - sum(rest)`, before rounding; then, if
    its f64 sum left to right is not yet `target` exactly, with the fewest nudges of single
    entries by up to 32 ulps (smallest entries first) that make it so. A nudge of an ulp moves the
    order conditions by an ulp of the entry, below their own round-off."""
    import math
    import itertools
    v = list(v)
    v[0] = rnd(target - sum(v[1:]))
    if f64_sum(v) == float(target):
        return v
    order = sorted((j for j, x in enumerate(v) if x != 0), key=lambda j: abs(v[j]))
    steps = [k for m in range(1, 33) for k in (m, -m)]
    for count in (1, 2):
        for js in itertools.combinations(order, count):
            for ks in itertools.product(steps, repeat=count):
                w = list(v)
                for j, k in zip(js, ks):
                    w[j] = F(float(w[j]) + k * math.ulp(float(w[j])))
                if f64_sum(w) == float(target):
                    return w
    raise ValueError(f"no nudge makes the f64 sum {target}")


def derive(T):
    s = len(T["c"])
    g = F(T["gamma"])
    cm = [[F(x) for x in r] for r in T["cm"]]
    # Gamma = (diag(1/gamma) - C)^-1, lower triangular, by columns.
    G = [[F(0)] * s for _ in range(s)]
    for j in range(s):
        G[j][j] = g
        for i in range(j + 1, s):
            G[i][j] = g * sum(cm[i][k] * G[k][j] for k in range(j, i))
    A = [[F(x) for x in r] + [F(0)] * (s - len(r)) for r in T["a"]]
    al = [[sum(A[i][k] * G[k][j] for k in range(i)) for j in range(s)] for i in range(s)]
    H = [[sum(F(row[k]) * G[k][j] for k in range(s)) for j in range(s)] for row in T["dense"]]
    c = [rnd(x) for x in T["c"]]
    d = [rnd(x) for x in T["d"]]
    gf = rnd(g)
    # Round, then make the first coefficient of each condition the dependent one, computed
    # exactly. The sums the stepper forms on a clock (whose stage slopes are all exactly 1) are
    # then made exact in f64 too, by nudging entries an ulp or two (`f64_sum_to`).
    Gr = [[rnd(G[i][j]) for j in range(i)] for i in range(s)]
    ar = [[rnd(al[i][j]) for j in range(i)] for i in range(s)]
    for i in range(1, s):
        Gr[i][0] = rnd(d[i] - gf - sum(Gr[i][1:]))
        ar[i] = f64_sum_to(ar[i], c[i])
    # b = alpha_s + Gamma_s (stiffly accurate), e = Gamma_s = b - alpha_s (the error estimate).
    b = f64_sum_to([rnd(al[s - 1][j] + G[s - 1][j]) for j in range(s)], F(1))
    e = f64_sum_to([rnd(G[s - 1][j]) for j in range(s)], F(0))
    Hr = [f64_sum_to([rnd(x) for x in row], F(0)) for row in H]
    return dict(name=T["name"], s=s, gamma=gf, alpha=ar, gam=Gr, b=b, e=e, c=c, d=d, dense=Hr,
                exact=dict(G=G, al=al, H=H))


def f(x):
    return repr(float(x))


def vec(v):
    return "&[" + ", ".join(f(x) for x in v) + "]"


def rows(name, R):
    return f"    {name}: &[\n" + "".join(f"        {vec(r)},\n" for r in R) + "    ],\n"


def rust(T, const, doc, order, embedded):
    """The Rust static of one method, as `src/sim/row_tableau.rs` holds it."""
    D = derive(T)
    out = (f"/// {doc}\npub static {const}: RowTableau = RowTableau {{\n    name: \"{T['name']}\",\n"
           f"    stages: {D['s']},\n    order: {order},\n    embedded: {embedded},\n    gamma: {f(D['gamma'])},\n")
    out += rows("alpha", D["alpha"]) + rows("gam", D["gam"])
    for k in ["b", "e", "c", "d"]:
        out += f"    {k}: {vec(D[k])},\n"
    return out + rows("dense", D["dense"]) + "};\n"


def moved(T):
    """How far the repair moved the coefficients from the exact transform of the decimals."""
    D = derive(T)
    G, al, H, s = D["exact"]["G"], D["exact"]["al"], D["exact"]["H"], D["s"]
    return max([abs(float(D["gam"][i][j] - G[i][j])) for i in range(s) for j in range(i)]
               + [abs(float(D["alpha"][i][j] - al[i][j])) for i in range(s) for j in range(i)]
               + [abs(float(D["dense"][r][j] - H[r][j])) for r in range(len(H)) for j in range(s)])


if __name__ == "__main__":
    print(f"// The repair moved no coefficient by more than {moved(RODAS4):.1e} (Rodas4), {moved(RODAS5P):.1e} (Rodas5P).")
    print(rust(RODAS4, "RODAS4", "Rodas4 (Hairer & Wanner).", 4, 3))
    print(rust(RODAS5P, "RODAS5P", "Rodas5P (Steinebach 2023).", 5, 4), end="")
