//! Stage 5 (sim): the coefficients of the Rosenbrock (ROW) methods, in the original form of
//! Hairer & Wanner (Solving ODEs II, IV.7, eq. 7.4) that `rosenbrock.rs` steps with: with
//! `W = I - h gamma J`,
//!
//! `W k_i = h F(t0 + c_i h, z0 + sum_{j<i} alpha_ij k_j) + h J sum_{j<i} Gamma_ij k_j
//! + d_i h^2 F_t`,
//!
//! `z1 = z0 + sum_j b_j k_j`, and the error estimate `z1 - z1^ = sum_j e_j k_j`. Both methods are
//! stiffly accurate: `b = alpha_s + Gamma_s` (the last stage's input is the embedded solution,
//! `e = Gamma_s`).
//!
//! Dense output (`rosenbrock::RowDense`): with `theta = (t - t0) / h` and the vectors
//! `q_r = sum_j H_rj k_j`,
//! `z(theta) = (1 - theta) z0 + theta (z1 + (1 - theta) (q_0 + theta (q_1 + theta q_2)))`
//! (Rodas4 has `q_0, q_1`, Rodas5P `q_0 .. q_2`).
//!
//! Sources: the published coefficients (those of OrdinaryDiffEq.jl's `rosenbrock_tableaus.jl`,
//! `Rodas4Tableau` and `Rodas5PTableau`, read through the search tool; kept digit for digit in
//! the tests below) are of the *transformed* form (`a`, `C`, `gamma`, `c`, `d`, `H`):
//! - Rodas4: E. Hairer, G. Wanner, Solving ODEs II, 2nd ed., Springer 1996, IV.7 (the RODAS code);
//!   order 4, embedded 3, 6 stages, dense output of order 3.
//! - Rodas5P: G. Steinebach, "Construction of Rosenbrock-Wanner method Rodas5P and numerical
//!   benchmarks within the Julia Differential Equations package", BIT Numer. Math. 63 (2023);
//!   order 5, embedded 4, 8 stages, dense output of order 4.
//!
//! The repair (why the original form). The transformed form's coefficients reach 165 in size
//! (Rodas5P's `C`), and its stages cancel terms of size 80 to give values of size 1: a clock
//! `y' = 1` came out as `h (1 + 1e-14)` per step, and the 16-digit decimals satisfy the order
//! conditions only to 6e-15 (Rodas4: 8e-16). A clock drifted by some ulps per step, and events on
//! it landed ulps away from where the explicit pairs put them exactly. The original form's
//! coefficients are below 7, and on a clock each stage is `h` exactly. They are computed by
//! `tools/row_tableau.py` from the published decimals in exact rational arithmetic
//! (`Gamma = (diag(1/gamma) - C)^-1`, `alpha = a Gamma`, `b = alpha_s + Gamma_s`,
//! `H_original = H Gamma`), and then repaired: the first coefficient of each linear condition
//! (`gamma + sum_j Gamma_ij = d_i`, `sum_j alpha_ij = c_i`, `sum b = 1`, `sum e = 0`, and
//! `sum_j H_rj = 0`: the dense output of a clock is its line) recomputed exactly from the others
//! before the single rounding; then, for the sums the stepper forms on a clock (whose stage
//! slopes are all exactly 1), an entry or two nudged by a few ulps until the f64 sum, left to
//! right, is exact too. The repair moves no coefficient by more than 1.2e-13 (Rodas5P's `H`,
//! whose published rows summed to 1e-13 instead of 0), 1.1e-15 for Rodas4; in exact arithmetic
//! the order conditions up to order 4 then hold to 1e-15 (Rodas5P's sum b = 1 was 1 + 5.5e-15).
//! The tests below check the derivation against the published decimals, the order
//! conditions to a few ulps, and a clock's step to an ulp; `rosenbrock.rs`'s tests check the
//! observed orders.

// The derived coefficients are printed by `tools/row_tableau.py` as the shortest decimals that
// round-trip, and the published ones are kept as published.
#![allow(clippy::excessive_precision)]

/// A Rosenbrock method in the original form above.
#[derive(Debug)]
pub struct RowTableau {
    pub name: &'static str,
    pub stages: usize,
    /// Order of the solution (checked by the convergence tests).
    #[cfg_attr(not(test), allow(dead_code))]
    pub order: usize,
    /// Order of the embedded solution: the error estimate is `O(h^(embedded + 1))`.
    pub embedded: usize,
    pub gamma: f64,
    /// Stage inputs: `alpha[i]` holds `alpha_ij` for `j < i` (row 0 empty).
    pub alpha: &'static [&'static [f64]],
    /// Stage couplings through the Jacobian: `gam[i]` holds `Gamma_ij` for `j < i`.
    pub gam: &'static [&'static [f64]],
    /// Solution weights.
    pub b: &'static [f64],
    /// Error-estimate weights `b - b^`.
    pub e: &'static [f64],
    /// Stage times `c_i = sum_j alpha_ij`.
    pub c: &'static [f64],
    /// Time-derivative weights `d_i = gamma + sum_j Gamma_ij` (`gamma_i` of Hairer & Wanner).
    pub d: &'static [f64],
    /// Dense-output rows `H_r` over the stages.
    pub dense: &'static [&'static [f64]],
}

/// Rodas4 (Hairer & Wanner).
pub static RODAS4: RowTableau = RowTableau {
    name: "rodas4",
    stages: 6,
    order: 4,
    embedded: 3,
    gamma: 0.25,
    alpha: &[
        &[],
        &[0.386],
        &[0.1460747075254179, 0.06392529247458209],
        &[-0.33081150366773016, 0.7111510251682848, 0.24966047849944542],
        &[-4.5525571863180305, 1.7101813632413319, 4.014347332103172, -0.17197150902647357],
        &[2.428633765466989, -0.38274873376478463, -1.8557203309295804, 0.5598352992273763, 0.25],
    ],
    gam: &[
        &[],
        &[-0.3543],
        &[-0.13360250526817555, -0.012897494731824468],
        &[1.526849173006467, -0.5336562887504572, -1.27939288425601],
        &[6.9811909517850195, -2.0929300970061164, -5.870067663032753, 0.73180680825385],
        &[
            -2.0801894941809365,
            0.5957623556766833,
            1.701617798267262,
            -0.08851451983588043,
            -0.3786761399271284,
        ],
    ],
    b: &[
        0.3484442712860523,
        0.2130136219118987,
        -0.15410253266231846,
        0.4713207793914958,
        -0.12867613992712837,
        0.25,
    ],
    e: &[
        -2.0801894941809365,
        0.5957623556766833,
        1.701617798267262,
        -0.08851451983588048,
        -0.3786761399271284,
        0.25,
    ],
    c: &[0.0, 0.386, 0.21, 0.63, 1.0, 1.0],
    d: &[0.25, -0.1043, 0.1035, -0.03620000000000023, 0.0, 0.0],
    dense: &[
        &[
            4.786970949445337,
            0.6966969867332767,
            -4.49196220541594,
            -1.247990161586589,
            0.25628443082391583,
            0.0,
        ],
        &[
            -12.742021716038717,
            1.8944219846936763,
            11.130209592703055,
            1.3659874200712048,
            -1.648597281429218,
            0.0,
        ],
    ],
};

/// Rodas5P (Steinebach 2023).
pub static RODAS5P: RowTableau = RowTableau {
    name: "rodas5p",
    stages: 8,
    order: 5,
    embedded: 4,
    gamma: 0.21193756319429014,
    alpha: &[
        &[],
        &[0.6358126895828704],
        &[0.31242290829798824, 0.09715693104176527],
        &[1.314082575329928, 1.8583084874257938, -2.19546039024965],
        &[0.42153145792835994, 0.25386966273008993, -0.23655479053262385, -0.010005969169959578],
        &[
            1.7120280621215367,
            2.445632033380795,
            -3.117254839827603,
            -0.046805382663106014,
            0.006400126988377644,
        ],
        &[
            -0.9993030215739275,
            -1.5559156221686077,
            3.1251564324842263,
            0.24141811637172583,
            -0.02329346830770701,
            0.21193756319429014,
        ],
        &[
            -0.00348725019926846,
            -0.12996697120564568,
            1.5259417608062797,
            1.149614094912389,
            -0.7043357115882416,
            -1.0497034859198031,
            0.21193756319429014,
        ],
    ],
    gam: &[
        &[],
        &[-0.6358126895828704],
        &[-0.4219499144476442, -0.12845036137023835],
        &[0.3876632898584038, -2.0150665034868993, 3.220110937722479],
        &[3.165730533008969, 1.357403877033835, -2.1414486119160854, -0.2677977215559399],
        &[
            -2.7113310836954634,
            -4.001547655549403,
            6.242411272311829,
            0.28822349903483196,
            -0.029693595296084705,
        ],
        &[
            0.9958157713746592,
            1.425948650962962,
            -1.5992146716779467,
            0.9081959785406633,
            -0.6810422432805345,
            -1.2616410491140932,
        ],
        &[
            0.12584733011226795,
            0.1802058530898284,
            -0.20210253993990515,
            0.11477428094984266,
            -0.0860674739989413,
            0.08161021050037438,
            -0.42620522390775706,
        ],
    ],
    b: &[
        0.12236007991299958,
        0.050238881884182705,
        1.3238392208663745,
        1.2643883758622316,
        -0.7904031855871829,
        -0.9680932754194287,
        -0.21426766071346695,
        0.21193756319429014,
    ],
    e: &[
        0.12584733011226795,
        0.1802058530898284,
        -0.20210253993990515,
        0.11477428094984266,
        -0.0860674739989413,
        0.08161021050037438,
        -0.42620522390775706,
        0.21193756319429014,
    ],
    c: &[0.0, 0.6358126895828704, 0.4095798393397535, 0.9769306725060716, 0.4288403609558664, 1.0, 1.0, 1.0],
    d: &[
        0.21193756319429014,
        -0.42387512638858027,
        -0.3384627126235924,
        1.8046452872882734,
        2.325825639765069,
        0.0,
        0.0,
        0.0,
    ],
    dense: &[
        &[
            0.8232744916805124,
            -0.3181483349120229,
            -0.1692233010408659,
            0.0498794533963211,
            -0.19831791977261218,
            -0.31488148287699214,
            0.1638750616770419,
            -0.036457968151382275,
        ],
        &[
            0.6726085201965615,
            1.3128972079521335,
            -9.467244336394309,
            -12.92452091814204,
            9.002714541842755,
            11.404611057341922,
            1.4210850083209665,
            -1.4221510811179898,
        ],
        &[
            -1.4025185206933513,
            -0.9860299407499759,
            11.00687186785749,
            14.11258551442229,
            -9.574969612795115,
            -12.076626078349427,
            -2.1142228286973404,
            1.0349095990054278,
        ],
    ],
};

#[cfg(test)]
mod tests;

/// The published transformed coefficients, digit for digit (see the module's documentation).
#[cfg(test)]
mod published {
    pub(super) struct Published {
        pub gamma: f64,
        pub a: &'static [&'static [f64]],
        pub cm: &'static [&'static [f64]],
        pub dense: &'static [&'static [f64]],
    }

    pub(super) static RODAS4_PUBLISHED: Published = Published {
        gamma: 0.25,
        a: &[
            &[],
            &[1.544000000000000],
            &[0.9466785280815826, 0.2557011698983284],
            &[3.314825187068521, 2.896124015972201, 0.9986419139977817],
            &[1.221224509226641, 6.019134481288629, 12.53708332932087, -0.6878860361058950],
            &[1.221224509226641, 6.019134481288629, 12.53708332932087, -0.6878860361058950, 1.0],
        ],
        cm: &[
            &[],
            &[-5.668800000000000],
            &[-2.430093356833875, -0.2063599157091915],
            &[-0.1073529058151375, -9.594562251023355, -20.47028614809616],
            &[7.496443313967647, -10.24680431464352, -33.99990352819905, 11.70890893206160],
            &[
                8.083246795921522,
                -7.981132988064893,
                -31.52159432874371,
                16.31930543123136,
                -6.058818238834054,
            ],
        ],
        dense: &[
            &[
                10.12623508344586,
                -7.487995877610167,
                -34.80091861555747,
                -7.992771707568823,
                1.025137723295662,
                0.0,
            ],
            &[
                -0.6762803392801253,
                6.087714651680015,
                16.43084320892478,
                24.76722511418386,
                -6.594389125716872,
                0.0,
            ],
        ],
    };

    pub(super) static RODAS5P_PUBLISHED: Published = Published {
        gamma: 0.21193756319429014,
        a: &[
            &[],
            &[3.0],
            &[2.849394379747939, 0.45842242204463923],
            &[-6.954028509809101, 2.489845061869568, -10.358996098473584],
            &[2.8029986275628964, 0.5072464736228206, -0.3988312541770524, -0.04721187230404641],
            &[
                -7.502846399306121,
                2.561846144803919,
                -11.627539656261098,
                -0.18268767659942256,
                0.030198172008377946,
            ],
            &[
                -7.502846399306121,
                2.561846144803919,
                -11.627539656261098,
                -0.18268767659942256,
                0.030198172008377946,
                1.0,
            ],
            &[
                -7.502846399306121,
                2.561846144803919,
                -11.627539656261098,
                -0.18268767659942256,
                0.030198172008377946,
                1.0,
                1.0,
            ],
        ],
        cm: &[
            &[],
            &[-14.155112264123755],
            &[-17.97296035885952, -2.859693295451294],
            &[147.12150275711716, -1.41221402718213, 71.68940251302358],
            &[165.43517024871676, -0.4592823456491126, 42.90938336958603, -5.961986721573306],
            &[
                24.854864614690072,
                -3.0009227002832186,
                47.4931110020768,
                5.5814197821558125,
                -0.6610691825249471,
            ],
            &[
                30.91273214028599,
                -3.1208243349937974,
                77.79954646070892,
                34.28646028294783,
                -19.097331116725623,
                -28.087943162872662,
            ],
            &[
                37.80277123390563,
                -3.2571969029072276,
                112.26918849496327,
                66.9347231244047,
                -40.06618937091002,
                -54.66780262877968,
                -9.48861652309627,
            ],
        ],
        dense: &[
            &[
                25.948786856663858,
                -2.5579724845846235,
                10.433815404888879,
                -2.3679251022685204,
                0.524948541321073,
                1.1241088310450404,
                0.4272876194431874,
                -0.17202221070155493,
            ],
            &[
                -9.91568850695171,
                -0.9689944594115154,
                3.0438037242978453,
                -24.495224566215796,
                20.176138334709044,
                15.98066361424651,
                -6.789040303419874,
                -6.710236069923372,
            ],
            &[
                11.419903575922262,
                2.8879645146136994,
                72.92137995996029,
                80.12511834622643,
                -52.072871366152654,
                -59.78993625266729,
                -0.15582684282751913,
                4.883087185713722,
            ],
        ],
    };
}
