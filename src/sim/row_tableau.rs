//! Stage 5 (sim): the coefficients of the Rosenbrock (ROW) methods, in the transformed form of
//! Hairer & Wanner (Solving ODEs II, IV.7, eq. 7.4') that `rosenbrock.rs` steps with: with
//! `W = I / (h gamma) - J`,
//!
//! `W k_i = F(t0 + c_i h, z0 + sum_{j<i} a_ij k_j) + sum_{j<i} (C_ij / h) k_j + h d_i F_t`,
//!
//! `z1 = z0 + sum_j b_j k_j`. Both methods here are stiffly accurate: their last stages are
//! evaluated at `t0 + h` from inputs `z0 + sum a_ij k_j` that already are the embedded and final
//! solutions, so `b` is the last row of `a` plus the last stage, the embedded solution is the last
//! stage's input and the error estimate is the last stage `k_s` itself.
//!
//! Dense output (`rosenbrock::RowDense`): with `theta = (t - t0) / h` and the vectors
//! `q_r = sum_j H_rj k_j`,
//! `z(theta) = (1 - theta) z0 + theta (z1 + (1 - theta) (q_0 + theta (q_1 + theta q_2)))`
//! (Rodas4 has `q_0, q_1`, Rodas5P `q_0 .. q_2`).
//!
//! Sources (published data; the values below are those of OrdinaryDiffEq.jl's
//! `rosenbrock_tableaus.jl`, read through the search tool, `Rodas4Tableau` and
//! `Rodas5PTableau`):
//! - Rodas4: E. Hairer, G. Wanner, Solving ODEs II, 2nd ed., Springer 1996, IV.7 (the RODAS code);
//!   order 4, embedded 3, 6 stages, dense output of order 3.
//! - Rodas5P: G. Steinebach, "Construction of Rosenbrock-Wanner method Rodas5P and numerical
//!   benchmarks within the Julia Differential Equations package", BIT Numer. Math. 63 (2023);
//!   order 5, embedded 4, 8 stages, dense output of order 4.
//!
//! The order conditions are checked numerically by the tests of `rosenbrock.rs` (observed
//! convergence orders on a linear and a nonlinear non-autonomous problem) and below (row
//! consistency).

// The coefficients are kept exactly as published (trailing zeros and all), so that they can be
// compared with the sources digit by digit.
#![allow(clippy::excessive_precision)]

/// A Rosenbrock method in the transformed form above.
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
    /// Stage inputs: `a[i]` holds `a_ij` for `j < i` (row 0 empty).
    pub a: &'static [&'static [f64]],
    /// Stage couplings: `cm[i]` holds `C_ij` for `j < i`.
    pub cm: &'static [&'static [f64]],
    /// Stage times `c_i`.
    pub c: &'static [f64],
    /// Time-derivative weights `d_i` (`gamma_i` of Hairer & Wanner).
    pub d: &'static [f64],
    /// Dense-output rows `H_r` over the stages.
    pub dense: &'static [&'static [f64]],
}

const RODAS4_A51: f64 = 1.221224509226641;
const RODAS4_A52: f64 = 6.019134481288629;
const RODAS4_A53: f64 = 12.53708332932087;
const RODAS4_A54: f64 = -0.6878860361058950;

/// Rodas4 (Hairer & Wanner).
pub static RODAS4: RowTableau = RowTableau {
    name: "rodas4",
    stages: 6,
    order: 4,
    embedded: 3,
    gamma: 0.25,
    a: &[
        &[],
        &[1.544000000000000],
        &[0.9466785280815826, 0.2557011698983284],
        &[3.314825187068521, 2.896124015972201, 0.9986419139977817],
        &[RODAS4_A51, RODAS4_A52, RODAS4_A53, RODAS4_A54],
        &[RODAS4_A51, RODAS4_A52, RODAS4_A53, RODAS4_A54, 1.0],
    ],
    cm: &[
        &[],
        &[-5.668800000000000],
        &[-2.430093356833875, -0.2063599157091915],
        &[-0.1073529058151375, -9.594562251023355, -20.47028614809616],
        &[7.496443313967647, -10.24680431464352, -33.99990352819905, 11.70890893206160],
        &[8.083246795921522, -7.981132988064893, -31.52159432874371, 16.31930543123136, -6.058818238834054],
    ],
    c: &[0.0, 0.386, 0.21, 0.63, 1.0, 1.0],
    d: &[0.25, -0.1043, 0.1035, -0.03620000000000023, 0.0, 0.0],
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

const R5P_A61: f64 = -7.502846399306121;
const R5P_A62: f64 = 2.561846144803919;
const R5P_A63: f64 = -11.627539656261098;
const R5P_A64: f64 = -0.18268767659942256;
const R5P_A65: f64 = 0.030198172008377946;

/// Rodas5P (Steinebach 2023).
pub static RODAS5P: RowTableau = RowTableau {
    name: "rodas5p",
    stages: 8,
    order: 5,
    embedded: 4,
    gamma: 0.21193756319429014,
    a: &[
        &[],
        &[3.0],
        &[2.849394379747939, 0.45842242204463923],
        &[-6.954028509809101, 2.489845061869568, -10.358996098473584],
        &[2.8029986275628964, 0.5072464736228206, -0.3988312541770524, -0.04721187230404641],
        &[R5P_A61, R5P_A62, R5P_A63, R5P_A64, R5P_A65],
        &[R5P_A61, R5P_A62, R5P_A63, R5P_A64, R5P_A65, 1.0],
        &[R5P_A61, R5P_A62, R5P_A63, R5P_A64, R5P_A65, 1.0, 1.0],
    ],
    cm: &[
        &[],
        &[-14.155112264123755],
        &[-17.97296035885952, -2.859693295451294],
        &[147.12150275711716, -1.41221402718213, 71.68940251302358],
        &[165.43517024871676, -0.4592823456491126, 42.90938336958603, -5.961986721573306],
        &[24.854864614690072, -3.0009227002832186, 47.4931110020768, 5.5814197821558125, -0.6610691825249471],
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The rows have the shapes the stepper indexes, and the stage times are the row sums of
    /// `a` scaled back by `gamma`: in the transformed form `c_i = sum_j alpha_ij`, and since
    /// `a = alpha Gamma^-1` this is not checkable directly; what is checkable is `c = 1` for the
    /// stiffly accurate last stages and `d_0 = gamma` (`gamma_1 = gamma_11`).
    #[test]
    fn rows_have_their_shapes() {
        for tab in [&RODAS4, &RODAS5P] {
            assert_eq!(tab.a.len(), tab.stages);
            assert_eq!(tab.cm.len(), tab.stages);
            assert_eq!(tab.c.len(), tab.stages);
            assert_eq!(tab.d.len(), tab.stages);
            for i in 0..tab.stages {
                assert_eq!(tab.a[i].len(), i, "{} a row {i}", tab.name);
                assert_eq!(tab.cm[i].len(), i, "{} C row {i}", tab.name);
            }
            for row in tab.dense {
                assert_eq!(row.len(), tab.stages);
            }
            assert_eq!(tab.d[0], tab.gamma);
            assert_eq!(tab.c[tab.stages - 1], 1.0);
        }
    }
}
