//! Component types by name, so that systems can be built from data at run time.

use std::collections::BTreeMap;
use std::fmt;
use std::sync::Arc;

use nalgebra::DMatrix;

use super::module::{Binder, ModuleError, SampleModule};

/// A parameter value given to a component factory.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamValue {
    /// A number.
    Number(f64),
    /// A list of numbers.
    Numbers(Vec<f64>),
    /// A matrix (in a description file: an array of rows).
    Matrix(DMatrix<f64>),
    /// A string (usually a CSMat name).
    Text(String),
    /// A list of strings (usually CSMat names).
    Texts(Vec<String>),
    /// A flag.
    Bool(bool),
    /// Named sub-parameters (e.g. the model an LQG controller is designed on).
    Table(Params),
}

/// What kind of value a component parameter takes, and for CSMat names how the component uses
/// the CSMat. Description files are checked against it before the component is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamKind {
    /// A number.
    Number,
    /// A list of numbers (a single number is a list of one).
    Numbers,
    /// A matrix: an array of rows of numbers (a list of numbers is one column).
    Matrix,
    /// A string that is not a CSMat name.
    Text,
    /// A file name; in a description file, relative to that file.
    File,
    /// A flag.
    Bool,
    /// A table of sub-parameters.
    Table,
    /// The name of a CSMat the component reads.
    Input,
    /// Names of CSMats the component reads.
    Inputs,
    /// The name of a CSMat the component writes.
    Output,
}

impl ParamKind {
    /// How the kind is written in docs and error messages.
    pub fn describe(self) -> &'static str {
        match self {
            ParamKind::Number => "a number",
            ParamKind::Numbers => "a list of numbers",
            ParamKind::Matrix => "a matrix (array of rows)",
            ParamKind::Text => "a string",
            ParamKind::File => "a file name (relative to the description file)",
            ParamKind::Bool => "true or false",
            ParamKind::Table => "a table",
            ParamKind::Input => "the name of a CSMat it reads",
            ParamKind::Inputs => "a list of CSMat names it reads",
            ParamKind::Output => "the name of a CSMat it writes",
        }
    }
}

/// One parameter of a component type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ParamSpec {
    /// Its name.
    pub name: &'static str,
    /// What it takes.
    pub kind: ParamKind,
    /// `None`: required. `Some(text)`: optional, defaulting to what `text` says.
    pub default: Option<&'static str>,
    /// One line on what it means.
    pub doc: &'static str,
    /// Its unit (`s`, `N·m`), when it has one.
    pub unit: Option<&'static str>,
    /// The values it accepts, in words (`≥ 0`, `> 0`, `1 to 65536`), when not every value of
    /// its kind is accepted.
    pub range: Option<&'static str>,
}

impl ParamSpec {
    /// A required parameter.
    pub const fn required(name: &'static str, kind: ParamKind, doc: &'static str) -> Self {
        Self {
            name,
            kind,
            default: None,
            doc,
            unit: None,
            range: None,
        }
    }

    /// An optional parameter with its default (as docs show it).
    pub const fn optional(
        name: &'static str,
        kind: ParamKind,
        default: &'static str,
        doc: &'static str,
    ) -> Self {
        Self {
            name,
            kind,
            default: Some(default),
            doc,
            unit: None,
            range: None,
        }
    }

    /// Its doc with its unit and range, as references and editors show it:
    /// `time constant [s]; ≥ 0`.
    pub fn meaning(&self) -> String {
        let mut text = self.doc.to_owned();
        if let Some(unit) = self.unit {
            text.push_str(&format!(" [{unit}]"));
        }
        if let Some(range) = self.range {
            text.push_str(&format!("; {range}"));
        }
        text
    }

    /// With a unit.
    pub const fn unit(mut self, unit: &'static str) -> Self {
        self.unit = Some(unit);
        self
    }

    /// With the range of values it accepts, in words.
    pub const fn range(mut self, range: &'static str) -> Self {
        self.range = Some(range);
        self
    }
}

/// A component type's documentation and parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ComponentSpec {
    /// The type name description files use.
    pub name: &'static str,
    /// What it computes, in a sentence or two.
    pub summary: &'static str,
    /// Its parameters, in the order docs list them.
    pub params: &'static [ParamSpec],
}

impl ComponentSpec {
    /// The parameter `name`.
    pub fn param(&self, name: &str) -> Option<&ParamSpec> {
        self.params.iter().find(|p| p.name == name)
    }
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
        ModuleError::Param {
            name: err.name,
            reason: err.problem,
        }
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

    /// A list of numbers, or `default` if absent.
    pub fn numbers_or(&self, name: &str, default: &[f64]) -> Result<Vec<f64>, ParamError> {
        if self.0.contains_key(name) {
            self.numbers(name)
        } else {
            Ok(default.to_vec())
        }
    }

    /// A matrix (a list of numbers is one column, a number is 1 × 1).
    pub fn matrix(&self, name: &str) -> Result<DMatrix<f64>, ParamError> {
        match self.get(name)? {
            ParamValue::Matrix(m) => Ok(m.clone()),
            ParamValue::Numbers(xs) => Ok(DMatrix::from_column_slice(xs.len(), 1, xs)),
            ParamValue::Number(x) => Ok(DMatrix::from_element(1, 1, *x)),
            other => Err(Self::wrong(name, "a matrix", other)),
        }
    }

    /// A flag.
    pub fn bool(&self, name: &str) -> Result<bool, ParamError> {
        match self.get(name)? {
            ParamValue::Bool(b) => Ok(*b),
            other => Err(Self::wrong(name, "true or false", other)),
        }
    }

    /// A flag, or `default` if absent.
    pub fn bool_or(&self, name: &str, default: bool) -> Result<bool, ParamError> {
        match self.0.get(name) {
            None => Ok(default),
            Some(ParamValue::Bool(b)) => Ok(*b),
            Some(other) => Err(Self::wrong(name, "true or false", other)),
        }
    }

    /// A list of strings (a single string is a list of one).
    pub fn texts(&self, name: &str) -> Result<Vec<String>, ParamError> {
        match self.get(name)? {
            ParamValue::Texts(xs) => Ok(xs.clone()),
            ParamValue::Text(x) => Ok(vec![x.clone()]),
            other => Err(Self::wrong(name, "a list of strings", other)),
        }
    }

    /// A table of sub-parameters.
    pub fn table(&self, name: &str) -> Result<&Params, ParamError> {
        match self.get(name)? {
            ParamValue::Table(t) => Ok(t),
            other => Err(Self::wrong(name, "a table", other)),
        }
    }

    /// Whether `name` is given.
    pub fn has(&self, name: &str) -> bool {
        self.0.contains_key(name)
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
impl From<DMatrix<f64>> for ParamValue {
    fn from(m: DMatrix<f64>) -> Self {
        ParamValue::Matrix(m)
    }
}
impl From<Vec<String>> for ParamValue {
    fn from(xs: Vec<String>) -> Self {
        ParamValue::Texts(xs)
    }
}
impl From<Params> for ParamValue {
    fn from(t: Params) -> Self {
        ParamValue::Table(t)
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
    types: BTreeMap<String, (String, Option<&'static ComponentSpec>, Factory)>,
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
            .insert(name.to_owned(), (description.to_owned(), None, factory));
    }

    /// Registers a component type made with `#[derive(Component)]` (or implementing
    /// [`Component`](crate::Component) by hand), replacing an earlier type of its name.
    ///
    /// ```
    /// use ndds_runtime::{Component, Mat, Registry, RoutineResult, SampleContext, SampleModule};
    ///
    /// /// Doubles its input.
    /// #[derive(Component)]
    /// #[component(name = "double")]
    /// struct Double {
    ///     /// u (1 × 1)
    ///     #[input(shape = (1, 1))]
    ///     input: Mat,
    ///     /// 2·u
    ///     #[output(same_as = input)]
    ///     output: Mat,
    /// }
    ///
    /// impl SampleModule for Double {
    ///     fn execute(&mut self, _: &SampleContext) -> RoutineResult {
    ///         let u = self.input.value(0, 0);
    ///         Ok(self.output.write().set(0, 0, 2.0 * u)?)
    ///     }
    /// }
    ///
    /// let mut library = Registry::empty();
    /// library.add::<Double>();
    /// assert_eq!(library.spec("double").unwrap().params.len(), 2);
    /// ```
    pub fn add<C: crate::Component>(&mut self) -> &mut Self {
        self.add_with(C::spec(), C::build);
        self
    }

    /// Registers a documented type: description files are checked against `spec` (unknown,
    /// missing and mistyped parameters) before `factory` runs.
    pub fn add_with<F, M>(&mut self, spec: &'static ComponentSpec, factory: F)
    where
        F: Fn(&mut Binder<'_>, &Params) -> Result<M, ModuleError> + Send + Sync + 'static,
        M: SampleModule,
    {
        let factory: Factory = Arc::new(move |b, p| Ok(Box::new(factory(b, p)?)));
        self.types.insert(
            spec.name.to_owned(),
            (spec.summary.to_owned(), Some(spec), factory),
        );
    }

    /// Adds every type of `other` (replacing types of the same name).
    pub fn extend(&mut self, other: Registry) {
        self.types.extend(other.types);
    }

    /// The factory for `name`.
    pub fn get(&self, name: &str) -> Option<&Factory> {
        self.types.get(name).map(|(_, _, f)| f)
    }

    /// The documented parameters of `name` (`None` for types registered without a spec).
    pub fn spec(&self, name: &str) -> Option<&'static ComponentSpec> {
        self.types.get(name).and_then(|(_, s, _)| *s)
    }

    /// Registered names with their descriptions.
    pub fn types(&self) -> impl Iterator<Item = (&str, &str)> {
        self.types
            .iter()
            .map(|(n, (d, _, _))| (n.as_str(), d.as_str()))
    }

    /// Every documented type's spec, by name.
    pub fn specs(&self) -> impl Iterator<Item = &'static ComponentSpec> + '_ {
        self.types.values().filter_map(|(_, s, _)| *s)
    }
}

impl fmt::Debug for Registry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.types.keys()).finish()
    }
}
