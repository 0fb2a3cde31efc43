//! Plots: the numeric fields of a sample, and the decimation that keeps a 1 kHz topic from
//! flooding the page (each field is sent as at most two points per bucket, its minimum and its
//! maximum in the order they came, so spikes survive).

use ndds_runtime::CsMat;

/// At most this many fields of one topic are plotted (the first ones, in field order).
pub const MAX_FIELDS: usize = 64;

/// The numeric fields of a sample decoded as JSON, by path (`pose.x`, `joints[1]`), in
/// document order; booleans count as 0 and 1.
pub fn json_fields(value: &serde_json::Value) -> Vec<(String, f64)> {
    let mut out = Vec::new();
    walk(value, &mut String::new(), &mut out);
    out
}

fn walk(value: &serde_json::Value, path: &mut String, out: &mut Vec<(String, f64)>) {
    if out.len() >= MAX_FIELDS {
        return;
    }
    match value {
        serde_json::Value::Number(n) => {
            if let Some(v) = n.as_f64() {
                out.push((
                    if path.is_empty() {
                        "value".into()
                    } else {
                        path.clone()
                    },
                    v,
                ));
            }
        }
        serde_json::Value::Bool(b) => {
            out.push((path.clone(), if *b { 1.0 } else { 0.0 }));
        }
        serde_json::Value::Array(items) => {
            for (i, item) in items.iter().enumerate() {
                let len = path.len();
                path.push_str(&format!("[{i}]"));
                walk(item, path, out);
                path.truncate(len);
            }
        }
        serde_json::Value::Object(fields) => {
            for (key, item) in fields {
                let len = path.len();
                if !path.is_empty() {
                    path.push('.');
                }
                path.push_str(key);
                walk(item, path, out);
                path.truncate(len);
            }
        }
        _ => {}
    }
}

/// The elements of a CSMat, named by its field names and units where it has them (`q1
/// (rad)`; `x,vx` for a matrix), else by index (`[0,1]`).
pub fn csmat_fields(mat: &CsMat) -> Vec<(String, f64)> {
    csmat_names(mat)
        .into_iter()
        .zip(csmat_values(mat))
        .collect()
}

/// The names [`csmat_fields`] gives a CSMat's elements (row-major, at most [`MAX_FIELDS`]).
pub fn csmat_names(mat: &CsMat) -> Vec<String> {
    let (rows, cols) = mat.shape();
    let (row_fields, col_fields) = (mat.row_fields(), mat.col_fields());
    let mut out = Vec::with_capacity((rows * cols).min(MAX_FIELDS));
    for (r, c) in (0..rows)
        .flat_map(|r| (0..cols).map(move |c| (r, c)))
        .take(MAX_FIELDS)
    {
        let row = row_fields.get(r);
        let col = col_fields.get(c);
        let mut name = match (rows, cols) {
            (_, 1) => row.map_or(format!("[{r}]"), |f| f.name.clone()),
            (1, _) => col.map_or(format!("[{c}]"), |f| f.name.clone()),
            _ => format!(
                "{},{}",
                row.map_or(r.to_string(), |f| f.name.clone()),
                col.map_or(c.to_string(), |f| f.name.clone())
            ),
        };
        let unit = [row, col]
            .into_iter()
            .flatten()
            .map(|f| f.unit.as_str())
            .find(|u| !u.is_empty());
        if let Some(unit) = unit {
            name.push_str(&format!(" ({unit})"));
        }
        out.push(name);
    }
    out
}

/// A CSMat's elements, row-major, as many as [`csmat_names`] names.
pub fn csmat_values(mat: &CsMat) -> Vec<f64> {
    let (rows, cols) = mat.shape();
    (0..rows)
        .flat_map(|r| (0..cols).map(move |c| (r, c)))
        .take(MAX_FIELDS)
        .map(|(r, c)| mat.get(r, c).unwrap_or(f64::NAN))
        .collect()
}

/// A point: (time in seconds, value).
type Point = (f64, f64);

/// One field's points, decimated into buckets of a fixed width.
#[derive(Debug)]
pub struct Decimator {
    bucket: f64,
    /// The open bucket: its index, and its first extreme and second extreme as (t, v).
    open: Option<(i64, Point, Point)>,
    ready: Vec<Point>,
}

impl Decimator {
    /// Buckets `bucket_s` seconds wide.
    pub fn new(bucket_s: f64) -> Self {
        Decimator {
            bucket: bucket_s.max(1e-6),
            open: None,
            ready: Vec::new(),
        }
    }

    /// A value at time `t` (seconds); times go forward (an earlier one opens no new bucket).
    pub fn push(&mut self, t: f64, v: f64) {
        let index = (t / self.bucket).floor() as i64;
        match &mut self.open {
            Some((open, lo, hi)) if index <= *open => {
                if v < lo.1 {
                    *lo = (t, v);
                }
                if v > hi.1 {
                    *hi = (t, v);
                }
            }
            _ => {
                self.close();
                self.open = Some((index, (t, v), (t, v)));
            }
        }
    }

    fn close(&mut self) {
        if let Some((_, lo, hi)) = self.open.take() {
            if lo.0 == hi.0 {
                self.ready.push(lo);
            } else if lo.0 < hi.0 {
                self.ready.extend([lo, hi]);
            } else {
                self.ready.extend([hi, lo]);
            }
        }
    }

    /// The points of every bucket closed by time `now` (seconds), in time order.
    pub fn take(&mut self, now: f64) -> Vec<Point> {
        if let Some((index, _, _)) = self.open
            && ((now / self.bucket).floor() as i64) > index
        {
            self.close();
        }
        std::mem::take(&mut self.ready)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_fields_are_named_by_path_and_only_numbers_and_booleans_count() {
        let value = serde_json::json!({
            "pose": {"x": 1.5, "y": -2},
            "joints": [0.1, 0.2],
            "name": "arm",
            "ok": true
        });
        let fields = json_fields(&value);
        assert_eq!(
            fields,
            vec![
                ("pose.x".to_owned(), 1.5),
                ("pose.y".to_owned(), -2.0),
                ("joints[0]".to_owned(), 0.1),
                ("joints[1]".to_owned(), 0.2),
                ("ok".to_owned(), 1.0),
            ]
        );
        assert_eq!(
            json_fields(&serde_json::json!(7)),
            vec![("value".to_owned(), 7.0)]
        );
    }

    #[test]
    fn csmat_fields_carry_names_and_units() {
        let mut angles = CsMat::zeros("angles", 2, 1)
            .with_row_fields([("q1", "rad"), ("q2", "rad")])
            .unwrap();
        angles.set(1, 0, 0.5).unwrap();
        assert_eq!(
            csmat_fields(&angles),
            vec![("q1 (rad)".to_owned(), 0.0), ("q2 (rad)".to_owned(), 0.5)]
        );
        let plain = CsMat::zeros("m", 2, 2);
        let names: Vec<String> = csmat_fields(&plain).into_iter().map(|f| f.0).collect();
        assert_eq!(names, ["0,0", "0,1", "1,0", "1,1"]);
    }

    #[test]
    fn a_thousand_points_a_second_become_two_per_bucket_and_keep_their_extremes() {
        let mut d = Decimator::new(0.02);
        // 1 kHz for one second: a sine with one spike.
        for i in 0..1000 {
            let t = i as f64 / 1000.0;
            let v = if i == 503 { 100.0 } else { (t * 6.0).sin() };
            d.push(t, v);
        }
        let points = d.take(1.0);
        assert!(points.len() <= 2 * 50, "{}", points.len());
        assert!(points.len() >= 50, "{}", points.len());
        assert!(points.iter().any(|p| p.1 == 100.0), "the spike survives");
        assert!(points.windows(2).all(|w| w[0].0 <= w[1].0), "in time order");
        // The open bucket is not sent before it closes.
        d.push(1.001, 0.0);
        assert!(d.take(1.005).is_empty());
        assert_eq!(d.take(1.03), vec![(1.001, 0.0)]);
    }
}
