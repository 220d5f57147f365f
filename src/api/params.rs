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
    /// An element of a vector parameter is named `u[3]`.
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), ParamError> {
        let idx = self.model.param_index(name)?.0 as usize;
        self.check(idx, value)?;
        self.values[idx] = value;
        Ok(())
    }

    /// Sets every element of vector parameter `name` (`param u[N]`): exactly `N` values, each
    /// checked against the declared range; on an error nothing is changed.
    pub fn set_vector(&mut self, name: &str, values: &[f64]) -> Result<(), ParamError> {
        let Some(v) = self.model.vector(name) else {
            return Err(match self.model.param_index(name) {
                Ok(_) => {
                    ParamError::NotAVector { model: self.model.name().to_string(), name: name.to_string() }
                }
                Err(e) => e,
            });
        };
        if values.len() != v.len as usize {
            return Err(ParamError::VectorLength { name: name.to_string(), len: v.len, found: values.len() });
        }
        let first = v.first.0 as usize;
        for (k, &value) in values.iter().enumerate() {
            self.check(first + k, value)?;
        }
        self.values[first..first + values.len()].copy_from_slice(values);
        Ok(())
    }

    /// [`Self::set_vector`], consuming and returning `self` for chaining.
    pub fn with_vector(mut self, name: &str, values: &[f64]) -> Result<Params, ParamError> {
        self.set_vector(name, values)?;
        Ok(self)
    }

    /// The values of vector parameter `name`, if the model has one.
    pub fn vector(&self, name: &str) -> Option<&[f64]> {
        let v = self.model.vector(name)?;
        let first = v.first.0 as usize;
        Some(&self.values[first..first + v.len as usize])
    }

    /// Whether `value` is finite and in the declared range of parameter `idx`.
    fn check(&self, idx: usize, value: f64) -> Result<(), ParamError> {
        let param = &self.model.checked().params[idx];
        if !value.is_finite() {
            return Err(ParamError::NotFinite { name: param.name.clone(), value });
        }
        if let Some((lo, hi)) = param.range {
            if !(lo..=hi).contains(&value) {
                return Err(ParamError::OutOfRange { name: param.name.clone(), value, lo, hi });
            }
        }
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
