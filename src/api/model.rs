//! A checked model: parsed, names resolved, ready to compile.

use std::path::Path;
use std::sync::Arc;

use super::{Compiled, Error, ModelError, ParamError, Params};
use crate::codegen::CompileOptions;
use crate::sema::{self, ParamIdx};
use crate::sim::SimOptions;

/// The largest model file [`Model::from_file`] reads: far beyond any hand-written model (the
/// shipped ones are under 3 KB; a generated 10,000-state chain is about 400 KB), small enough that
/// a wrong path (`/dev/zero`, a log file) is refused before it fills memory.
pub const MAX_MODEL_BYTES: u64 = 64 << 20;

/// A model text that parsed and checked. Cheap to clone (shared).
#[derive(Clone, Debug)]
pub struct Model {
    inner: Arc<ModelInner>,
}

#[derive(Debug)]
struct ModelInner {
    checked: sema::Model,
    source: String,
    file_name: String,
}

impl Model {
    /// Parses and checks `text`. Diagnostics name the file `model.hyb`; see [`Self::parse_named`].
    pub fn parse(text: &str) -> Result<Model, Error> {
        Model::parse_named(text, "model.hyb")
    }

    /// Parses and checks `text`, naming `file_name` in every diagnostic.
    pub fn parse_named(text: &str, file_name: &str) -> Result<Model, Error> {
        match super::check_source(text) {
            Ok(checked) => Ok(Model {
                inner: Arc::new(ModelInner {
                    checked,
                    source: text.to_string(),
                    file_name: file_name.to_string(),
                }),
            }),
            Err(errors) => {
                let rendered = errors.render(file_name, text);
                Err(ModelError { errors, rendered }.into())
            }
        }
    }

    /// Reads (at most [`MAX_MODEL_BYTES`]), parses and checks a model file; diagnostics name the
    /// path as given. Bytes that are not UTF-8 are replaced (and then reported where they stand).
    /// A path ending in `.xml` or `.sbml` is an SBML document, imported first
    /// ([`Self::from_sbml_file`]).
    pub fn from_file(path: impl AsRef<Path>) -> Result<Model, Error> {
        let path = path.as_ref();
        if super::import::is_sbml_path(path) {
            return Model::from_sbml_file(path);
        }
        Model::parse_named(&super::import::read_text(path)?, &path.display().to_string())
    }

    /// The model's name (`model NAME`).
    pub fn name(&self) -> &str {
        &self.inner.checked.name
    }

    /// The checked model, for the stages behind the front door.
    pub fn checked(&self) -> &sema::Model {
        &self.inner.checked
    }

    /// The text the model was parsed from.
    pub fn source(&self) -> &str {
        &self.inner.source
    }

    /// The file name its diagnostics use.
    pub fn file_name(&self) -> &str {
        &self.inner.file_name
    }

    /// Warnings about the valid model (`sema::lint`), rendered like errors against its source;
    /// empty when there are none.
    pub fn warnings(&self) -> String {
        let found = sema::lint::warnings(&self.inner.checked);
        crate::diag::render_warnings(&self.inner.file_name, &self.inner.source, &found)
    }

    /// The parameters at their declared defaults.
    pub fn params(&self) -> Params {
        Params::defaults(self.clone())
    }

    /// Parameter names in declaration order.
    pub fn param_names(&self) -> impl Iterator<Item = &str> {
        self.inner.checked.params.iter().map(|p| p.name.as_str())
    }

    /// State names in declaration order.
    pub fn state_names(&self) -> impl Iterator<Item = &str> {
        self.inner.checked.states.iter().map(|s| s.name.as_str())
    }

    /// Output names in declaration order.
    pub fn output_names(&self) -> impl Iterator<Item = &str> {
        self.inner.checked.outputs.iter().map(|o| o.name.as_str())
    }

    /// The options of a run: the model's `simulate` line over the run defaults
    /// ([`SimOptions::default`]), as `hybc run` uses them without flags.
    pub fn sim_options(&self) -> SimOptions {
        let defaults = SimOptions::default();
        let sim = &self.inner.checked.simulate;
        SimOptions {
            t_end: sim.t_end.unwrap_or(defaults.t_end),
            rtol: sim.rtol.unwrap_or(defaults.rtol),
            atol: sim.atol.unwrap_or(defaults.atol),
            ..defaults
        }
    }

    /// The options of an analysis's runs that differentiate (`sweep`, `fit`, `optimize`): as
    /// [`Self::sim_options`], with gradients by the cheaper mode (`Sens::Auto`: the adjoint when
    /// the quantities are far fewer than the free parameters) unless the caller says otherwise.
    pub fn analysis_sim_options(&self) -> SimOptions {
        SimOptions { sens: crate::sim::Sens::Auto, ..self.sim_options() }
    }

    /// The index of parameter `name`, or an error that lists the model's parameters.
    /// An element of a vector parameter is named `u[3]` (no spaces, no leading zeros); the vector's
    /// own name is refused here with a word on how to name its elements.
    pub fn param_index(&self, name: &str) -> Result<ParamIdx, ParamError> {
        let checked = &self.inner.checked;
        if let Some(v) = checked.vector(name) {
            return Err(ParamError::IsVector { name: name.to_string(), len: v.len });
        }
        checked.param_index(name).ok_or_else(|| self.unknown_param(name))
    }

    /// The vector parameter `name` (`param u[N]`), if the model has one.
    pub fn vector(&self, name: &str) -> Option<&sema::ParamVector> {
        self.inner.checked.vector(name)
    }

    /// "no parameter `name`", with the closest name and the list of parameters (a vector listed
    /// once, as `u[0] .. u[20]`).
    pub(crate) fn unknown_param(&self, name: &str) -> ParamError {
        let checked = &self.inner.checked;
        let mut known: Vec<String> =
            checked.params.iter().filter(|p| !p.name.contains('[')).map(|p| p.name.clone()).collect();
        known.extend(
            checked.vectors.iter().map(|v| format!("{0}[0] .. {0}[{1}]", v.name, v.len.saturating_sub(1))),
        );
        let candidates = checked.params.iter().filter(|p| !p.name.contains('[')).map(|p| p.name.as_str());
        let hint =
            sema::closest_name(name, candidates.chain(checked.vectors.iter().map(|v| v.name.as_str())));
        ParamError::Unknown { model: self.name().to_string(), name: name.to_string(), hint, known }
    }

    /// The parameters `names` stand for, in order: a parameter's name one (`u[3]`, an element of
    /// a vector), a vector's name every element. Names are expanded here once, so that what is
    /// compiled, differentiated or solved for is a list of indices from then on. Refuses an
    /// unknown name (naming the closest) and a parameter named twice, directly or through its
    /// vector.
    pub fn param_list<S: AsRef<str>>(&self, names: &[S]) -> Result<Vec<ParamIdx>, ParamError> {
        let checked = &self.inner.checked;
        let mut out: Vec<ParamIdx> = Vec::with_capacity(names.len());
        // A set, not a scan of `out`: `--grad u` on a long vector names thousands.
        let mut seen = std::collections::HashSet::new();
        for name in names {
            let name = name.as_ref();
            let first = out.len();
            match checked.vector(name) {
                Some(v) => out.extend(v.elements()),
                None => out.push(checked.param_index(name).ok_or_else(|| self.unknown_param(name))?),
            }
            if let Some(p) = out[first..].iter().find(|p| !seen.insert(**p)) {
                return Err(ParamError::Duplicate { name: checked.params[p.0 as usize].name.clone() });
            }
        }
        Ok(out)
    }

    /// Compiles the model to native code with gradients with respect to `grad` (parameter
    /// names as [`Self::param_list`] reads them, in the order of the sensitivity columns; empty
    /// for no gradients).
    pub fn compile<S: AsRef<str>>(&self, grad: &[S]) -> Result<Compiled, Error> {
        self.compile_with(grad, &CompileOptions::default())
    }

    /// [`Self::compile`] with explicit code-generation options.
    pub fn compile_with<S: AsRef<str>>(&self, grad: &[S], opts: &CompileOptions) -> Result<Compiled, Error> {
        Compiled::new(self.clone(), &self.param_list(grad)?, opts)
    }

    /// [`Self::compile`] with the gradient parameters as a [`Self::param_list`] gave them.
    pub(crate) fn compile_params(&self, grad: &[ParamIdx]) -> Result<Compiled, Error> {
        Compiled::new(self.clone(), grad, &CompileOptions::default())
    }

    /// [`Self::compile`] with gradients with respect to every parameter.
    pub fn compile_all(&self) -> Result<Compiled, Error> {
        let all: Vec<ParamIdx> = (0..self.inner.checked.params.len()).map(|i| ParamIdx(i as u32)).collect();
        self.compile_params(&all)
    }

    /// A model an analysis derived from this one (periodic's section made a `stop`, one
    /// parameter per initial state): `checked`, with this one's source and file name for
    /// messages. It is not checked again: the analysis built it from a checked model, through
    /// the checker's own types.
    pub(crate) fn derived(&self, checked: sema::Model) -> Model {
        let inner = ModelInner {
            checked,
            source: self.inner.source.clone(),
            file_name: self.inner.file_name.clone(),
        };
        Model { inner: Arc::new(inner) }
    }

    /// Whether `other` is this very model (the same parse, or a clone of it).
    pub(crate) fn same(&self, other: &Model) -> bool {
        Arc::ptr_eq(&self.inner, &other.inner)
    }
}
