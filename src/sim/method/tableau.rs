//! Stage 5 (sim): Butcher tableaux of the two explicit Runge-Kutta pairs, as data. Knows no
//! models and no step loop.
//!
//! Both pairs are written in one shape: `stages` rows where the last row has `c = 1` and `a` equal
//! to the solution weights `b`, so the last stage is `f(t + h, y_new)` and is reused as the first
//! stage of the next step (FSAL). For Dormand-Prince 5(4) that is the published 7th stage; for
//! DOP853 it is Hairer's 13th function call, which his code also evaluates after every step.
//! DOP853's three extra dense-output stages (14-16) follow as rows `stages..stages+3`.
//!
//! Coefficients: Dormand & Prince (1980) with Shampine's dense output; DOP853 from Hairer, Norsett
//! & Wanner, "Solving ODEs I" (2nd ed.) and Hairer's `dop853.f`, entered by hand. The tests check
//! the order conditions that pin them down (row sums, sum of weights, polynomial exactness).
//! The stepper reads every row as its nonzero [`Terms`], extracted at compile time.

/// Which dense-output formula goes with the tableau.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum DenseKind {
    /// Hermite quartic plus one correction: 5 coefficient vectors.
    Dopri5,
    /// Hermite plus four corrections built from 16 stages: 8 coefficient vectors.
    Dop853,
}

/// A tableau as the stepper reads it: every weight row as its nonzero [`Terms`]. The full rows
/// (`DP5_A`, `DP8_D`, ...) stay next to it as the published data and for the order tests.
pub(crate) struct Tableau {
    /// Stages of one step including the FSAL stage.
    pub stages: usize,
    /// Stages including dense-output extras (equal to `stages` for Dopri5).
    pub all_stages: usize,
    pub c: &'static [f64],
    /// Row `i` holds `a[i][0..i]`; row 0 is empty.
    pub a: &'static [Terms],
    /// Error weights `b - b_hat` over `stages` (the main estimator), zeros kept: a non-finite
    /// derivative in any stage then makes the estimate NaN and the step is rejected, also when
    /// that stage has no weight in `b` or in the estimators (DOP853's stages 2 to 5).
    pub e: Terms,
    /// DOP853's 3rd-order estimator weights, combined with `e` as Hairer does.
    pub e3: Option<Terms>,
    /// Order of the solution; the controller's exponents derive from it.
    pub order: u32,
    /// Step-size controller settings that go with the pair.
    pub control: Control,
    pub dense: DenseKind,
    /// Dense-output correction weights, one row per correction vector, over `all_stages`.
    pub d: &'static [Terms],
    /// `h |lambda|` beyond which the pair's step is held by stability on the negative real axis
    /// (Hairer's stiffness-test values: 3.25 for DOPRI5, 6.1 for DOP853).
    pub stability_limit: f64,
}

/// The PI controller's settings for one pair. Both use `beta = 0.2 / q` (Hairer's default for
/// DOPRI5, 0.04) and factor bounds [0.2, 10]. Hairer's DOP853 defaults (`beta = 0`, bounds
/// [1/3, 6]) were tried: they take a third fewer steps on the thermostat but its event-time
/// gradients at rtol 1e-10 lost two digits (errors ~5e-8 against the closed form, test
/// `closed_forms`), so they are not used.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Control {
    /// Weight of the previous error (`err_prev^beta`).
    pub beta: f64,
    /// Bounds of the factor `h_new / h`.
    pub fac_min: f64,
    pub fac_max: f64,
}

/// Largest stage count of any tableau (DOP853 with its dense-output stages).
const MAX_STAGES: usize = 16;

/// The structurally nonzero weights of one tableau row as `(stage, weight)` pairs, found at
/// compile time, so the stage sums neither multiply by zero (a third of DOP853's weights) nor
/// test every weight on every step.
///
/// Invariant (the stage sums' unchecked loads rely on it): the stages strictly ascend. Both
/// constructors enumerate the row in order, and the fields are private to this module.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Terms {
    len: usize,
    stage: [usize; MAX_STAGES],
    weight: [f64; MAX_STAGES],
}

impl Terms {
    const EMPTY: Terms = Terms { len: 0, stage: [0; MAX_STAGES], weight: [0.0; MAX_STAGES] };

    const fn of(row: &[f64]) -> Terms {
        let mut t = Terms::EMPTY;
        let mut j = 0;
        while j < row.len() {
            if row[j] != 0.0 {
                t.stage[t.len] = j;
                t.weight[t.len] = row[j];
                t.len += 1;
            }
            j += 1;
        }
        t
    }

    /// Every weight of `row`, zeros included.
    const fn all(row: &[f64]) -> Terms {
        let mut t = Terms::EMPTY;
        while t.len < row.len() {
            t.stage[t.len] = t.len;
            t.weight[t.len] = row[t.len];
            t.len += 1;
        }
        t
    }

    const fn rows<const N: usize>(rows: &[&[f64]]) -> [Terms; N] {
        let mut out = [Terms::EMPTY; N];
        let mut i = 0;
        while i < N {
            out[i] = Terms::of(rows[i]);
            i += 1;
        }
        out
    }

    /// The stages with a nonzero weight, ascending.
    pub fn stages(&self) -> &[usize] {
        &self.stage[..self.len]
    }

    /// Their weights, in the same order.
    pub fn weights(&self) -> &[f64] {
        &self.weight[..self.len]
    }

    /// The largest stage with a nonzero weight (the last one: they ascend), 0 for an empty row.
    pub fn last_stage(&self) -> usize {
        self.stages().last().copied().unwrap_or(0)
    }
}

const DP5_B: [f64; 6] = [35.0 / 384.0, 0.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0];

const DP5_A: &[&[f64]] = &[
    &[],
    &[0.2],
    &[3.0 / 40.0, 9.0 / 40.0],
    &[44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0],
    &[19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0],
    &[9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0, 49.0 / 176.0, -5103.0 / 18656.0],
    &DP5_B,
];

const DP5_E: &[f64] =
    &[71.0 / 57600.0, 0.0, -71.0 / 16695.0, 71.0 / 1920.0, -17253.0 / 339200.0, 22.0 / 525.0, -1.0 / 40.0];

const DP5_D: &[&[f64]] = &[&[
    -12715105075.0 / 11282082432.0,
    0.0,
    87487479700.0 / 32700410799.0,
    -10690763975.0 / 1880347072.0,
    701980252875.0 / 199316789632.0,
    -1453857185.0 / 822651844.0,
    69997945.0 / 29380423.0,
]];

pub(crate) static DOPRI5: Tableau = Tableau {
    stages: 7,
    all_stages: 7,
    c: &[0.0, 0.2, 0.3, 0.8, 8.0 / 9.0, 1.0, 1.0],
    a: &Terms::rows::<7>(DP5_A),
    e: Terms::all(DP5_E),
    e3: None,
    order: 5,
    control: Control { beta: 0.04, fac_min: 0.2, fac_max: 10.0 },
    stability_limit: 3.25,
    dense: DenseKind::Dopri5,
    d: &Terms::rows::<1>(DP5_D),
};

// The published DOP853 values carry 30 digits; they are kept verbatim so that they can be checked
// against the source line by line.
#[allow(clippy::excessive_precision)]
const DP8_B: [f64; 12] = [
    5.42937341165687622380535766363e-2,
    0.0,
    0.0,
    0.0,
    0.0,
    4.45031289275240888144113950566e0,
    1.89151789931450038304281599044e0,
    -5.8012039600105847814672114227e0,
    3.1116436695781989440891606237e-1,
    -1.52160949662516078556178806805e-1,
    2.01365400804030348374776537501e-1,
    4.47106157277725905176885569043e-2,
];

#[allow(clippy::excessive_precision)]
const DP8_BHH: [f64; 3] = [
    0.244094488188976377952755905512e+00,
    0.733846688281611857341361741547e+00,
    0.220588235294117647058823529412e-01,
];

/// DOP853's 3rd-order error weights: `b` minus the embedded weights `bhh` on stages 1, 9, 12.
const DP8_E3: [f64; 13] = [
    DP8_B[0] - DP8_BHH[0],
    0.0,
    0.0,
    0.0,
    0.0,
    DP8_B[5],
    DP8_B[6],
    DP8_B[7],
    DP8_B[8] - DP8_BHH[1],
    DP8_B[9],
    DP8_B[10],
    DP8_B[11] - DP8_BHH[2],
    0.0,
];

#[allow(clippy::excessive_precision)]
const DP8_A: &[&[f64]] = &[
    &[],
    &[5.26001519587677318785587544488e-2],
    &[1.97250569845378994544595329183e-2, 5.91751709536136983633785987549e-2],
    &[2.95875854768068491816892993775e-2, 0.0, 8.87627564304205475450678981324e-2],
    &[
        2.41365134159266685502369798665e-1,
        0.0,
        -8.84549479328286085344864962717e-1,
        9.24834003261792003115737966543e-1,
    ],
    &[
        3.7037037037037037037037037037e-2,
        0.0,
        0.0,
        1.70828608729473871279604482173e-1,
        1.25467687566822425016691814123e-1,
    ],
    &[
        3.7109375e-2,
        0.0,
        0.0,
        1.70252211019544039314978060272e-1,
        6.02165389804559606850219397283e-2,
        -1.7578125e-2,
    ],
    &[
        3.70920001185047927108779319836e-2,
        0.0,
        0.0,
        1.70383925712239993810214054705e-1,
        1.07262030446373284651809199168e-1,
        -1.53194377486244017527936158236e-2,
        8.27378916381402288758473766002e-3,
    ],
    &[
        6.24110958716075717114429577812e-1,
        0.0,
        0.0,
        -3.36089262944694129406857109825e0,
        -8.68219346841726006818189891453e-1,
        2.75920996994467083049415600797e1,
        2.01540675504778934086186788979e1,
        -4.34898841810699588477366255144e1,
    ],
    &[
        4.77662536438264365890433908527e-1,
        0.0,
        0.0,
        -2.48811461997166764192642586468e0,
        -5.90290826836842996371446475743e-1,
        2.12300514481811942347288949897e1,
        1.52792336328824235832596922938e1,
        -3.32882109689848629194453265587e1,
        -2.03312017085086261358222928593e-2,
    ],
    &[
        -9.3714243008598732571704021658e-1,
        0.0,
        0.0,
        5.18637242884406370830023853209e0,
        1.09143734899672957818500254654e0,
        -8.14978701074692612513997267357e0,
        -1.85200656599969598641566180701e1,
        2.27394870993505042818970056734e1,
        2.49360555267965238987089396762e0,
        -3.0467644718982195003823669022e0,
    ],
    &[
        2.27331014751653820792359768449e0,
        0.0,
        0.0,
        -1.05344954667372501984066689879e1,
        -2.00087205822486249909675718444e0,
        -1.79589318631187989172765950534e1,
        2.79488845294199600508499808837e1,
        -2.85899827713502369474065508674e0,
        -8.87285693353062954433549289258e0,
        1.23605671757943030647266201528e1,
        6.43392746015763530355970484046e-1,
    ],
    &DP8_B,
    // Dense-output stages 14, 15, 16 (index 12 is the FSAL stage f(t + h, y_new)).
    &[
        5.61675022830479523392909219681e-2,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        2.53500210216624811088794765333e-1,
        -2.46239037470802489917441475441e-1,
        -1.24191423263816360469010140626e-1,
        1.5329179827876569731206322685e-1,
        8.20105229563468988491666602057e-3,
        7.56789766054569976138603589584e-3,
        -8.298e-3,
    ],
    &[
        3.18346481635021405060768473261e-2,
        0.0,
        0.0,
        0.0,
        0.0,
        2.83009096723667755288322961402e-2,
        5.35419883074385676223797384372e-2,
        -5.49237485713909884646569340306e-2,
        0.0,
        0.0,
        -1.08347328697249322858509316994e-4,
        3.82571090835658412954920192323e-4,
        -3.40465008687404560802977114492e-4,
        1.41312443674632500278074618366e-1,
    ],
    &[
        -4.28896301583791923408573538692e-1,
        0.0,
        0.0,
        0.0,
        0.0,
        -4.69762141536116384314449447206e0,
        7.68342119606259904184240953878e0,
        4.06898981839711007970213554331e0,
        3.56727187455281109270669543021e-1,
        0.0,
        0.0,
        0.0,
        -1.39902416515901462129418009734e-3,
        2.9475147891527723389556272149e0,
        -9.15095847217987001081870187138e0,
    ],
];

#[allow(clippy::excessive_precision)]
const DP8_E: &[f64] = &[
    0.1312004499419488073250102996e-01,
    0.0,
    0.0,
    0.0,
    0.0,
    -0.1225156446376204440720569753e+01,
    -0.4957589496572501915214079952e+00,
    0.1664377182454986536961530415e+01,
    -0.3503288487499736816886487290e+00,
    0.3341791187130174790297318841e+00,
    0.8192320648511571246570742613e-01,
    -0.2235530786388629525884427845e-01,
    0.0,
];

#[allow(clippy::excessive_precision)]
const DP8_D: &[&[f64]] = &[
    &[
        -0.84289382761090128651353491142e+01,
        0.0,
        0.0,
        0.0,
        0.0,
        0.56671495351937776962531783590e+00,
        -0.30689499459498916912797304727e+01,
        0.23846676565120698287728149680e+01,
        0.21170345824450282767155149946e+01,
        -0.87139158377797299206789907490e+00,
        0.22404374302607882758541771650e+01,
        0.63157877876946881815570249290e+00,
        -0.88990336451333310820698117400e-01,
        0.18148505520854727256656404962e+02,
        -0.91946323924783554000451984436e+01,
        -0.44360363875948939664310572000e+01,
    ],
    &[
        0.10427508642579134603413151009e+02,
        0.0,
        0.0,
        0.0,
        0.0,
        0.24228349177525818288430175319e+03,
        0.16520045171727028198505394887e+03,
        -0.37454675472269020279518312152e+03,
        -0.22113666853125306036270938578e+02,
        0.77334326684722638389603898808e+01,
        -0.30674084731089398182061213626e+02,
        -0.93321305264302278729567221706e+01,
        0.15697238121770843886131091075e+02,
        -0.31139403219565177677282850411e+02,
        -0.93529243588444783865713862664e+01,
        0.35816841486394083752465898540e+02,
    ],
    &[
        0.19985053242002433820987653617e+02,
        0.0,
        0.0,
        0.0,
        0.0,
        -0.38703730874935176555105901742e+03,
        -0.18917813819516756882830838328e+03,
        0.52780815920542364900561016686e+03,
        -0.11573902539959630126141871134e+02,
        0.68812326946963000169666922661e+01,
        -0.10006050966910838403183860980e+01,
        0.77771377980534432092869265740e+00,
        -0.27782057523535084065932004339e+01,
        -0.60196695231264120758267380846e+02,
        0.84320405506677161018159903784e+02,
        0.11992291136182789328035130030e+02,
    ],
    &[
        -0.25693933462703749003312586129e+02,
        0.0,
        0.0,
        0.0,
        0.0,
        -0.15418974869023643374053993627e+03,
        -0.23152937917604549567536039109e+03,
        0.35763911791061412378285349910e+03,
        0.93405324183624310003907691704e+02,
        -0.37458323136451633156875139351e+02,
        0.10409964950896230045147246184e+03,
        0.29840293426660503123344363579e+02,
        -0.43533456590011143754432175058e+02,
        0.96324553959188282948394950600e+02,
        -0.39177261675615439165231486172e+02,
        -0.14972683625798562581422125276e+03,
    ],
];

#[allow(clippy::excessive_precision)]
pub(crate) static DOP853: Tableau = Tableau {
    stages: 13,
    all_stages: 16,
    c: &[
        0.0,
        0.526001519587677318785587544488e-01,
        0.789002279381515978178381316732e-01,
        0.118350341907227396726757197510e+00,
        0.281649658092772603273242802490e+00,
        0.333333333333333333333333333333e+00,
        0.25e+00,
        0.307692307692307692307692307692e+00,
        0.651282051282051282051282051282e+00,
        0.6e+00,
        0.857142857142857142857142857142e+00,
        1.0,
        1.0,
        0.1,
        0.2,
        0.777777777777777777777777777778e+00,
    ],
    a: &Terms::rows::<16>(DP8_A),
    e: Terms::all(DP8_E),
    e3: Some(Terms::of(&DP8_E3)),
    order: 8,
    control: Control { beta: 0.025, fac_min: 0.2, fac_max: 10.0 },
    stability_limit: 6.1,
    dense: DenseKind::Dop853,
    d: &Terms::rows::<4>(DP8_D),
};

#[cfg(test)]
mod tests {
    use super::*;

    /// The published rows of one tableau.
    struct Rows {
        a: &'static [&'static [f64]],
        e: &'static [f64],
        e3: Option<&'static [f64]>,
        d: &'static [&'static [f64]],
    }

    const DP5: Rows = Rows { a: DP5_A, e: DP5_E, e3: None, d: DP5_D };
    const DP8: Rows = Rows { a: DP8_A, e: DP8_E, e3: Some(&DP8_E3), d: DP8_D };

    fn check_rows(t: &Tableau, rows: &Rows) {
        assert_eq!(rows.a.len(), t.all_stages);
        assert_eq!(t.c.len(), t.all_stages);
        for (i, row) in rows.a.iter().enumerate() {
            assert_eq!(row.len(), i, "row {i} length");
            // Row sums equal the nodes: the consistency condition every RK method satisfies.
            let sum: f64 = row.iter().sum();
            assert!((sum - t.c[i]).abs() < 1e-14, "row {i}: sum {sum} vs c {}", t.c[i]);
        }
        let b = rows.a[t.stages - 1];
        assert!((b.iter().sum::<f64>() - 1.0).abs() < 1e-14);
        assert_eq!(rows.e.len(), t.stages);
        for row in rows.d {
            assert_eq!(row.len(), t.all_stages);
        }
        // The stepper's sparse rows hold exactly the nonzero weights; the main error row all.
        let same = |terms: &Terms, row: &[f64]| {
            let nonzero: Vec<(usize, f64)> =
                row.iter().copied().enumerate().filter(|&(_, w)| w != 0.0).collect();
            let kept: Vec<(usize, f64)> =
                terms.stages().iter().copied().zip(terms.weights().iter().copied()).collect();
            assert_eq!(kept, nonzero);
        };
        assert_eq!(t.a.len(), rows.a.len());
        t.a.iter().zip(rows.a).for_each(|(terms, row)| same(terms, row));
        assert_eq!(t.d.len(), rows.d.len());
        t.d.iter().zip(rows.d).for_each(|(terms, row)| same(terms, row));
        let all: Vec<(usize, f64)> =
            t.e.stages().iter().copied().zip(t.e.weights().iter().copied()).collect();
        assert_eq!(all, rows.e.iter().copied().enumerate().collect::<Vec<_>>());
        // The stepper sums these rows centred on the first stage (`sums::centred_sum`), which is
        // exact only because their weights sum to zero (an estimator of `b - b_hat`; a dense
        // correction that vanishes when every stage derivative is the same).
        let zero_sum = |row: &[f64], what: &str| {
            let sum: f64 = row.iter().sum();
            let size: f64 = row.iter().map(|w| w.abs()).sum();
            assert!(sum.abs() <= 1e-15 * size, "{what}: weights sum to {sum}");
        };
        zero_sum(rows.e, "error row");
        rows.e3.iter().for_each(|e3| zero_sum(e3, "3rd-order error row"));
        rows.d.iter().for_each(|d| zero_sum(d, "dense row"));
        assert_eq!(t.e3.is_some(), rows.e3.is_some());
        if let (Some(terms), Some(row)) = (&t.e3, rows.e3) {
            same(terms, row);
        }
    }

    #[test]
    fn dopri5_rows_are_consistent() {
        check_rows(&DOPRI5, &DP5);
    }

    #[test]
    fn dop853_rows_are_consistent() {
        check_rows(&DOP853, &DP8);
        // sum b_i c_i^(q-1) = 1/q up to order 8 (quadrature conditions).
        let b = DP8_A[12];
        for q in 1..=8 {
            let s: f64 = b.iter().zip(DOP853.c).map(|(bi, ci)| bi * ci.powi(q - 1)).sum();
            assert!((s - 1.0 / q as f64).abs() < 1e-13, "quadrature order {q}: {s}");
        }
    }
}
