//! A finished Sobol' analysis with names attached: the table `hybc sobol` prints and its JSON
//! object (field names are a contract, docs/sobol.md). No IO.

use serde_json::{json, Map, Value};

use super::{AnalysisError, Evaluated, OutputIndices, Z_95};

/// An analysis's indices with what went into them.
#[derive(Clone, Debug)]
pub struct SobolReport {
    /// The model's name.
    pub model: String,
    /// The varied parameters, in the design's order.
    pub params: Vec<String>,
    /// Base points of the design.
    pub n: usize,
    /// Rows per base point (`D + 2`, or `2 D + 2` with second order).
    pub block: usize,
    /// Rows of the design (runs).
    pub rows: usize,
    /// Whether second-order indices were estimated.
    pub second_order: bool,
    /// The seed of the design and of the bootstrap.
    pub seed: u64,
    /// Bootstrap resamples (0: no intervals).
    pub bootstrap: usize,
    /// The policy for rows without a value, as the user wrote it.
    pub on_fail: String,
    /// Every row's outputs and how the runs ended.
    pub evaluated: Evaluated,
    /// Each output's indices, or why it has none, in the order asked for.
    pub outputs: Vec<Result<OutputIndices, AnalysisError>>,
}

impl SobolReport {
    /// The outputs without indices (their policy refused the rows without a value).
    pub fn failures(&self) -> impl Iterator<Item = &AnalysisError> {
        self.outputs.iter().filter_map(|r| r.as_ref().err())
    }

    /// `zeno 3318 (the first is row 6)`, or `none`.
    fn ended_early(&self) -> String {
        if self.evaluated.ended_early.is_empty() {
            return "none".into();
        }
        let parts: Vec<String> = self.evaluated.ended_early.iter().map(|(w, c)| format!("{w} {c}")).collect();
        format!(
            "{} (the first is row {})",
            parts.join(", "),
            self.evaluated.first_ended_early.map_or(0, |r| r + 1)
        )
    }

    /// The table `hybc sobol` prints. An output without indices is one line, `no indices`: the
    /// error that says why goes to standard error, once.
    pub fn to_table(&self) -> String {
        let mut s = format!(
            "sobol: model {}, {} parameters ({}), N = {} base points, {} runs ({} per base point), seed {}\n",
            self.model,
            self.params.len(),
            self.params.join(", "),
            self.n,
            self.rows,
            self.block,
            self.seed
        );
        s += &format!("runs that ended early: {}\n", self.ended_early());
        let conf = self.bootstrap > 0;
        if conf {
            s += &format!(
                "intervals: +/- 1.96 bootstrap standard errors ({} resamples of the base points), 95%\n",
                self.bootstrap
            );
        }
        let width = self.params.iter().map(|n| n.len()).max().unwrap_or(0).max(9);
        let num = |v: f64| if v.is_finite() { format!("{v:>10.4}") } else { format!("{:>10}", "-") };
        for result in &self.outputs {
            s.push('\n');
            let r = match result {
                Ok(r) => r,
                Err(e) => {
                    s += &format!("output {}: no indices\n", e.label());
                    continue;
                }
            };
            s += &format!(
                "output {}: {} base points used, {} dropped, {} rows without a value, variance {}\n",
                r.label,
                r.used_points,
                r.dropped_points,
                r.failed_rows,
                crate::sim::short(r.indices.variance)
            );
            s += &format!("  {:<width$} {:>10}", "parameter", "S1");
            if conf {
                s += &format!(" {:>10}", "S1_conf");
            }
            s += &format!(" {:>10}", "ST");
            if conf {
                s += &format!(" {:>10}", "ST_conf");
            }
            s.push('\n');
            for (i, name) in self.params.iter().enumerate() {
                s += &format!("  {name:<width$} {}", num(r.indices.s1[i]));
                if let Some(e) = &r.errors {
                    s += &format!(" {}", num(Z_95 * e.s1[i]));
                }
                s += &format!(" {}", num(r.indices.st[i]));
                if let Some(e) = &r.errors {
                    s += &format!(" {}", num(Z_95 * e.st[i]));
                }
                s.push('\n');
            }
            for (k, (i, j, v)) in r.indices.s2.iter().enumerate() {
                s += &format!("  S2 {} {}: {}", self.params[*i], self.params[*j], num(*v).trim_start());
                if let Some(e) = &r.errors {
                    s += &format!(" +/- {}", num(Z_95 * e.s2[k].2).trim_start());
                }
                s.push('\n');
            }
        }
        s
    }

    /// The JSON object `hybc sobol --format json` prints (docs/sobol.md).
    pub fn to_json(&self) -> Value {
        let d = self.params.len();
        let mut top = Map::new();
        top.insert("model".into(), json!(self.model));
        top.insert("parameters".into(), json!(self.params));
        top.insert("n".into(), json!(self.n));
        top.insert("runs".into(), json!(self.rows));
        top.insert("second_order".into(), json!(self.second_order));
        top.insert("seed".into(), json!(self.seed));
        top.insert("bootstrap".into(), json!(self.bootstrap));
        top.insert("conf_level".into(), json!(0.95));
        top.insert("on_fail".into(), json!(self.on_fail));
        let early: Map<String, Value> =
            self.evaluated.ended_early.iter().map(|(w, c)| (w.to_string(), json!(c))).collect();
        top.insert("ended_early".into(), Value::Object(early));
        top.insert("first_ended_early_row".into(), json!(self.evaluated.first_ended_early.map(|r| r + 1)));
        let conf = |v: &[f64]| -> Value { v.iter().map(|s| json!(Z_95 * s)).collect() };
        let outputs: Vec<Value> = self
            .outputs
            .iter()
            .map(|result| match result {
                Err(e) => json!({ "name": e.label(), "error": e.to_string() }),
                Ok(r) => {
                    let mut o = Map::new();
                    o.insert("name".into(), json!(r.label));
                    o.insert("failed_rows".into(), json!(r.failed_rows));
                    o.insert("dropped_base_points".into(), json!(r.dropped_points));
                    o.insert("base_points".into(), json!(r.used_points));
                    o.insert("variance".into(), json!(r.indices.variance));
                    o.insert("S1".into(), json!(r.indices.s1));
                    o.insert("ST".into(), json!(r.indices.st));
                    if let Some(e) = &r.errors {
                        o.insert("S1_conf".into(), conf(&e.s1));
                        o.insert("ST_conf".into(), conf(&e.st));
                    }
                    if self.second_order {
                        // A D x D matrix with null off the upper triangle, as SALib's S2.
                        let matrix = |pick: &dyn Fn(usize) -> f64| -> Value {
                            let mut m = vec![vec![Value::Null; d]; d];
                            for (k, (i, j, _)) in r.indices.s2.iter().enumerate() {
                                m[*i][*j] = json!(pick(k));
                            }
                            json!(m)
                        };
                        o.insert("S2".into(), matrix(&|k| r.indices.s2[k].2));
                        if let Some(e) = &r.errors {
                            o.insert("S2_conf".into(), matrix(&|k| Z_95 * e.s2[k].2));
                        }
                    }
                    Value::Object(o)
                }
            })
            .collect();
        top.insert("outputs".into(), Value::Array(outputs));
        Value::Object(top)
    }
}
