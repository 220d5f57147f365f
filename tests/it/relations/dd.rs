//! The numbers of the exact reference: double-double values (about 106 bits, Dekker's and
//! Knuth's error-free transformations on `f64`, `mul_add` for the exact product) and dual
//! numbers over them (a value and its gradient with respect to the model's parameters), so that
//! a reference event time and its gradient come from the same algebra. Far more precise than any
//! run at rtol >= 1e-12: the reference's own error is below 1e-25 relative on the generated
//! models, so every discrepancy the harness reports is hybc's.

use std::cmp::Ordering;
use std::ops::{Add, Div, Mul, Neg, Sub};

/// `hi + lo` with `|lo| <= ulp(hi) / 2`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Dd {
    pub hi: f64,
    pub lo: f64,
}

fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

fn quick_two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    (s, b - (s - a))
}

impl Dd {
    pub const ZERO: Dd = Dd { hi: 0.0, lo: 0.0 };

    pub fn new(x: f64) -> Dd {
        Dd { hi: x, lo: 0.0 }
    }

    pub fn f64(self) -> f64 {
        self.hi + self.lo
    }

    pub fn abs(self) -> Dd {
        if self.hi < 0.0 || (self.hi == 0.0 && self.lo < 0.0) {
            -self
        } else {
            self
        }
    }

    /// -1, 0 or 1.
    pub fn signum(self) -> f64 {
        if self.hi > 0.0 || (self.hi == 0.0 && self.lo > 0.0) {
            1.0
        } else if self.hi < 0.0 || (self.hi == 0.0 && self.lo < 0.0) {
            -1.0
        } else {
            0.0
        }
    }

    pub fn is_finite(self) -> bool {
        self.hi.is_finite() && self.lo.is_finite()
    }
}

impl Add for Dd {
    type Output = Dd;
    fn add(self, b: Dd) -> Dd {
        let (s, e) = two_sum(self.hi, b.hi);
        let (t, f) = two_sum(self.lo, b.lo);
        let (s, e) = quick_two_sum(s, e + t);
        let (hi, lo) = quick_two_sum(s, e + f);
        Dd { hi, lo }
    }
}

impl Neg for Dd {
    type Output = Dd;
    fn neg(self) -> Dd {
        Dd { hi: -self.hi, lo: -self.lo }
    }
}

impl Sub for Dd {
    type Output = Dd;
    fn sub(self, b: Dd) -> Dd {
        self + (-b)
    }
}

impl Mul for Dd {
    type Output = Dd;
    fn mul(self, b: Dd) -> Dd {
        let p = self.hi * b.hi;
        let e = self.hi.mul_add(b.hi, -p);
        let (hi, lo) = quick_two_sum(p, e + (self.hi * b.lo + self.lo * b.hi));
        Dd { hi, lo }
    }
}

impl Div for Dd {
    type Output = Dd;
    fn div(self, b: Dd) -> Dd {
        // Two Newton corrections of the quotient of the leading parts.
        let q1 = self.hi / b.hi;
        let r = self - b * Dd::new(q1);
        let q2 = r.hi / b.hi;
        let r = r - b * Dd::new(q2);
        let q3 = r.hi / b.hi;
        let (hi, lo) = quick_two_sum(q1, q2);
        Dd { hi, lo } + Dd::new(q3)
    }
}

impl PartialOrd for Dd {
    fn partial_cmp(&self, b: &Dd) -> Option<Ordering> {
        match self.hi.partial_cmp(&b.hi) {
            Some(Ordering::Equal) => self.lo.partial_cmp(&b.lo),
            other => other,
        }
    }
}

/// A value with its gradient with respect to the model's parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct Dual {
    pub v: Dd,
    pub d: Vec<Dd>,
}

impl Dual {
    pub fn constant(v: f64, m: usize) -> Dual {
        Dual { v: Dd::new(v), d: vec![Dd::ZERO; m] }
    }

    pub fn of_dd(v: Dd, m: usize) -> Dual {
        Dual { v, d: vec![Dd::ZERO; m] }
    }

    /// Parameter `j` of `m`, with value `v`.
    pub fn param(v: f64, j: usize, m: usize) -> Dual {
        let mut d = vec![Dd::ZERO; m];
        d[j] = Dd::new(1.0);
        Dual { v: Dd::new(v), d }
    }

    pub fn scale(&self, k: Dd) -> Dual {
        Dual { v: self.v * k, d: self.d.iter().map(|&x| x * k).collect() }
    }

    pub fn gradient(&self) -> Vec<f64> {
        self.d.iter().map(|x| x.f64()).collect()
    }
}

impl Add<&Dual> for &Dual {
    type Output = Dual;
    fn add(self, b: &Dual) -> Dual {
        Dual { v: self.v + b.v, d: self.d.iter().zip(&b.d).map(|(&x, &y)| x + y).collect() }
    }
}

impl Sub<&Dual> for &Dual {
    type Output = Dual;
    fn sub(self, b: &Dual) -> Dual {
        Dual { v: self.v - b.v, d: self.d.iter().zip(&b.d).map(|(&x, &y)| x - y).collect() }
    }
}

// The product and quotient rules: sums inside a product are the derivative's, not a slip.
#[allow(clippy::suspicious_arithmetic_impl)]
impl Mul<&Dual> for &Dual {
    type Output = Dual;
    fn mul(self, b: &Dual) -> Dual {
        Dual { v: self.v * b.v, d: self.d.iter().zip(&b.d).map(|(&x, &y)| x * b.v + self.v * y).collect() }
    }
}

#[allow(clippy::suspicious_arithmetic_impl)]
impl Div<&Dual> for &Dual {
    type Output = Dual;
    fn div(self, b: &Dual) -> Dual {
        let q = self.v / b.v;
        Dual { v: q, d: self.d.iter().zip(&b.d).map(|(&x, &y)| (x - q * y) / b.v).collect() }
    }
}

impl Neg for &Dual {
    type Output = Dual;
    fn neg(self) -> Dual {
        Dual { v: -self.v, d: self.d.iter().map(|&x| -x).collect() }
    }
}

#[test]
fn double_double_carries_what_a_double_drops() {
    let third = Dd::new(1.0) / Dd::new(3.0);
    let back = third * Dd::new(3.0) - Dd::new(1.0);
    assert!(back.abs().f64() < 1e-31, "{back:?}");
    let tiny = Dd::new(1.0) + Dd::new(1e-20);
    assert_eq!((tiny - Dd::new(1.0)).f64(), 1e-20);
    let x = Dual::param(2.0, 0, 1);
    let y = &(&x * &x) / &x;
    assert_eq!((y.v.f64(), y.d[0].f64()), (2.0, 1.0));
}
