//! Component types by name, so that systems can be built from data at run time.

use std::collections::BTreeMap;
use std::fmt;
use std::sync::Arc;

use super::module::{Binder, ModuleError, SampleModule};

/// A parameter value given to a component factory.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamValue {
    /// A number.
    Number(f64),
    /// A list of numbers (a row-major matrix needs `rows`/`cols` besides).
    Numbers(Vec<f64>),
    /// A string (usually a CSMat name).
    Text(String),
    /// A flag.
    Bool(bool),
}

/// The parameters of one component instance, by name.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Params(pub BTreeMap<String, ParamValue>);

/// A missing or mistyped parameter.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("parameter `{name}`: {problem}")]
pub struct ParamError {
    /// The parameter.
    pub name: String,
    /// What is wrong.
    pub problem: String,
}

impl From<ParamError> for ModuleError {
    fn from(err: ParamError) -> Self {
        ModuleError::Failed(err.to_string())
    }
}

impl Params {
    /// Empty.
    pub fn new() -> Self {
        Self::default()
    }

    /// With `name = value`.
    pub fn with(mut self, name: &str, value: impl Into<ParamValue>) -> Self {
        self.0.insert(name.to_owned(), value.into());
        self
    }

    fn get(&self, name: &str) -> Result<&ParamValue, ParamError> {
        self.0.get(name).ok_or_else(|| ParamError {
            name: name.to_owned(),
            problem: "missing".into(),
        })
    }

    fn wrong(name: &str, expected: &str, got: &ParamValue) -> ParamError {
        ParamError {
            name: name.to_owned(),
            problem: format!("expected {expected}, got {got:?}"),
        }
    }

    /// A number.
    pub fn number(&self, name: &str) -> Result<f64, ParamError> {
        match self.get(name)? {
            ParamValue::Number(x) => Ok(*x),
            other => Err(Self::wrong(name, "a number", other)),
        }
    }

    /// A number, or `default` if absent.
    pub fn number_or(&self, name: &str, default: f64) -> Result<f64, ParamError> {
        if self.0.contains_key(name) {
            self.number(name)
        } else {
            Ok(default)
        }
    }

    /// A list of numbers (a single number is a list of one).
    pub fn numbers(&self, name: &str) -> Result<Vec<f64>, ParamError> {
        match self.get(name)? {
            ParamValue::Numbers(xs) => Ok(xs.clone()),
            ParamValue::Number(x) => Ok(vec![*x]),
            other => Err(Self::wrong(name, "a list of numbers", other)),
        }
    }

    /// A string.
    pub fn text(&self, name: &str) -> Result<&str, ParamError> {
        match self.get(name)? {
            ParamValue::Text(s) => Ok(s),
            other => Err(Self::wrong(name, "a string", other)),
        }
    }

    /// A string, or `default` if absent.
    pub fn text_or<'a>(&'a self, name: &str, default: &'a str) -> Result<&'a str, ParamError> {
        if self.0.contains_key(name) {
            self.text(name)
        } else {
            Ok(default)
        }
    }
}

impl From<f64> for ParamValue {
    fn from(x: f64) -> Self {
        ParamValue::Number(x)
    }
}
impl From<Vec<f64>> for ParamValue {
    fn from(xs: Vec<f64>) -> Self {
        ParamValue::Numbers(xs)
    }
}
impl From<&str> for ParamValue {
    fn from(s: &str) -> Self {
        ParamValue::Text(s.to_owned())
    }
}
impl From<bool> for ParamValue {
    fn from(b: bool) -> Self {
        ParamValue::Bool(b)
    }
}

/// Builds one component instance.
pub type Factory = Arc<
    dyn Fn(&mut Binder<'_>, &Params) -> Result<Box<dyn SampleModule>, ModuleError> + Send + Sync,
>;

/// Component types by name.
#[derive(Clone, Default)]
pub struct Registry {
    types: BTreeMap<String, (String, Factory)>,
}

impl Registry {
    /// An empty registry.
    pub fn empty() -> Self {
        Self::default()
    }

    /// Registers `name` (replacing an earlier type of that name), with a one-line description.
    pub fn register<F, M>(&mut self, name: &str, description: &str, factory: F)
    where
        F: Fn(&mut Binder<'_>, &Params) -> Result<M, ModuleError> + Send + Sync + 'static,
        M: SampleModule,
    {
        let factory: Factory = Arc::new(move |b, p| Ok(Box::new(factory(b, p)?)));
        self.types
            .insert(name.to_owned(), (description.to_owned(), factory));
    }

    /// The factory for `name`.
    pub fn get(&self, name: &str) -> Option<&Factory> {
        self.types.get(name).map(|(_, f)| f)
    }

    /// Registered names with their descriptions.
    pub fn types(&self) -> impl Iterator<Item = (&str, &str)> {
        self.types
            .iter()
            .map(|(n, (d, _))| (n.as_str(), d.as_str()))
    }
}

impl fmt::Debug for Registry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.types.keys()).finish()
    }
}
