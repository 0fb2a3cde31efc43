//! `[[mat]]`: a CSMat created with a value, its rows and columns optionally named and given
//! units.

use nalgebra::DMatrix;

use super::keys::{Key, Section, TEXT};
use super::reader::Reader;
use super::values::matrix;
use super::{Description, Named};
use crate::CsMat;
use crate::system::source::{Diagnostics, Location};

pub(super) const SECTION: Section = Section::list(
    "mat",
    &[
        Key::new("name", TEXT),
        Key::new("value", "a number, a list (a column) or an array of rows"),
        Key::new("rows", "a name for each row"),
        Key::new("cols", "a name for each column"),
        Key::new("row_units", "a unit for each row"),
        Key::new("col_units", "a unit for each column"),
    ],
    |d, r, _, p| read(d, r, p),
);

pub(crate) struct MatDecl {
    pub name: Named,
    pub value: CsMat,
}

fn read(d: &mut Description, r: &Reader<'_>, p: &mut Diagnostics) {
    let name = r.required_text("name", p);
    let value = match r.raw("value") {
        None => {
            r.missing("value", p);
            None
        }
        Some(raw) => matrix(raw, "value", p),
    };
    let (Some(name), Some(value)) = (name, value) else {
        return;
    };
    let Some(value) = not_empty(value, r, p) else {
        return;
    };
    let mut mat = CsMat::from_matrix(&name.name, value);
    for axis in AXES {
        mat = axis.name(mat, &name, r, p);
    }
    d.mats.push(MatDecl { name, value: mat });
}

fn not_empty(value: DMatrix<f64>, r: &Reader<'_>, p: &mut Diagnostics) -> Option<DMatrix<f64>> {
    if !value.is_empty() {
        return Some(value);
    }
    if let Some(raw) = r.raw("value") {
        p.expected(&raw.at, "`value` is empty", "at least one number");
    }
    None
}

/// Rows or columns, and the keys that name them and give their units.
#[derive(Clone, Copy)]
enum Axis {
    Row,
    Column,
}

const AXES: [Axis; 2] = [Axis::Row, Axis::Column];

impl Axis {
    /// As messages say it, and its keys: names, units.
    fn words(self) -> (&'static str, &'static str, &'static str) {
        match self {
            Axis::Row => ("row", "rows", "row_units"),
            Axis::Column => ("column", "cols", "col_units"),
        }
    }

    fn count(self, mat: &CsMat) -> usize {
        match self {
            Axis::Row => mat.rows(),
            Axis::Column => mat.cols(),
        }
    }

    /// `mat` with this axis' names and units, when the table gives them and they fit (else
    /// reported, and `mat` as it was).
    fn name(self, mat: CsMat, decl: &Named, r: &Reader<'_>, p: &mut Diagnostics) -> CsMat {
        let (_, names_key, units_key) = self.words();
        let names = r.texts(names_key, p);
        let units = r.texts(units_key, p);
        if names.is_empty() && units.is_empty() {
            return mat;
        }
        let at = r
            .raw(names_key)
            .or(r.raw(units_key))
            .map_or(r.at.clone(), |x| x.at.clone());
        if !self.counts_fit(&mat, decl, (&names, &units), &at, p) {
            return mat;
        }
        let fields = names.iter().enumerate().map(|(i, n)| {
            let unit = units.get(i).map_or("", |u| u.name.as_str());
            (n.name.as_str(), unit)
        });
        let named = match self {
            Axis::Row => mat.clone().with_row_fields(fields),
            Axis::Column => mat.clone().with_col_fields(fields),
        };
        named.unwrap_or_else(|err| {
            p.push(&at, err.to_string());
            mat
        })
    }

    /// Whether there is a name for each row (column) and a unit for each or none.
    fn counts_fit(
        self,
        mat: &CsMat,
        decl: &Named,
        (names, units): (&[Named], &[Named]),
        at: &Location,
        p: &mut Diagnostics,
    ) -> bool {
        let count = self.count(mat);
        if names.len() == count && (units.is_empty() || units.len() == count) {
            return true;
        }
        let (axis, names_key, units_key) = self.words();
        p.expected(
            at,
            format!(
                "CSMat `{}` has {count} {axis}s but {} {axis} names and {} units",
                decl.name,
                names.len(),
                units.len()
            ),
            format!("{count} names (`{names_key}`) and {count} units (`{units_key}`) or none"),
        );
        false
    }
}
