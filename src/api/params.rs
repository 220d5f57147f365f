//! Parameter values of one model, by name, range-checked.

use super::{Model, ParamError};

/// Values for every parameter of one model, starting from the declared defaults. Setting a value
/// checks the name (an unknown one is an error naming the closest), finiteness and the declared
/// range.
#[derive(Clone, Debug)]
pub struct Params {
    model: Model,
    values: Vec<f64>,
}

impl Params {
    pub(crate) fn defaults(model: Model) -> Params {
        let values = model.checked().params.iter().map(|p| p.default).collect();
        Params { model, values }
    }

    /// Sets parameter `name` to `value`, checked against its declared range.
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), ParamError> {
        let idx = self.model.param_index(name)?.0 as usize;
        let param = &self.model.checked().params[idx];
        if !value.is_finite() {
            return Err(ParamError::NotFinite { name: param.name.clone(), value });
        }
        if let Some((lo, hi)) = param.range {
            if !(lo..=hi).contains(&value) {
                return Err(ParamError::OutOfRange { name: param.name.clone(), value, lo, hi });
            }
        }
        self.values[idx] = value;
        Ok(())
    }

    /// [`Self::set`], consuming and returning `self` for chaining.
    pub fn with(mut self, name: &str, value: f64) -> Result<Params, ParamError> {
        self.set(name, value)?;
        Ok(self)
    }

    /// The value of parameter `name`, if the model has one.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.model.checked().param_index(name).map(|i| self.values[i.0 as usize])
    }

    /// All values, in declaration order (what the integrator takes).
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// `(name, value)` pairs in declaration order.
    pub fn iter(&self) -> impl Iterator<Item = (&str, f64)> {
        self.model.param_names().zip(self.values.iter().copied())
    }

    /// The model these values belong to.
    pub fn model(&self) -> &Model {
        &self.model
    }
}
